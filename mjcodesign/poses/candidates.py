"""Ranked grasp candidates: the :class:`Candidates` type, its file, and the checks every pose passes.

Whatever proposes the poses (the antipodal sampler, an AnyGrasp import), :func:`refine_and_rank` gives
each its start openings, refines it (:func:`mjcodesign.poses.refine.refine`), drops it with the reason
when it collides, cannot reach the object or starts under the ground, and ranks the rest. A pose that
still penetrates more than ``MAX_PENETRATION`` on the dense point set is dropped.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import PoseError
from mjcodesign.models.types import MAX_OPENING, GripperPose
from mjcodesign.objects import GraspObject
from mjcodesign.poses.gripper import COARSE_EDGE, DENSE_EDGE, RigidGripper, rotvec, scene_offset
from mjcodesign.poses.refine import LOSS_THRESHOLD, MAX_FINGER_GAP, T_RANGE, refine
from mjcodesign.scenarios.grasp import start_openings

__all__ = [
    "MAX_PENETRATION",
    "NOISE_ROTATION",
    "NOISE_TRANSLATION",
    "OPEN_CLEARANCE",
    "Candidates",
    "approach_spread_deg",
    "augment_poses",
    "read_candidates",
    "refine_and_rank",
    "to_gripper_pose",
]

MAX_PENETRATION = 1e-3
"""Accepted poses penetrate the object or the ground by at most this much [m] (dense point set)."""
NOISE_TRANSLATION = 3e-3
"""Augmentation noise σ on the palm position [m] (paper, NOTES.md)."""
NOISE_ROTATION = 5e-3
"""Augmentation noise σ on each component of the rotation vector [rad] (paper, NOTES.md)."""
OPEN_CLEARANCE = 0.004
"""Refinement starts each inner face this far outside the object [m]."""

_MAX_OBJECT_SAMPLES = 4000  # caps the object points of the opening initialisation


@dataclass
class Candidates:
    """Ranked palm poses [m] in the scene's world, best first."""

    matrices: np.ndarray
    """Palm poses, shape (n, 4, 4)."""
    openings: np.ndarray
    """(s1, s2) per pose [m], shape (n, 2)."""
    scores: np.ndarray
    """Higher is better, in (0, 1], shape (n,)."""
    min_signed_distance: np.ndarray
    """Smallest signed distance of the gripper to the object and the ground [m], shape (n,)."""
    loss: np.ndarray
    """Refinement loss, shape (n,)."""
    rejected: dict[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.scores)

    def head(self, n: int) -> Candidates:
        """The best ``n``."""
        return Candidates(
            self.matrices[:n],
            self.openings[:n],
            self.scores[:n],
            self.min_signed_distance[:n],
            self.loss[:n],
            dict(self.rejected),
        )

    def approaches(self) -> np.ndarray:
        """Approach directions (palm −z) in the world, shape (n, 3)."""
        return -self.matrices[:, :3, 2]

    def as_dicts(self) -> list[dict]:
        """JSON-ready rows."""
        return [
            {
                "matrix": self.matrices[i].tolist(),
                "openings": self.openings[i].tolist(),
                "score": float(self.scores[i]),
                "min_signed_distance_m": float(self.min_signed_distance[i]),
            }
            for i in range(len(self))
        ]

    def save(self, path: str | Path, object_name: str) -> None:
        """An ``.npz`` that ``mjcodesign grasp --pose FILE`` reads (first row = best)."""
        np.savez(
            Path(path),
            matrices=self.matrices,
            openings=self.openings,
            scores=self.scores,
            min_signed_distance=self.min_signed_distance,
            object=np.array(object_name),
        )


