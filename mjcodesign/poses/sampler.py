"""The antipodal grasp sampler: contact pairs on the object's surface, turned into palm poses.

Pairs of surface points whose normals pass a friction-cone test are the contact candidates; each is
scored by its alignment and its grasp axis' distance to the COM, picked at random by score, approached
from above or from the side, and handed to :func:`mjcodesign.poses.accept.refine_and_rank`.
Frames are :mod:`mjcodesign.poses.gripper`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import PoseError
from mjcodesign.models.types import MAX_OPENING, PALM_HALF
from mjcodesign.objects import GraspObject, check_seed
from mjcodesign.poses.accept import OPEN_CLEARANCE, Rejection, grasped_part_fits, refine_and_rank
from mjcodesign.poses.candidates import Candidates, augment_poses
from mjcodesign.poses.grid import ObjectSDF
from mjcodesign.poses.gripper import palm_frame, rotvec, scene_offset
from mjcodesign.poses.sdf import MeshSDF

__all__ = ["FRICTION", "SamplerOptions", "antipodal_pairs", "ray_pairs", "sample_poses"]

FRICTION = 0.5
"""Friction coefficient of the antipodal cone test: half the contact's μ = 1 (paper) as a margin."""

_TIP_INSET = 0.05  # contacts sit this far from the fingertip along the finger [m] (ANYGRASP_DEPTH)
_MIN_TIP_INSET = 0.004  # ... or this close to the tip for contacts near the ground [m]
_MIN_WIDTH = 5e-4  # contacts closer than this are one point [m] (the YCB bowl's wall is 0.9 mm)
_RAY_START = 1e-5  # rays start this far inside the surface, past their own triangle [m]
_COM_SCALE = 0.03  # score decays with the grasp axis' distance to the COM on this scale [m]
_MAX_AXIS_SLOPE = 0.5  # |sin| of the closing axis' elevation: fingers that open along a steep axis
# swing a tip into the ground or over the object at the start opening
# Closing axes steeper than this (|sin| of the elevation, 11.5 deg) are drawn only after the flatter
# ones: over ycb-in-domain (4 sampler poses each, 11 designs, light density, 2026-12-01) every design
# let fall 9 of 115 side grasps closing within 11.5 deg of horizontal, 13 of 36 steeper ones.
_FLAT_AXIS_SLOPE = 0.2
_STEEP_WEIGHT = 0.05  # prior factor of a pair whose closing axis is steeper than _FLAT_AXIS_SLOPE
_SIDE_CLEARANCE = 0.003  # side grasps: fingers' lower edge above the ground [m]
# Top grasps need the contact this far from the fingertips [m]: over ycb-in-domain (4 poses each, 11
# designs, the earlier sampler), top grasps whose fingers touched the object within 35 mm of the tip
# held in 8 of 103 cases, deeper ones in 7 of 14.
_TOP_MIN_INSET = 0.035
# Prior factor of pairs that only a top approach can take. In the same run, every design let fall 30
# of 32 top grasps (29 of 29 on objects under 10 cm: the downward disturbance pushes the object out of
# a top-down pinch), 22 of 151 side grasps: a top grasp is drawn only where no side grasp is left.
_TOP_ONLY_WEIGHT = 0.05
_MAX_TILT = np.deg2rad(25.0)  # random tilt of the approach about the closing axis
# ... but a side approach tilts up (palm below the contact, fingers pointing up) by at most this: in
# the same run every design let fall 9 of 27 side grasps tilted up more than 6 deg, 13 of 124 others.
_MAX_UP_TILT = np.deg2rad(5.0)
_TOP_MIN_COS = 0.35  # a top approach needs the closing axis this far from vertical (|u_z| < 0.94)
_FIRST_RATE = 0.7  # expected share of candidates accepted, before the first round has measured it
_MIN_RATE = 0.1  # ... and the smallest share a round plans for
_ROUND_MARGIN = 1.3  # a round tries this many more candidates than the measured rate asks for
_MIN_ROUND = 8  # candidates per round at least (a numpy batch amortises its fixed cost)
_MIN_TRIES = 64  # candidates tried at most, at least (large objects accept few: 019_pitcher_base)
# When every pair of the surface samples has been tried short of n poses (thin rims: 024_bowl had 196
# pairs for 50 poses), up to this many fresh sets of samples are drawn, seeded seed + k * step.
_EXTRA_POOLS = 4
_POOL_SEED_STEP = 1_000_003
# Where the pass above accepts fewer than asked, the fallback (_fallback) tries at most this many more
# candidates, in rounds of _FALLBACK_ROUND.
_FALLBACK_TRIES = 2048
_FALLBACK_ROUND = 64
_FALLBACK_POOLS = 8  # ... drawing up to this many more sets of surface samples than _EXTRA_POOLS


