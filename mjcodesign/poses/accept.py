"""The checks every grasp candidate passes, and the refinement-and-ranking of a batch of poses.

Whatever proposes the poses (the antipodal sampler, an AnyGrasp import), :func:`refine_and_rank` gives
each its start openings (the part it grasps in the fingers' sweep slab), refines it
(:func:`mjcodesign.poses.refine.refine`), drops it with the reason (:class:`Rejection`) when it collides,
cannot reach the object or cannot start the grasp motion, and ranks the rest. A pose that still
penetrates more than ``MAX_PENETRATION`` on the dense point set is dropped.
"""

from __future__ import annotations

import enum

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.models.types import MAX_OPENING
from mjcodesign.objects import FingerSweep, GraspObject, SweepStatus, sweep_starts
from mjcodesign.poses.candidates import MAX_PENETRATION, Candidates, rank_order
from mjcodesign.poses.grid import ObjectSDF
from mjcodesign.poses.gripper import COARSE_EDGE, RigidGripper, scene_offset
from mjcodesign.poses.refine import LOSS_THRESHOLD, MAX_FINGER_GAP, T_RANGE, approach_depth, refine

__all__ = ["OPEN_CLEARANCE", "Rejection", "grasped_part_fits", "refine_and_rank", "start_check"]

OPEN_CLEARANCE = 0.004
"""Refinement starts each inner face this far outside the object [m]."""


class Rejection(enum.Enum):
    """Why a candidate pose was dropped; the value is the reason written in ``rejected``."""

    FRICTION_CONE = "friction cone"
    PAIR_TOO_WIDE = "wider than the opening"
    STEEP_AXIS = "closing axis too steep"
    PART_TOO_WIDE = "grasped part wider than the stroke"
    GROUND = "ground collision"
    OBJECT = "object collision"
    NO_REACH = "finger does not reach the object"
    LOSS = "loss above threshold"
    START_TOO_WIDE = "too wide for the stroke at the start opening"
    START_NO_ROOM = "no room to open a finger"
    START_GROUND = "below the ground at the start opening"


def _slab_openings(obj: GraspObject, T: np.ndarray, design: FingerDesign) -> np.ndarray:
    """Per pose, how far the grasped part reaches on each finger's side of the palm centre (P, 2) [m].

    The part around the palm centre in the fingers' sweep slab (:func:`mjcodesign.objects.sweep_starts`
    on the object's collision geometry); NaN where there is none on that side.
    """
    v, f = obj.collision_mesh()
    sweep = FingerSweep.of(design)
    _, _, reach = sweep_starts(
        v + scene_offset(obj), f, T[:, :3, :3], T[:, :3, 3], np.zeros((len(T), 2)), sweep
    )
    return np.where(np.isfinite(reach), reach, np.nan)


def grasped_part_fits(obj: GraspObject, T: np.ndarray, design: FingerDesign) -> np.ndarray:
    """Whether the part between the fingers fits the stroke on both sides at poses (P, 4, 4): (P,)."""
    return _initial_openings(obj, T, design)[1]


def _initial_openings(obj, T, design) -> tuple[np.ndarray, np.ndarray]:
    """Start openings (P, 2) and whether the grasped part fits the stroke on both sides (P,)."""
    ext = _slab_openings(obj, T, design)
    fits = ~np.any(ext + OPEN_CLEARANCE > MAX_OPENING, axis=1)
    s = np.clip(np.nan_to_num(ext, nan=0.0) + OPEN_CLEARANCE, 0.0, MAX_OPENING)
    return s, fits


def _below_ground(T, s, design) -> np.ndarray:
    """Poses whose gripper stays below the ground wherever the approach offset t moves it (P,)."""
    g = RigidGripper.build(design, COARSE_EDGE)
    z = g.world(T[:, :3, :3], T[:, :3, 3], s)[..., 2].min(axis=1)
    return z + T_RANGE * np.abs(T[:, 2, 2]) < -MAX_PENETRATION