def read_candidates(path: str | Path) -> Candidates:
    """Candidates saved by :meth:`Candidates.save` (``mjcodesign poses --out``)."""
    path = Path(path)
    try:
        with np.load(path) as z:
            M, s = np.asarray(z["matrices"], dtype=float), np.asarray(z["openings"], dtype=float)
            sc, sd = np.asarray(z["scores"], dtype=float), np.asarray(z["min_signed_distance"], dtype=float)
    except (OSError, ValueError, KeyError) as exc:
        raise PoseError(f"{path}: not a poses file ({type(exc).__name__}: {exc})") from exc
    if M.ndim != 3 or M.shape[1:] != (4, 4) or s.shape != (len(M), 2) or len(M) == 0:
        raise PoseError(f"{path}: expected matrices (n, 4, 4) and openings (n, 2), n >= 1")
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(s))):
        raise PoseError(f"{path}: poses file contains NaN or inf")
    return Candidates(M, s, sc, sd, np.zeros(len(M)))


def to_gripper_pose(c: Candidates, index: int = 0) -> GripperPose:
    """Row ``index`` as a :class:`~mjcodesign.models.types.GripperPose`; :class:`PoseError` if none."""
    if not (0 <= index < len(c)):
        raise PoseError(f"no grasp candidate {index} (of {len(c)}); rejected: {c.rejected}")

    return GripperPose.from_matrix(c.matrices[index], tuple(float(v) for v in c.openings[index]))


def approach_spread_deg(approaches: np.ndarray) -> float:
    """Mean angle [deg] between each approach direction and their mean direction (0: all alike)."""
    a = np.asarray(approaches, dtype=float)
    if len(a) < 2:
        return 0.0
    m = a.mean(axis=0)
    if np.linalg.norm(m) < 1e-12:
        return 90.0
    m /= np.linalg.norm(m)
    return float(np.degrees(np.mean(np.arccos(np.clip(a @ m, -1.0, 1.0)))))


def augment_poses(T: np.ndarray, copies: int, rng: np.random.Generator) -> np.ndarray:
    """Each pose followed by ``copies`` noisy copies, shape (P (1 + copies), 4, 4)."""
    if copies == 0:
        return T
    rep = np.repeat(T[:, None], copies, axis=1).reshape(-1, 4, 4)
    noise_r = rotvec(rng.normal(0.0, NOISE_ROTATION, size=(len(rep), 3)))
    rep[:, :3, :3] = noise_r @ rep[:, :3, :3]
    rep[:, :3, 3] += rng.normal(0.0, NOISE_TRANSLATION, size=(len(rep), 3))
    return np.concatenate([T[:, None], rep.reshape(len(T), copies, 4, 4)], axis=1).reshape(-1, 4, 4)


def _object_points(obj: GraspObject) -> np.ndarray:
    """Seeded surface samples, one per ``DENSE_EDGE``² up to a cap (COM frame) [m]."""
    import trimesh

    count = int(min(_MAX_OBJECT_SAMPLES, np.ceil(obj.mesh.area / DENSE_EDGE**2)))
    samples, _ = trimesh.sample.sample_surface(obj.mesh, count, seed=0)
    return samples