@dataclass(frozen=True, kw_only=True)
class SamplerOptions:
    """Antipodal sampler settings."""

    surface_samples: int = 512
    """Object surface points; pairs among them are the contact candidates."""
    top_fraction: float = 0.0
    """Share of the candidates that a top approach can take with the contact ``_TOP_MIN_INSET`` from the
    fingertips that is approached from above even where a side approach fits (the rest from the side,
    which held far more often over ycb-in-domain: docs/benchmarks.md). Pairs that no side approach can
    take are approached from above whatever this is."""
    augment: int = 0
    """Noisy copies per candidate (σ ``NOISE_TRANSLATION``, ``NOISE_ROTATION``), besides the original;
    they rank after every distinct candidate (:func:`~mjcodesign.poses.candidates.rank_order`)."""
    candidates_per_pose: int = 16
    """At most this many candidates are tried per requested pose (the rounds stop earlier once enough
    are accepted). With 8, 50 poses fell short on 5 of the 46 ycb-in-domain objects (024_bowl 34,
    028_skillet_lid 33); the rounds stop as soon as n are accepted, so the others cost no more."""
    fit_depth: bool = False
    """Each candidate first moves along its approach to the depth the paper's L_init sets
    (:func:`~mjcodesign.poses.refine.approach_depth`); otherwise the contacts stay about ``_TIP_INSET``
    from the fingertips."""

    def __post_init__(self) -> None:
        if not (0.0 <= self.top_fraction <= 1.0):
            raise PoseError(f"top_fraction must be in [0, 1], got {self.top_fraction}")
        if self.surface_samples < 8 or self.augment < 0 or self.candidates_per_pose < 1:
            raise PoseError("surface_samples >= 8, augment >= 0 and candidates_per_pose >= 1 required")


def antipodal_pairs(points: np.ndarray, normals: np.ndarray, friction: float = FRICTION):
    """Index pairs (i, j) whose contacts pass the friction-cone test, and their alignment.

    Contact i pushes along ``u = (p_j − p_i) / |p_j − p_i|``; both −n_i·u and n_j·u must exceed
    cos(atan μ). Returns (i, j, width [m], alignment = mean of the two cosines).
    """
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    i, j = np.triu_indices(len(p), k=1)
    v = p[j] - p[i]
    w = np.linalg.norm(v, axis=1)
    u = v / np.maximum(w, 1e-12)[:, None]
    c_i = -np.einsum("kj,kj->k", n[i], u)
    c_j = np.einsum("kj,kj->k", n[j], u)
    cos_max = 1.0 / np.sqrt(1.0 + friction**2)
    ok = (c_i >= cos_max) & (c_j >= cos_max) & (w >= _MIN_WIDTH)
    return i[ok], j[ok], w[ok], 0.5 * (c_i[ok] + c_j[ok])


def ray_pairs(
    sdf: MeshSDF,
    points: np.ndarray,
    normals: np.ndarray,
    face_normals: np.ndarray,
    friction: float = FRICTION,
):
    """Antipodal pairs found by casting a ray from each surface point into the object.

    The ray from p along −n meets the opposite surface at q with normal m; the pair passes when
    m · (−n) ≥ cos(atan μ) (the first contact's cosine is 1). Returns (p, q, width [m], alignment).
    """
    start = points - _RAY_START * normals
    t, face = sdf.ray(start, -normals)
    hit = np.isfinite(t) & (face >= 0)
    q = start - t[:, None] * normals
    m = face_normals[np.where(hit, face, 0)]
    c = -np.einsum("ij,ij->i", m, normals)
    width = t + _RAY_START
    ok = hit & (c >= 1.0 / np.sqrt(1.0 + friction**2)) & (width >= _MIN_WIDTH)
    return points[ok], q[ok], width[ok], 0.5 * (1.0 + c[ok])