def start_check(
    obj: GraspObject, T: np.ndarray, s: np.ndarray, design: FingerDesign
) -> list[Rejection | None]:
    """Why the grasp motion cannot start at each pose (P,), None where it can.

    The scene opens each finger outside the part it grasps (:func:`mjcodesign.objects.sweep_starts` on
    the object's collision geometry, the grasp scenario's rule); there no finger may be under the ground.
    """
    if len(T) == 0:
        return []
    sweep = FingerSweep.of(design)
    v, f = obj.collision_mesh()
    starts, status, _ = sweep_starts(v + scene_offset(obj), f, T[:, :3, :3], T[:, :3, 3], s, sweep)
    g = RigidGripper.build(design, COARSE_EDGE)
    z = g.world(T[:, :3, :3], T[:, :3, 3], starts)[..., 2].min(axis=1)
    out: list[Rejection | None] = [None] * len(T)
    for k in range(len(T)):
        if np.any(status[k] == SweepStatus.TOO_WIDE):
            out[k] = Rejection.START_TOO_WIDE
        elif np.any(status[k] == SweepStatus.NO_ROOM):
            out[k] = Rejection.START_NO_ROOM
        elif z[k] < 0.0:  # the scene refuses a fingertip or palm under the ground at the start
            out[k] = Rejection.START_GROUND
    return out


def refine_and_rank(
    obj: GraspObject,
    T: np.ndarray,
    scores: np.ndarray,
    design: FingerDesign,
    rejected: dict[str, int],
    *,
    source_index: np.ndarray | None = None,
    copy_index: np.ndarray | None = None,
    source: str = "sampler",
    sdf: ObjectSDF | None = None,
    fit_depth: bool = False,
) -> Candidates:
    """Refine palm poses (P, 4, 4) with prior scores (P,), drop the failures and rank the rest.

    Each drop is counted in ``rejected`` (reason -> count), which the result carries, and listed with
    its provenance in :attr:`Candidates.refused`. ``source_index`` (P,) and ``copy_index`` (P,) say
    where each pose came from (default: its position, no copy). ``fit_depth``: each pose first moves along
    its approach to the depth :func:`~mjcodesign.poses.refine.approach_depth` sets, where the openings
    are then refined.
    """
    P = len(T)
    src = np.arange(P) if source_index is None else np.asarray(source_index, dtype=np.int64)
    cpy = np.zeros(P, dtype=np.int64) if copy_index is None else np.asarray(copy_index, dtype=np.int64)
    why: list[Rejection | None] = [None] * P
    s0, fits = _initial_openings(obj, T, design)
    if fit_depth:  # deeper, the grasped part may differ: its start openings again
        T = T.copy()
        T[fits] = approach_depth(obj, T[fits], s0[fits], design=design, sdf=sdf)
        s0, fits = _initial_openings(obj, T, design)
    low = fits & _below_ground(T, s0, design)
    _mark(why, ~fits, Rejection.PART_TOO_WIDE)
    _mark(why, low, Rejection.GROUND)
    run = np.flatnonzero(fits & ~low)
    r = refine(obj, T[run], s0[run], design=design, sdf=sdf, fixed_offset=fit_depth)
    ground = r.min_ground < -MAX_PENETRATION
    collide = ~ground & (r.min_object < -MAX_PENETRATION)
    high = ~(ground | collide) & (r.loss > LOSS_THRESHOLD)
    reach = high & (r.gap.max(axis=1) > MAX_FINGER_GAP)
    for mask, reason in (
        (ground, Rejection.GROUND),
        (collide, Rejection.OBJECT),
        (reach, Rejection.NO_REACH),
        (high & ~reach, Rejection.LOSS),
    ):
        _mark(why, _scatter(run, mask, P), reason)
    keep = np.flatnonzero(~(ground | collide | high))
    for k, reason in zip(keep, start_check(obj, r.matrices[keep], r.openings[keep], design), strict=True):
        why[run[k]] = reason
    ok = np.array([why[i] is None for i in run], dtype=bool)
    final = scores[run][ok] / (1.0 + r.loss[ok])
    order = rank_order(final, src[run][ok])
    idx = np.flatnonzero(ok)[order]
    for reason in why:
        if reason is not None:
            rejected[reason.value] = rejected.get(reason.value, 0) + 1
    refused = [(int(src[i]), int(cpy[i]), why[i].value) for i in range(P) if why[i] is not None]
    return Candidates(
        r.matrices[idx],
        r.openings[idx],
        final[order],
        r.min_signed_distance[idx],
        r.loss[idx],
        rejected,
        source_index=src[run][idx],
        copy_index=cpy[run][idx],
        source=source,
        refused=refused,
    )


def _mark(why: list, mask: np.ndarray, reason: Rejection) -> None:
    """Record ``reason`` for the poses of ``mask`` that have none yet."""
    for i in np.flatnonzero(mask):
        if why[i] is None:
            why[i] = reason


def _scatter(rows: np.ndarray, mask: np.ndarray, n: int) -> np.ndarray:
    out = np.zeros(n, dtype=bool)
    out[rows[mask]] = True
    return out
