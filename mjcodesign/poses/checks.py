"""Checks a palm pose from a file must pass before it is simulated: the object it was made for, its reach.

A candidate file (``mjcodesign poses --out``) names the object its poses were sampled on; poses of one
object run on another would be grasps of nothing in particular. A palm so far from the object that no
finger can touch it would run and report ``not_lifted``, a number that means nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import PoseError
from mjcodesign.models.types import MAX_OPENING, GripperPose
from mjcodesign.objects import GraspObject

__all__ = ["candidate_object", "check_candidate_object", "check_reach", "finger_reach"]


def candidate_object(path: str | Path) -> str | None:
    """The object a candidate file was made for, or None when the file does not say (older files)."""
    try:
        with np.load(Path(path), allow_pickle=False) as z:
            return str(z["object"]) if "object" in z.files else None
    except (OSError, ValueError, KeyError, TypeError):
        return None  # an unreadable file is reported by the reader, with its reason


def check_candidate_object(path: str | Path, obj: GraspObject) -> None:
    """Raise :class:`PoseError` when the candidate file at ``path`` was made for another object."""
    made_for = candidate_object(path)
    if made_for is not None and made_for != obj.name:
        raise PoseError(f"{path}: its poses were made for object {made_for!r}, not {obj.name!r} (--object)")


def finger_reach(obj: GraspObject, geometry: FingerDesign) -> float:
    """The farthest the palm can be from the object's COM with a finger still touching it [m].

    Every finger point lies within length + largest opening + base height of the palm; every object
    point within its bounding radius of its COM (triangle inequality).
    """
    radius = float(np.max(np.linalg.norm(np.asarray(obj.mesh.vertices, dtype=float), axis=1)))
    return geometry.length + MAX_OPENING + geometry.height_base + radius


def check_reach(pose: GripperPose, obj: GraspObject, geometry: FingerDesign) -> GripperPose:
    """``pose``, or :class:`PoseError` when no finger can reach the object from it.

    The object's COM is at world x = y = 0, resting on the ground (z = 0), as the grasp scene places it.
    """
    com = np.array([0.0, 0.0, -float(np.min(np.asarray(obj.mesh.vertices)[:, 2]))])
    distance = float(np.linalg.norm(np.asarray(pose.position) - com))
    reach = finger_reach(obj, geometry)
    if distance > reach:
        raise PoseError(
            f"the palm is {distance:.4g} m from the object's centre, beyond the fingers' reach "
            f"({reach:.3g} m): no finger can touch it"
        )
    return pose