def sample_poses(
    obj: GraspObject,
    n: int,
    *,
    seed: int = 0,
    options: SamplerOptions | None = None,
    design: FingerDesign | None = None,
    points: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    cache_dir: str | Path | None = None,
) -> Candidates:
    """Up to ``n`` refined antipodal grasps of ``obj``, best first; deterministic per ``seed`` (>= 0).

    ``points``/``normals`` (object COM frame [m], outward unit normals) replace the mesh's surface
    samples, e.g. a partial point cloud from a camera; the refinement still uses the mesh. The
    candidates are drawn by prior score without replacement and refined in rounds, one numpy batch a
    round, until ``n`` distinct candidates are accepted or ``options.candidates_per_pose`` × ``n`` (at
    least 64) have been tried; where fewer than ``n`` are accepted then, :func:`_fallback` tries the
    pairs left and fresh samples' pairs (so the candidates of an object that gets ``n`` are those of
    the pass alone). ``cache_dir`` keeps the object's signed-distance grid (:class:`ObjectSDF`).
    :class:`PoseError` when no candidate is accepted, with every reason counted.
    """
    seed = check_seed(seed, error=PoseError)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise PoseError(f"n must be an integer >= 1, got {n!r}")
    options = options or SamplerOptions()
    design = design or FingerDesign()
    rng = np.random.default_rng(seed)
    if points is None:
        pts, nrm = _surface(obj, options.surface_samples, seed)
    else:
        pts, nrm = _check_cloud(points, normals)
    sdf = ObjectSDF(obj.mesh, cache_dir=cache_dir)
    rejected: dict[str, int] = {}
    centre, u, prior, steep = _pool(obj, pts, nrm, sdf if points is None else None, design, rejected)
    if len(prior) == 0 and not steep:
        raise PoseError(
            f"object {obj.name} is too wide for the stroke: no antipodal pair is closer than "
            f"{2000 * (MAX_OPENING - OPEN_CLEARANCE):.0f} mm (each finger opens {1000 * MAX_OPENING:.0f} mm; "
            f"{rejected})"
        )
    if len(prior) == 0:
        raise PoseError(
            f"object {obj.name}: every antipodal pair that fits the stroke closes along an axis steeper "
            f"than {np.degrees(np.arcsin(_MAX_AXIS_SLOPE)):.0f} deg from horizontal ({rejected})"
        )
    cap = max(n * options.candidates_per_pose, _MIN_TRIES)
    order = _weighted_order(prior, rng)[:cap]
    parts: list[Candidates] = []
    tried = extra = 0
    while True:
        got = len({int(x) for c in parts for x in c.source_index})
        if got >= n:
            break
        if tried >= len(order):  # every pair tried: draw a fresh set of surface samples, if allowed
            if points is not None or extra >= _EXTRA_POOLS or len(order) >= cap:
                break
            extra += 1
            more = _pool(
                obj,
                *_surface(obj, options.surface_samples, seed + _POOL_SEED_STEP * extra),
                sdf,
                design,
                rejected,
            )
            order = np.r_[order, len(prior) + _weighted_order(more[2], rng)][:cap]
            centre, u, prior = np.r_[centre, more[0]], np.r_[u, more[1]], np.r_[prior, more[2]]
            continue
        rate = got / tried if tried else _FIRST_RATE
        size = int(np.ceil(_ROUND_MARGIN * (n - got) / max(rate, _MIN_RATE)))
        pick = order[tried : tried + max(size, _MIN_ROUND)]
        T = _approach(obj, centre[pick], u[pick], design, options.top_fraction, rng)
        parts.append(_refine_round(obj, T, prior[pick], tried, design, options, rng, rejected, sdf))
        tried += len(pick)
    got = len({int(x) for c in parts for x in c.source_index})
    if got < n and not _out_of_reach(parts):  # the fallback: only where the pass above fell short
        more = range(extra + 1, _EXTRA_POOLS + _FALLBACK_POOLS + 1) if points is None else range(0)
        pools = [seed + _POOL_SEED_STEP * k for k in more]
        pairs = _Pairs(centre, u, prior)
        parts += _fallback(
            obj, pairs, order[:tried], n - got, tried, pools, design, options, rng, rejected, sdf
        )
    out = Candidates.concat(parts)
    if len(out) == 0 and all(r == Rejection.PART_TOO_WIDE.value for _, _, r in out.refused):
        raise PoseError(
            f"object {obj.name} is too wide for the stroke: at every pose the part between the fingers "
            f"reaches past the {1000 * MAX_OPENING:.0f}-mm opening of a finger"
        )
    if len(out) == 0:  # every reason, exact: the pairs dropped before a pose, then every pose refused
        dropped = (Rejection.FRICTION_CONE, Rejection.PAIR_TOO_WIDE, Rejection.STEEP_AXIS)
        refused: dict[str, int] = {}
        for _, _, r in out.refused:
            refused[r] = refused.get(r, 0) + 1
        raise PoseError(
            f"object {obj.name}: no grasp candidate accepted. Contact pairs of the surface samples dropped: "
            + ", ".join(f"{r.value} {rejected.get(r.value, 0)}" for r in dropped)
            + f"; all {len(out.refused)} candidates from the other pairs refused: "
            + ", ".join(f"{k} {v}" for k, v in sorted(refused.items(), key=lambda kv: -kv[1]))
        )
    out.rejected = dict(rejected)
    return out.head(n)


