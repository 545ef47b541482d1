"""One grasp through the surrogate: an object and a pose made into the inputs the dataset would hold.

The object is loaded as data generation loads it (same mesh repair and ``object_seed``; no convex
decomposition is needed), the pose comes from :func:`mjcodesign.jobs.resolve_pose` (a candidate
file ``FILE.npz[:ROW]``, a JSON pose, ``auto`` or ``best``), and the partial cloud from
:func:`mjcodesign.data.partial_cloud` with the dataset's point count, in the gripper frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjcodesign.data import partial_cloud
from mjcodesign.data.cloud import gripper_up, to_gripper
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.jobs import resolve_pose
from mjcodesign.models.types import GripperPose
from mjcodesign.objects import at_mass, load_object, published_mass_or_none
from mjcodesign.poses import scene_offset
from mjcodesign.surrogate.checkpoint import load_surrogate
from mjcodesign.surrogate.inference import GraspBatch, Poses, Surrogate

__all__ = ["pose_matrix", "predict_grasp", "training_density"]


def pose_matrix(pose: GripperPose) -> np.ndarray:
    """The 4x4 palm pose [m] of a :class:`GripperPose` (:meth:`GripperPose.matrix`)."""
    return pose.matrix()


def training_density(surrogate: Surrogate) -> float:
    """The middle of the training data's density range [kg/m³] (the default of a prediction)."""
    d = surrogate.meta["dataset"]["density"]
    return 0.5 * (float(d["low_kg_m3"]) + float(d["high_kg_m3"]))


def predict_grasp(
    checkpoint: str | Path,
    source: str,
    pose: str,
    design: Stiffness,
    density: float | None = None,
    *,
    seed: int = 0,
    cache_dir: str | Path | None = None,
) -> dict:
    """The surrogate's outputs for ``design`` grasping object ``source`` at ``pose``, JSON-ready.

    ``density`` [kg/m³] defaults to the dataset's regime: the object's published mass where the
    dataset's mass rule takes them (``real``, ``auto``) and it has one, else :func:`training_density`.
    ``seed`` draws the cloud's points.
    """
    sur = load_surrogate(checkpoint)
    rho = training_density(sur) if density is None else float(density)
    if not (np.isfinite(rho) and rho > 0):
        raise DesignError(f"density must be a finite value > 0 kg/m³, got {rho}")
    ds = sur.meta["dataset"]
    obj = load_object(source, rho, seed=int(ds["object_seed"]), cache_dir=cache_dir)
    published = published_mass_or_none(source) if density is None else None
    if published is not None and ((ds.get("config") or {}).get("mass") or {}).get("mode") in ("real", "auto"):
        obj = at_mass(obj, published.mass)
        rho = obj.density
    gp = resolve_pose(pose, obj, FingerDesign(), seed=seed)
    T = pose_matrix(gp)
    cloud = partial_cloud(obj, T, gp.openings, np.random.default_rng(seed), n=int(ds["cloud_points"]))
    com = to_gripper(T, scene_offset(obj)[None])[0]
    poses = Poses(cloud.points[None], com[None], gripper_up(T)[None], np.array([obj.mass / obj.density]))
    pred = sur.predict(GraspBatch(poses, [0], [rho], design.log_e.reshape(1, -1)))
    return {
        "object": obj.name,
        "pose": {"matrix": T.tolist(), "openings": list(gp.openings)},
        "density_kg_m3": rho,
        "mass_kg": float(obj.mass),
        "design": design.as_list(),
        "body_force": pred.body_force[0].tolist(),
        "displacement": pred.displacement[0].tolist(),
        "ground_contact": float(pred.ground_contact[0]),
        "success": bool(pred.success[0]),
        "success_score": float(pred.success_score[0]),
        "success_p": None if pred.success_p is None else float(pred.success_p[0]),
        "cloud_inside": int(cloud.inside),
        "checkpoint": str(checkpoint),
    }