def _slab_openings(obj: GraspObject, T: np.ndarray, design: FingerDesign) -> np.ndarray:
    """Per pose, each finger's opening that clears the object's vertices in its sweep slab (P, 2) [m].

    The slab is the finger's width (palm |x| ≤ w/2) and length (−L ≤ palm z ≤ 0); the finger closes
    from there during refinement. NaN where no vertex lies on that side (nothing to clear).
    """
    v = _object_points(obj) + scene_offset(obj)
    R, p = T[:, :3, :3], T[:, :3, 3]
    local = np.matmul(v[None] - p[:, None], R)  # palm coordinates (P, V, 3)
    in_slab = (
        (np.abs(local[..., 0]) <= 0.5 * design.width)
        & (local[..., 2] <= 0)
        & (local[..., 2] >= -design.length)
    )
    y = np.where(in_slab, local[..., 1], np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: nothing on that side
        a = np.nanmax(np.where(y > 0, y, np.nan), axis=1)
        b = np.nanmax(np.where(y < 0, -y, np.nan), axis=1)
    return np.c_[a, b]


def _initial_openings(obj, T, design) -> tuple[np.ndarray, np.ndarray]:
    """Start openings (P, 2) and whether the object fits the stroke on both sides (P,)."""
    ext = _slab_openings(obj, T, design)
    fits = ~np.any(ext + OPEN_CLEARANCE > MAX_OPENING, axis=1)
    s = np.clip(np.nan_to_num(ext, nan=0.0) + OPEN_CLEARANCE, 0.0, MAX_OPENING)
    return s, fits


def _below_ground(T, s, design) -> np.ndarray:
    """Poses whose gripper stays below the ground wherever the approach offset t moves it (P,)."""
    g = RigidGripper.build(design, COARSE_EDGE)
    z = g.world(T[:, :3, :3], T[:, :3, 3], s)[..., 2].min(axis=1)
    return z + T_RANGE * np.abs(T[:, 2, 2]) < -MAX_PENETRATION


def _start_below_ground(obj, T, s, design) -> np.ndarray:
    """Poses that the grasp motion cannot open: too wide, or a finger under the ground (P,).

    The scene starts each finger outside the object (:func:`mjcodesign.scenarios.grasp.start_openings`).
    """
    starts = np.zeros_like(s)
    bad = np.zeros(len(T), bool)
    for k in range(len(T)):
        try:
            starts[k] = start_openings(obj, GripperPose.from_matrix(T[k], tuple(s[k])))
        except PoseError:
            bad[k] = True
    g = RigidGripper.build(design, COARSE_EDGE)
    z = g.world(T[:, :3, :3], T[:, :3, 3], starts)[..., 2].min(axis=1)
    return bad | (z < -MAX_PENETRATION)


def _count(rejected: dict[str, int], reason: str, mask: np.ndarray) -> None:
    if np.any(mask):
        rejected[reason] = rejected.get(reason, 0) + int(np.sum(mask))


def refine_and_rank(
    obj: GraspObject, T: np.ndarray, scores: np.ndarray, design: FingerDesign, rejected: dict[str, int]
) -> Candidates:
    """Refine palm poses (P, 4, 4) with prior scores (P,), drop the failures and rank the rest.

    Each drop is counted in ``rejected`` (reason -> count), which the result carries.
    """
    s0, fits = _initial_openings(obj, T, design)
    if not np.any(fits):
        raise PoseError(
            f"object {obj.name} is too large for every opening (stroke {1000 * MAX_OPENING:.0f} mm per finger)"
        )
    _count(rejected, "object wider than the opening", ~fits)
    low = fits & _below_ground(T, s0, design)
    _count(rejected, "ground collision", low)
    fits &= ~low
    T, scores, s0 = T[fits], scores[fits], s0[fits]
    r = refine(obj, T, s0, design=design)
    ground = r.min_ground < -MAX_PENETRATION
    collide = ~ground & (r.min_object < -MAX_PENETRATION)
    high = ~(ground | collide) & (r.loss > LOSS_THRESHOLD)
    reach = high & (r.gap.max(axis=1) > MAX_FINGER_GAP)
    _count(rejected, "ground collision", ground)
    _count(rejected, "object collision", collide)
    _count(rejected, "finger does not reach the object", reach)
    _count(rejected, "loss above threshold", high & ~reach)
    keep = ~(ground | collide | high)
    start_bad = np.zeros(len(keep), bool)
    start_bad[keep] = _start_below_ground(obj, r.matrices[keep], r.openings[keep], design)
    _count(rejected, "below the ground at the start opening", start_bad)
    keep &= ~start_bad
    final = scores[keep] / (1.0 + r.loss[keep])
    order = np.argsort(-final, kind="stable")
    idx = np.flatnonzero(keep)[order]
    return Candidates(
        r.matrices[idx], r.openings[idx], final[order], r.min_signed_distance[idx], r.loss[idx], rejected
    )
