"""The partial point cloud of a pose: object surface points inside the fingers' bounding box.

As the authors' ``generate_partial_pointcloud.py`` does it: sample the object's surface 50 times more
densely than needed, keep the points inside the box that bounds both fingers at the grasp, and draw
N = 1024 of them (with repetition when fewer are inside; a pose with 100 or fewer is dropped). The
authors' box is trimesh's minimum-volume OBB of their finger particles; ours bounds the fingers'
rigid counterpart (:class:`mjcodesign.poses.RigidGripper`) at the pose's openings in the palm frame,
whose axes are the fingers' symmetry axes, so the box is the fingers' OBB (on four sampler poses of
013_apple its volume equalled trimesh's minimum-volume OBB of the same points) and the cloud comes
out in the gripper frame directly.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import PoseError
from mjcodesign.objects import GraspObject
from mjcodesign.poses import COARSE_EDGE, RigidGripper, scene_offset

__all__ = [
    "MIN_INSIDE",
    "OVERSAMPLE",
    "PartialCloud",
    "fingers_box",
    "gripper_up",
    "partial_cloud",
    "to_gripper",
]

OVERSAMPLE = 50
"""Surface samples drawn per point kept (the authors' ``oversample_factor``)."""
MIN_INSIDE = 101
"""Fewest samples inside the box for a usable cloud (the authors drop a pose below 101)."""


@dataclass(frozen=True)
class PartialCloud:
    """A pose's partial point cloud."""

    points: np.ndarray
    """Object surface points in the gripper (palm) frame [m], float32, shape (n, 3)."""
    inside: int
    """Surface samples that fell inside the box before the draw (out of ``OVERSAMPLE n``)."""

    @property
    def repeated(self) -> bool:
        """True when fewer than n samples were inside, so some points repeat."""
        return self.inside < len(self.points)


def to_gripper(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World points (k, 3) [m] in the palm frame of the 4x4 pose ``T``."""
    return (np.asarray(points, dtype=float) - T[:3, 3]) @ T[:3, :3]


def gripper_up(T: np.ndarray) -> np.ndarray:
    """The world's vertical (+z, unit) in the palm frame of pose(s) ``T``, shape (..., 4, 4) -> (..., 3).

    Row 2 of the palm's rotation: the direction :func:`to_gripper` maps world +z to.
    """
    return np.asarray(T)[..., 2, :3]


@functools.lru_cache(maxsize=4)
def _rigid(geometry: FingerDesign) -> RigidGripper:
    return RigidGripper.build(geometry, COARSE_EDGE)


def fingers_box(openings, geometry: FingerDesign | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners [m] of the box bounding both fingers at ``openings``, palm frame."""
    g = _rigid(geometry or FingerDesign())
    local = g.world(np.eye(3)[None], np.zeros((1, 3)), np.asarray(openings, dtype=float).reshape(1, 2))[0]
    fingers = local[g.side != 0]
    return fingers.min(axis=0), fingers.max(axis=0)


def partial_cloud(
    obj: GraspObject,
    T: np.ndarray,
    openings,
    rng: np.random.Generator,
    *,
    n: int = 1024,
    geometry: FingerDesign | None = None,
) -> PartialCloud:
    """The cloud of ``obj`` (COM at world x = y = 0, resting on the ground) for palm pose ``T`` (4x4).

    Raises :class:`PoseError` when ``MIN_INSIDE`` or fewer samples lie inside the fingers' box.
    """
    import trimesh

    lo, hi = fingers_box(openings, geometry)
    seed = int(rng.integers(0, 2**32))
    samples, _ = trimesh.sample.sample_surface(obj.mesh, OVERSAMPLE * n, seed=seed)
    local = to_gripper(T, samples + scene_offset(obj))
    inside = local[np.all((local >= lo) & (local <= hi), axis=1)]
    if len(inside) < MIN_INSIDE:
        raise PoseError(
            f"only {len(inside)} of {OVERSAMPLE * n} surface samples lie inside the fingers' box "
            f"(at least {MIN_INSIDE} needed)"
        )
    pick = rng.choice(len(inside), size=n, replace=len(inside) < n)
    return PartialCloud(inside[pick].astype(np.float32), int(len(inside)))