def _surface(obj: GraspObject, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` seeded surface samples of the object (COM frame) [m] and their outward normals."""
    import trimesh

    pts, face = trimesh.sample.sample_surface(obj.mesh, count, seed=seed)
    return pts, np.asarray(obj.mesh.face_normals)[face]


def _pool(obj, pts, nrm, sdf, design, rejected: dict[str, int]):
    """Contact pairs of the samples (``sdf``: also the ray pairs, None for a point cloud).

    Returns the pairs' centres (k, 3), closing axes (k, 3), prior scores (k,) and whether any pair
    was dropped only for its steep axis; the drops are counted in ``rejected``.
    """
    i, j, width, align = antipodal_pairs(pts, nrm)
    _count(rejected, Rejection.FRICTION_CONE, len(pts) * (len(pts) - 1) // 2 - len(i))
    pa, pb = pts[i], pts[j]
    if sdf is not None:  # thin walls, rims and handles: the surface straight across from each sample
        ra, rb, rw, ral = ray_pairs(sdf.exact, pts, nrm, np.asarray(obj.mesh.face_normals))
        pa, pb, width, align = np.r_[pa, ra], np.r_[pb, rb], np.r_[width, rw], np.r_[align, ral]
    wide = 0.5 * width + OPEN_CLEARANCE > MAX_OPENING
    steep = ~wide & (np.abs(pb[:, 2] - pa[:, 2]) > _MAX_AXIS_SLOPE * width)
    _count(rejected, Rejection.PAIR_TOO_WIDE, int(np.sum(wide)))
    _count(rejected, Rejection.STEEP_AXIS, int(np.sum(steep)))
    ok = ~(wide | steep)
    pa, pb, width, align = pa[ok], pb[ok], width[ok], align[ok]
    centre = 0.5 * (pa + pb)
    u = (pb - pa) / width[:, None]
    r_com = np.linalg.norm(np.cross(centre, u), axis=1)  # COM (origin) to the grasp line
    can_side, _, _ = _reach(centre + scene_offset(obj), u, design)
    # Pairs that only a top approach can take, and steep closing axes, come after the others.
    flat = np.abs(u[:, 2]) <= _FLAT_AXIS_SLOPE
    prior = align * np.exp(-r_com / _COM_SCALE)
    prior = prior * np.where(can_side, 1.0, _TOP_ONLY_WEIGHT) * np.where(flat, 1.0, _STEEP_WEIGHT)
    return centre, u, prior, bool(np.any(steep))


@dataclass(frozen=True)
class _Pairs:
    """The contact pairs of every pool drawn.

    Centres (k, 3) [m, COM frame], closing axes (k, 3) and prior scores (k,).
    """

    centre: np.ndarray
    u: np.ndarray
    prior: np.ndarray


def _out_of_reach(parts: list[Candidates]) -> bool:
    """Whether the regular pass accepted nothing and refused every pose it refined as out of reach.

    Such an object is smaller than the gap the closed fingers leave: no other pair of its surface
    points does better, so the fallback (thousands of refinements) is skipped.
    """
    refused = [r for c in parts for _, _, r in c.refused]
    accepted = sum(len(c) for c in parts)
    return accepted == 0 and bool(refused) and all(r == Rejection.NO_REACH.value for r in refused)


def _refine_round(obj, T, prior, first, design, options, rng, rejected, sdf) -> Candidates:
    """Refine-and-rank one round of palm poses (P, 4, 4) with their noisy copies; sources ``first``..."""
    copies = options.augment + 1
    T = augment_poses(T, options.augment, rng)
    return refine_and_rank(
        obj,
        T,
        np.repeat(prior, copies),
        design,
        rejected,
        source_index=np.repeat(np.arange(first, first + len(prior)), copies),
        copy_index=np.tile(np.arange(copies), len(prior)),
        sdf=sdf,
        fit_depth=options.fit_depth,
    )


def _fallback(obj, pairs: _Pairs, done, need, first, pools, design, options, rng, rejected, sdf):
    """More candidates where the regular pass accepted fewer than asked (``need`` more).

    The pairs that pass never tried (``done``: those it tried), then the pairs of fresh sets of
    surface samples (``pools``: their seeds; none for a point cloud), each set in random order (not
    by prior: the prior favours pairs near the COM, where that pass has just failed) and approached
    as that pass approaches them. On an object too wide as a whole, the pairs that fit the stroke are
    far from the COM (the tab of 071_nine_hole_peg_test, a 073-g_lego_duplo brick's sides): low-prior,
    past that pass's cap. At most ``_FALLBACK_TRIES`` candidates in all, in rounds of
    ``_FALLBACK_ROUND``; their sources are numbered from ``first`` on.
    """
    parts: list[Candidates] = []
    left = np.setdiff1d(np.arange(len(pairs.prior)), done)
    order = rng.permutation(left)
    tried = 0
    pools = list(pools)
    while tried < _FALLBACK_TRIES and len({int(x) for c in parts for x in c.source_index}) < need:
        if len(order) == 0:
            if not pools:
                break
            pts, nrm = _surface(obj, options.surface_samples, pools.pop(0))
            pairs = _Pairs(*_pool(obj, pts, nrm, sdf, design, rejected)[:3])
            order = rng.permutation(len(pairs.prior))
            continue
        pick, order = order[:_FALLBACK_ROUND], order[_FALLBACK_ROUND:]
        pick = pick[: _FALLBACK_TRIES - tried]
        T = _approach(obj, pairs.centre[pick], pairs.u[pick], design, options.top_fraction, rng)
        parts.append(
            _refine_round(obj, T, pairs.prior[pick], first + tried, design, options, rng, rejected, sdf)
        )
        tried += len(pick)
    return parts


def _count(rejected: dict[str, int], reason: Rejection, k: int) -> None:
    rejected[reason.value] = rejected.get(reason.value, 0) + int(k)


def _weighted_order(prior: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A permutation drawn by weight without replacement (Gumbel top-k: argsort of log w + Gumbel)."""
    keys = np.log(prior) + rng.gumbel(size=len(prior))
    return np.argsort(-keys, kind="stable")


def _reach(world_centre: np.ndarray, u: np.ndarray, design: FingerDesign):
    """Which approaches contact pairs admit, (P,) each: side, deep top, top at all.

    Deep top: the contact ``_TOP_MIN_INSET`` from fingertips above the ground; top at all: the closing
    axis is not too steep for the fingers.
    """
    height = world_centre[:, 2]
    # A side approach lays the 20-mm-wide fingers flat: the contact must clear the ground by half that.
    side_axis = np.linalg.norm(np.cross([0.0, 0.0, 1.0], u), axis=1) > 1e-6
    can_side = (height >= 0.5 * design.width + _SIDE_CLEARANCE) & side_axis
    can_top = np.abs(u[:, 2]) < np.sqrt(1 - _TOP_MIN_COS**2)
    deep_top = can_top & (height - _SIDE_CLEARANCE >= _TOP_MIN_INSET)
    return can_side, deep_top, can_top


def _approach(obj, centre, u, design, top_fraction, rng) -> np.ndarray:
    """Palm poses (P, 4, 4) with the contacts ``_TIP_INSET`` from the fingertips (less near the ground).

    A side approach is taken wherever the contact clears the ground by half the finger width; a top
    approach only where the contact can also sit ``_TOP_MIN_INSET`` from fingertips above the ground
    (a share ``top_fraction`` of those), or where no side approach fits (low, flat objects: the
    contact then sits near the fingertip). Where the part between the fingers is too wide for the
    stroke from the chosen side but not from the other (a handle over a flat body, a rim), the other
    is taken.
    """
    P = len(centre)
    world_centre = centre + scene_offset(obj)
    can_side, deep_top, can_top = _reach(world_centre, u, design)
    top = can_top & (((rng.random(P) < top_fraction) & deep_top) | ~can_side)
    tilt = rng.uniform(-1.0, 1.0, size=P)
    T = _palm_poses(world_centre, centre, u, design, top, tilt)
    other = np.where(top, can_side, can_top)
    swap = other & ~grasped_part_fits(obj, T, design)
    if np.any(swap):
        alt = _palm_poses(world_centre[swap], centre[swap], u[swap], design, ~top[swap], tilt[swap])
        T[swap] = np.where(grasped_part_fits(obj, alt, design)[:, None, None], alt, T[swap])
    return T


def _palm_poses(world_centre, centre, u, design, top, tilt) -> np.ndarray:
    """Palm poses (P, 4, 4): from above where ``top``, else from the side; ``tilt`` in [-1, 1] (P,)."""
    P = len(centre)
    z = np.array([0.0, 0.0, 1.0])
    height = world_centre[:, 2]
    side = np.cross(z, u)
    side_norm = np.linalg.norm(side, axis=1)
    a_top = -z + u[:, 2:3] * u
    side[side_norm <= 1e-6] = [1.0, 0.0, 0.0]
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    # Approach from outside: towards the object's vertical axis, a random sign when on it.
    sign = -np.sign(np.einsum("pk,pk->p", side, centre))
    sign[sign == 0] = 1.0
    a = np.where(top[:, None], a_top, sign[:, None] * side)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    # A side approach tilts up or down only as far as the fingertips (down) and the palm (up) stay
    # above the ground with the contact _TIP_INSET from the tip: tilted further, the refinement backs
    # the fingers out and the contact ends at the fingertip (ycb-in-domain, 4 poses each, 11 designs:
    # side grasps tilted more than 17 deg down held in 9 of 30 cases, the others in 67 of 73).
    down = np.arcsin(np.clip((height - 0.5 * design.width - _SIDE_CLEARANCE) / _TIP_INSET, 0.0, 1.0))
    up = np.arcsin(np.clip((height - PALM_HALF[0] - _SIDE_CLEARANCE) / (design.length - _TIP_INSET), 0, 1))
    lo, hi = -np.minimum(down, _MAX_TILT), np.minimum(up, _MAX_UP_TILT)
    angle = np.where(top, _MAX_TILT * tilt, lo + (hi - lo) * 0.5 * (tilt + 1.0))
    # Rotating by φ about u changes a_z at the rate (u × a)_z: its sign makes a positive tilt "up".
    up_sign = np.sign(np.cross(u, a)[:, 2])
    up_sign[up_sign == 0] = 1.0
    phi = np.where(top, angle, angle * up_sign)
    a = np.einsum("pij,pj->pi", rotvec(u * phi[:, None]), a)
    T = np.tile(np.eye(4), (P, 1, 1))
    T[:, :3, :3] = palm_frame(a, u)
    # Low contacts slide towards the fingertip so that the tip starts above the ground.
    reach = (height - _SIDE_CLEARANCE) / np.maximum(-a[:, 2], 1e-6)
    inset = np.clip(reach, _MIN_TIP_INSET, _TIP_INSET)
    T[:, :3, 3] = world_centre - a * (design.length - inset)[:, None]
    return T


def _check_cloud(points, normals) -> tuple[np.ndarray, np.ndarray]:
    """A point cloud's points (n, 3) [m] and unit normals (n, 3); :class:`PoseError` if unusable."""
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float) if normals is not None else None
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise PoseError("point cloud must have at least two points, shape (n, 3)")
    if n is None or n.shape != p.shape:
        raise PoseError("point cloud needs one normal per point, shape (n, 3)")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(n))):
        raise PoseError("point cloud contains NaN or inf")
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    if np.any(norm < 1e-9):
        raise PoseError("point cloud has zero-length normals")
    return p, n / norm
