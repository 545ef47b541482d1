"""The part of an object that the fingers sweep while they close, and the start openings it allows.

Palm frame (:class:`mjcodesign.models.types.GripperPose`): ``y`` is the closing axis (finger A on
``+y``), the fingers hang from the palm (``z = 0``) to their tips (``z = -reach``) and are ``width``
wide across ``x``. A finger at opening ``s`` fills ``s .. s + thickness`` along ``±y`` (its inner face
is at least ``s`` from the palm centre; the taper only moves it further out). Closing, it sweeps the
*slab* ``|x| <= width/2``, ``-reach <= z <= 0``: only the object there can stand in its way.

Per finger, the object in the slab splits along the closing axis, from the palm centre outwards:

- *grasped*: the part around the palm centre, and every part beyond it separated by a gap too narrow
  for the finger (thickness plus twice ``min_clearance``); the finger has to start outside all of it;
- *outside*: what lies beyond the first gap the finger fits in (a bowl's far wall, a mug's body behind
  its handle); the finger has to start short of it.

The slab's y-range of each triangle is exact: the largest and smallest y over the triangle's part
inside the slab lie at a vertex of that polygon, which is a triangle vertex, a triangle edge crossing
a slab face, or a slab edge (a line along y) crossing the triangle.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import MeshError
from mjcodesign.models.types import MAX_OPENING

__all__ = ["START_CLEARANCE", "FingerSweep", "SweepStatus", "slab_y_ranges", "sweep_failure", "sweep_starts"]

START_CLEARANCE = 0.01
"""A finger starts this far outside the part it grasps when there is room [m] (the grasp scenario's)."""
_MIN_CLEARANCE = 0.002  # ... and at least this far, and this far short of another part [m]

_PROBE_X = 3.1416e-6  # the inside probe runs this far off the slab's centre plane [m]: off mesh edges
_CHUNK = 400_000  # (pose, triangle) pairs per vectorised block: about 0.1 GB of temporaries


class SweepStatus(enum.IntEnum):
    """Outcome of :func:`sweep_starts` per finger."""

    OK = 0
    TOO_WIDE = 1
    """The object inside the slab reaches past the stroke: the finger cannot open around it."""
    NO_ROOM = 2
    """The pose's opening puts the finger into the gap's far side: into another part of the object."""


@dataclass(frozen=True, kw_only=True)
class FingerSweep:
    """The fingers' slab and the start rule [m]."""

    half_width: float
    """Half the finger width (palm x)."""
    reach: float
    """Palm to fingertip (palm −z)."""
    thickness: float
    """Finger thickness along the closing axis at its base."""
    clearance: float
    """A start opening lies this far outside the grasped part when there is room."""
    min_clearance: float
    """... and at least this far; and this far short of an outside part."""
    max_opening: float
    """The stroke: the largest opening of one finger."""

    @property
    def need(self) -> float:
        """The narrowest gap a finger fits in along the closing axis [m]."""
        return self.thickness + 2.0 * self.min_clearance

    @classmethod
    def of(cls, design: FingerDesign, *, clearance: float = START_CLEARANCE) -> FingerSweep:
        """The sweep of ``design``'s fingers on the gripper's stroke (``MAX_OPENING``)."""
        return cls(
            half_width=0.5 * design.width,
            reach=design.length,
            thickness=design.height_base,
            clearance=clearance,
            min_clearance=min(_MIN_CLEARANCE, clearance),
            max_opening=MAX_OPENING,
        )

    def __post_init__(self) -> None:
        vals = (self.half_width, self.reach, self.thickness, self.clearance, self.max_opening)
        if not all(np.isfinite(v) and v > 0 for v in vals):
            raise MeshError("finger sweep: width, reach, thickness, clearance and stroke must be > 0")
        if not (0 <= self.min_clearance <= self.clearance):
            raise MeshError("finger sweep: need 0 <= min_clearance <= clearance")


def _segment_hits(a, b, axis: int, value: float):
    """Points where segments a→b (..., 3) cross the plane ``x[axis] = value``, and whether they do."""
    da, db = a[..., axis] - value, b[..., axis] - value
    denom = np.where(da == db, 1.0, da - db)
    t = da / denom
    hit = (da != db) & (t >= 0.0) & (t <= 1.0)
    return a + t[..., None] * (b - a), hit


def _line_hits(tri, x: float, z: float):
    """Where the line (x, ·, z) along y crosses each triangle (..., 3, 3): y, and whether it does."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    # Barycentric coordinates of (x, z) in the triangle's projection onto the xz-plane.
    e1x, e1z = b[..., 0] - a[..., 0], b[..., 2] - a[..., 2]
    e2x, e2z = c[..., 0] - a[..., 0], c[..., 2] - a[..., 2]
    det = e1x * e2z - e2x * e1z
    ok = np.abs(det) > 1e-18
    det = np.where(ok, det, 1.0)
    px, pz = x - a[..., 0], z - a[..., 2]
    u = (px * e2z - e2x * pz) / det
    v = (e1x * pz - px * e1z) / det
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
    y = a[..., 1] + u * (b[..., 1] - a[..., 1]) + v * (c[..., 1] - a[..., 1])
    return y, hit


def slab_y_ranges(tri: np.ndarray, half_width: float, z_lo: float, z_hi: float):
    """Smallest and largest y of each triangle's part inside ``|x| <= half_width, z_lo <= z <= z_hi``.

    ``tri``: triangles (..., 3, 3) [m]. Returns (ymin, ymax), NaN where a triangle misses the slab.
    """
    tri = np.asarray(tri, dtype=float)
    eps = 1e-12

    def inside(p, skip_axis=None):
        ok = np.ones(p.shape[:-1], bool)
        if skip_axis != 0:
            ok &= np.abs(p[..., 0]) <= half_width + eps
        if skip_axis != 2:
            ok &= (p[..., 2] >= z_lo - eps) & (p[..., 2] <= z_hi + eps)
        return ok

    ys, oks = [tri[..., 1]], [inside(tri)]  # vertices (..., 3)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        for axis, value in ((0, -half_width), (0, half_width), (2, z_lo), (2, z_hi)):
            p, hit = _segment_hits(tri[..., i, :], tri[..., j, :], axis, value)
            ys.append(p[..., 1:2])
            oks.append((hit & inside(p, skip_axis=axis))[..., None])
    for x in (-half_width, half_width):
        for z in (z_lo, z_hi):
            y, hit = _line_hits(tri, x, z)
            ys.append(y[..., None])
            oks.append(hit[..., None])
    y = np.concatenate(ys, axis=-1)
    ok = np.concatenate(oks, axis=-1)
    ymin = np.where(ok, y, np.inf).min(axis=-1)
    ymax = np.where(ok, y, -np.inf).max(axis=-1)
    miss = ~ok.any(axis=-1)
    return np.where(miss, np.nan, ymin), np.where(miss, np.nan, ymax)


def _side_extents(pose, lo, hi, P: int, need: float) -> tuple[np.ndarray, np.ndarray]:
    """One finger's farthest grasped part and nearest outside part along its side [m], each (P,).

    ``lo``/``hi`` (N,): y-ranges of the object in the slab, signed so that the finger is on +y, of
    the poses ``pose`` (N,). From the palm centre outwards, a part merges into the grasped one while
    the gap before it is narrower than ``need`` (the finger cannot sit there).
    """
    reach = np.zeros(P)
    while True:
        merged = lo <= reach[pose] + need
        grown = reach.copy()
        np.maximum.at(grown, pose[merged], hi[merged])
        if np.array_equal(grown, reach):
            break
        reach = grown
    far_in = np.full(P, -np.inf)
    inside = merged & (hi > 0.0)
    np.maximum.at(far_in, pose[inside], hi[inside])
    near_out = np.full(P, np.inf)
    np.minimum.at(near_out, pose[~merged], lo[~merged])
    return far_in, near_out


def _slab_ranges(vertices, faces, R, p, sweep: FingerSweep):
    """(pose, ylow, yhigh) of the object in each pose's slab.

    Per triangle that meets the slab, its y-range there; and the inside of the solid along the slab's
    centre line (a solid wider than the slab in x and z has no surface in it between its two faces).
    """
    step = max(1, _CHUNK // max(len(faces), 1))
    poses, lows, highs = [], [], []
    for k in range(0, len(R), step):
        sl = slice(k, min(len(R), k + step))
        local = np.matmul(vertices[None] - p[sl, None], R[sl])  # palm coordinates (Pc, V, 3)
        tri = local[:, faces]  # (Pc, T, 3, 3)
        x, z = tri[..., 0], tri[..., 2]
        lo_x, hi_x, lo_z, hi_z = x.min(-1), x.max(-1), z.min(-1), z.max(-1)
        touch = (hi_x >= -sweep.half_width) & (lo_x <= sweep.half_width)
        touch &= (hi_z >= -sweep.reach) & (lo_z <= 0.0)
        within = (lo_x >= -sweep.half_width) & (hi_x <= sweep.half_width)
        within &= (lo_z >= -sweep.reach) & (hi_z <= 0.0)
        i, t = np.nonzero(touch & within)  # whole triangle in the slab: its vertices' range
        y = tri[i, t, :, 1]
        poses.append(i + k), lows.append(y.min(-1)), highs.append(y.max(-1))
        i, t = np.nonzero(touch & ~within)  # crossing the slab's faces: clip exactly
        ymin, ymax = slab_y_ranges(tri[i, t], sweep.half_width, -sweep.reach, 0.0)
        ok = ~np.isnan(ymax)
        poses.append(i[ok] + k), lows.append(ymin[ok]), highs.append(ymax[ok])
        i, t = np.nonzero(touch)
        seg = _inside_segments(tri[i, t], i + k, _PROBE_X, -0.5 * sweep.reach - _PROBE_X)
        poses.append(seg[0]), lows.append(seg[1]), highs.append(seg[2])
    return np.concatenate(poses), np.concatenate(lows), np.concatenate(highs)


def _inside_segments(tri: np.ndarray, pose: np.ndarray, x: float, z: float):
    """(pose, ylow, yhigh) where the line (x, ·, z) runs inside the solid bounded by ``tri`` (N, 3, 3).

    Between two y where the slab holds no surface, the slab's whole cross-section is inside the solid
    or outside it, so one line decides. Crossing a face whose outward normal has n_y < 0 enters the
    solid (winding +1), n_y > 0 leaves it: a union of closed, outward-wound pieces (the convex hulls)
    is inside where the winding number is positive.
    """
    y, hit = _line_hits(tri, x, z)
    n_y = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 1]
    keep = hit & (n_y != 0.0)
    pose, y, step = pose[keep], y[keep], np.where(n_y[keep] < 0.0, 1, -1)
    if len(pose) == 0:
        return pose, y, y
    order = np.lexsort((y, pose))
    pose, y, step = pose[order], y[order], step[order]
    wind = np.cumsum(step)
    start = np.r_[True, pose[1:] != pose[:-1]]  # the winding restarts with each pose
    wind -= np.repeat(np.r_[wind[start] - step[start]], np.diff(np.r_[np.flatnonzero(start), len(pose)]))
    inside = (wind[:-1] > 0) & (pose[1:] == pose[:-1])
    return pose[:-1][inside], y[:-1][inside], y[1:][inside]


def sweep_starts(
    vertices: np.ndarray,
    faces: np.ndarray,
    rotations: np.ndarray,
    positions: np.ndarray,
    openings: np.ndarray,
    sweep: FingerSweep,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start openings of poses from the object in the fingers' slab (module docstring).

    ``vertices`` (V, 3) [m] and ``faces`` (T, 3): the object's surface in the world; ``rotations``
    (P, 3, 3) and ``positions`` (P, 3): palm poses; ``openings`` (P, 2): each pose's target openings
    (A, B) [m].

    Returns ``starts`` (P, 2) [m]: outside the grasped part by ``clearance`` when there is room,
    else midway in the room, never below the pose's opening; ``status`` (P, 2) :class:`SweepStatus`;
    ``reach`` (P, 2) [m]: the farthest grasped part from the palm centre (−inf where none).
    """
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    R = np.asarray(rotations, dtype=float)
    p = np.asarray(positions, dtype=float)
    s = np.asarray(openings, dtype=float)
    P = len(R)
    pose, ymin, ymax = _slab_ranges(v, f, R, p, sweep)
    far_a, out_a = _side_extents(pose, ymin, ymax, P, sweep.need)
    far_b, out_b = _side_extents(pose, -ymax, -ymin, P, sweep.need)
    far_in, near_out = np.c_[far_a, far_b], np.c_[out_a, out_b]
    lowest = np.maximum(far_in + sweep.min_clearance, s)
    room = near_out - sweep.thickness - sweep.min_clearance  # the largest start short of the outside
    want = np.maximum(far_in + sweep.clearance, s)
    starts = np.where(want > room, 0.5 * (lowest + room), want)  # a tight room: start midway
    starts = np.minimum(starts, sweep.max_opening)
    status = np.full((P, 2), int(SweepStatus.OK))
    too_wide = lowest > sweep.max_opening
    status[too_wide] = SweepStatus.TOO_WIDE
    status[~too_wide & (room < lowest)] = SweepStatus.NO_ROOM
    return starts, status, far_in


def sweep_failure(name: str, status: int, finger: int, reach: float, sweep: FingerSweep) -> str:
    """The one-line reason for a finger's :class:`SweepStatus` (``finger`` 0: A, 1: B; ``reach`` [m])."""
    f = "AB"[finger]
    if status == SweepStatus.TOO_WIDE:
        return (
            f"object {name} is too wide for the stroke: in finger {f}'s sweep it reaches "
            f"{1000 * reach:.0f} mm from the palm centre, the finger opens {1000 * sweep.max_opening:.0f} mm"
        )
    if status == SweepStatus.NO_ROOM:
        return f"finger {f}'s opening puts it into another part of {name} (no room between the parts)"
    return "ok"
