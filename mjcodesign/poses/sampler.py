"""The antipodal grasp sampler: contact pairs on the object's surface, turned into palm poses.

Pairs of surface points whose normals pass a friction-cone test are the contact candidates; each is
scored by its alignment and its grasp axis' distance to the COM, picked at random by score, approached
from above or from the side, and handed to :func:`mjcodesign.poses.candidates.refine_and_rank`.
Frames are :mod:`mjcodesign.poses.gripper`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import PoseError
from mjcodesign.models.types import MAX_OPENING
from mjcodesign.objects import GraspObject
from mjcodesign.poses.candidates import OPEN_CLEARANCE, Candidates, augment_poses, refine_and_rank
from mjcodesign.poses.gripper import palm_frame, rotvec, scene_offset

__all__ = ["FRICTION", "SamplerOptions", "antipodal_pairs", "sample_poses"]

FRICTION = 0.5
"""Friction coefficient of the antipodal cone test: half the contact's μ = 1 (paper) as a margin."""

_TIP_INSET = 0.05  # contacts sit this far from the fingertip along the finger [m] (ANYGRASP_DEPTH)
_MIN_TIP_INSET = 0.004  # ... or this close to the tip for contacts near the ground [m]
_MIN_WIDTH = 0.004  # antipodal pairs closer than this are one surface patch, not two contacts [m]
_COM_SCALE = 0.03  # score decays with the grasp axis' distance to the COM on this scale [m]
_MAX_AXIS_SLOPE = 0.5  # |sin| of the closing axis' elevation: fingers that open along a steep axis
# swing a tip into the ground or over the object at the start opening
_SIDE_CLEARANCE = 0.003  # side grasps: fingers' lower edge above the ground [m]
_MAX_TILT = np.deg2rad(25.0)  # random tilt of the approach about the closing axis
_TOP_MIN_COS = 0.35  # a top approach needs the closing axis this far from vertical (|u_z| < 0.94)


@dataclass(frozen=True, kw_only=True)
class SamplerOptions:
    """Antipodal sampler settings."""

    surface_samples: int = 512
    """Object surface points; pairs among them are the contact candidates."""
    top_fraction: float = 0.5
    """Share of candidates approached from above (the rest from the side)."""
    augment: int = 2
    """Noisy copies per candidate (σ ``NOISE_TRANSLATION``, ``NOISE_ROTATION``), besides the original."""
    candidates_per_pose: int = 3
    """Candidates refined per requested pose (rejections eat some)."""

    def __post_init__(self) -> None:
        if not (0.0 <= self.top_fraction <= 1.0):
            raise PoseError(f"top_fraction must be in [0, 1], got {self.top_fraction}")
        if self.surface_samples < 8 or self.augment < 0 or self.candidates_per_pose < 1:
            raise PoseError("surface_samples >= 8, augment >= 0 and candidates_per_pose >= 1 required")


def antipodal_pairs(points: np.ndarray, normals: np.ndarray, friction: float = FRICTION):
    """Index pairs (i, j) whose contacts pass the friction-cone test, and their alignment.

    Contact i pushes along u = (p_j − p_i)/|p_j − p_i|; both −n_i·u and n_j·u must exceed
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


def sample_poses(
    obj: GraspObject,
    n: int,
    *,
    seed: int = 0,
    options: SamplerOptions | None = None,
    design: FingerDesign | None = None,
    points: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> Candidates:
    """Up to ``n`` refined antipodal grasps of ``obj``, best first; deterministic per ``seed``.

    ``points``/``normals`` (object COM frame [m], outward unit normals) replace the mesh's surface
    samples, e.g. a partial point cloud from a camera; the refinement still uses the mesh.
    """
    import trimesh

    if n < 1:
        raise PoseError(f"n must be >= 1, got {n}")
    options = options or SamplerOptions()
    design = design or FingerDesign()
    rng = np.random.default_rng(seed)
    if points is None:
        pts, face = trimesh.sample.sample_surface(obj.mesh, options.surface_samples, seed=seed)
        nrm = np.asarray(obj.mesh.face_normals)[face]
    else:
        pts, nrm = _check_cloud(points, normals)
    i, j, width, align = antipodal_pairs(pts, nrm)
    rejected = {"friction cone": len(pts) * (len(pts) - 1) // 2 - len(i)}
    wide = 0.5 * width + OPEN_CLEARANCE > MAX_OPENING
    steep = ~wide & (np.abs(pts[j, 2] - pts[i, 2]) > _MAX_AXIS_SLOPE * width)
    rejected["wider than the opening"] = int(np.sum(wide))
    rejected["closing axis too steep"] = int(np.sum(steep))
    ok = ~(wide | steep)
    i, j, width, align = i[ok], j[ok], width[ok], align[ok]
    if len(i) == 0:
        raise PoseError(f"object {obj.name}: no antipodal pair fits the opening ({rejected})")
    centre = 0.5 * (pts[i] + pts[j])
    u = (pts[j] - pts[i]) / width[:, None]
    r_com = np.linalg.norm(np.cross(centre, u), axis=1)  # COM (origin) to the grasp line
    prior = align * np.exp(-r_com / _COM_SCALE)
    k = min(len(i), n * options.candidates_per_pose)
    pick = rng.choice(len(i), size=k, replace=False, p=prior / prior.sum())
    T, scores = _approach(obj, centre[pick], u[pick], design, options.top_fraction, rng), prior[pick]
    T = augment_poses(T, options.augment, rng)
    scores = np.repeat(scores, options.augment + 1)
    cands = refine_and_rank(obj, T, scores, design, rejected)
    return cands.head(n)


def _approach(obj, centre, u, design, top_fraction, rng) -> np.ndarray:
    """Palm poses (P, 4, 4) with the contacts ``_TIP_INSET`` from the fingertips."""
    P = len(centre)
    z = np.array([0.0, 0.0, 1.0])
    world_centre = centre + scene_offset(obj)
    # A side approach lays the 20-mm-wide fingers flat: the contact must clear the ground by half that.
    low = world_centre[:, 2] < 0.5 * design.width + _SIDE_CLEARANCE
    top = ((rng.random(P) < top_fraction) | low) & (np.abs(u[:, 2]) < np.sqrt(1 - _TOP_MIN_COS**2))
    a_top = -z + u[:, 2:3] * u
    side = np.cross(z, u)
    side_ok = np.linalg.norm(side, axis=1) > 1e-6
    side[~side_ok] = [1.0, 0.0, 0.0]
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    # Approach from outside: towards the object's vertical axis, a random sign when on it.
    sign = -np.sign(np.einsum("pk,pk->p", side, centre))
    sign[sign == 0] = 1.0
    a = np.where(top[:, None], a_top, sign[:, None] * side)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    a = np.einsum("pij,pj->pi", rotvec(u * rng.uniform(-_MAX_TILT, _MAX_TILT, size=(P, 1))), a)
    T = np.tile(np.eye(4), (P, 1, 1))
    T[:, :3, :3] = palm_frame(a, u)
    # Low contacts slide towards the fingertip so that the tip starts above the ground.
    reach = (world_centre[:, 2] - _SIDE_CLEARANCE) / np.maximum(-a[:, 2], 1e-6)
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
