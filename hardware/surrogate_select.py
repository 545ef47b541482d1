"""Score grasp candidates with the surrogate, as the paper's robot does, for one fixed design.

The measured cloud (base frame, merged from the cameras) is seen by the surrogate as in training
(:func:`mjcodesign.data.partial_cloud`): the points inside the box that bounds both fingers at the
candidate's openings, in the simulator's palm frame, drawn to the checkpoint's point count.

Frames. A hardware candidate is the gripper frame at the soft fingertips, z along the approach, y
closing (`hardware.pipeline`); the simulator's palm frame sits at the finger bases, z pointing back
from the fingers, y closing. Both put the fingers in z ∈ [-L, 0] and the openings along ±y, so
``T_palm = T_tip · F`` with F a half turn about y and a shift of the finger length L back along the
approach: z_palm = -z_tip, x_palm = -x_tip, origin L behind the tips.

What the robot cannot measure is estimated and stated in the report: the COM is the centroid of the
merged cloud, the volume (mass = density · volume) is the cloud's convex-hull volume.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.errors import PoseError

from .camera import GripperGeometry

__all__ = ["CandidateScore", "palm_frame", "score_candidates"]

MIN_INSIDE = 101  # as the dataset: a box with fewer measured points gives no prediction


@dataclass(frozen=True)
class CandidateScore:
    """The surrogate's prediction for one candidate (None fields when it could not predict)."""

    index: int
    points_inside: int
    success_score: float | None = None
    success: bool | None = None
    body_force: tuple[float, ...] | None = None
    displacement: tuple[float, ...] | None = None
    ground_contact: float | None = None
    reason: str | None = None
    """Why there is no prediction."""

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def palm_frame(T_tip: np.ndarray, finger_length: float) -> np.ndarray:
    """The simulator's palm pose (4x4) of a hardware candidate pose at the fingertips [m]."""
    T = np.asarray(T_tip, dtype=float)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3] @ np.diag([-1.0, 1.0, -1.0])
    out[:3, 3] = T[:3, 3] - finger_length * T[:3, 2]
    return out


def _hull_volume(cloud: np.ndarray) -> float:
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(cloud).volume)
    except (QhullError, ValueError) as exc:
        raise PoseError(f"the point cloud spans no volume ({str(exc).splitlines()[0]})") from None


def score_candidates(
    checkpoint: str | Path,
    design,
    density: float,
    cloud: np.ndarray,
    candidates: list,
    geometry: GripperGeometry,
    *,
    seed: int = 0,
) -> tuple[list[CandidateScore], dict]:
    """Predictions of the surrogate at ``checkpoint`` for ``design`` (a Stiffness) on every candidate.

    Returns the scores (candidate order) and the estimates used (COM, volume, mass, point count).
    """
    from mjcodesign.data.cloud import fingers_box, gripper_up, to_gripper
    from mjcodesign.surrogate import GraspBatch, Poses, load_surrogate

    sur = load_surrogate(checkpoint)
    n = int(sur.meta["dataset"]["cloud_points"])
    pts = np.asarray(cloud, dtype=float)
    com = pts.mean(axis=0)
    volume = _hull_volume(pts)
    rng = np.random.default_rng(seed)
    scores: list[CandidateScore | None] = [None] * len(candidates)
    clouds, coms, ups, where = [], [], [], []
    for i, c in enumerate(candidates):
        T = palm_frame(c.pose, geometry.finger_length)
        local = to_gripper(T, pts)
        lo, hi = fingers_box((c.s1, c.s2))
        inside = local[np.all((local >= lo) & (local <= hi), axis=1)]
        if len(inside) < MIN_INSIDE:
            scores[i] = CandidateScore(
                i, len(inside), reason=f"{len(inside)} cloud points in the fingers' box (< {MIN_INSIDE})"
            )
            continue
        pick = rng.choice(len(inside), size=n, replace=len(inside) < n)
        clouds.append(inside[pick])
        coms.append(to_gripper(T, com[None])[0])
        ups.append(gripper_up(T))
        where.append((i, len(inside)))
    if where:
        p = len(where)
        poses = Poses(np.stack(clouds), np.stack(coms), np.stack(ups), np.full(p, volume))
        batch = GraspBatch(
            poses, np.arange(p), np.full(p, float(density)), np.tile(design.log_e.ravel(), (p, 1))
        )
        pred = sur.predict(batch)
        for k, (i, inside) in enumerate(where):
            scores[i] = CandidateScore(
                i,
                inside,
                success_score=float(pred.success_score[k]),
                success=bool(pred.success[k]),
                body_force=tuple(float(v) for v in pred.body_force[k]),
                displacement=tuple(float(v) for v in pred.displacement[k]),
                ground_contact=float(pred.ground_contact[k]),
            )
    estimates = {
        "com_base_m": com.tolist(),
        "volume_m3_convex_hull": volume,
        "density_kg_m3": float(density),
        "mass_kg_estimate": float(density) * volume,
        "cloud_points": n,
    }
    return [s for s in scores if s is not None], estimates
