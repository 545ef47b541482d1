"""Grasp candidates: an antipodal sampler, AnyGrasp/GraspNet import, and the rigid-counterpart refinement.

Frames. Every pose is a palm pose in the grasp scene's world (:func:`mjcodesign.scenario.build_scene`):
the object's COM at world x = y = 0, its lowest point ``REST_GAP`` above the ground (z = 0), the
object mesh keeping its source orientation. The palm frame is :class:`mjcodesign.mjcf.GripperPose`'s:
``-z`` is the approach, ``y`` the closing axis (finger A at ``+y``), fingers hang to ``z = -L``.

Refinement (the paper's L_init). The soft fingers' rigid counterpart is the same finger blocks, rigid,
on the palm, with the two openings ``s1, s2`` on prismatic joints. Over the approach offset ``t`` (along
the palm's z axis) and ``s1, s2`` it minimises, with d the signed distance [m] of finger and palm
surface points to the object and to the ground, in units of ``_D0`` = 1 mm::

    L = W_D · Σ_fingers max(min_finger d, 0)² + W_P · Σ_points (max(−d_object, 0)² + max(−d_ground, 0)²)

the squared form of the paper (0.1 d² outside, 1e3 d² penetrating). The attraction acts on each
finger's nearest point, so it closes each finger until it touches (a sum over every point would pull
the whole 136-mm finger onto small objects). A pose whose loss stays above
``LOSS_THRESHOLD`` after refinement is dropped with the reason, as is one that still penetrates more
than ``MAX_PENETRATION`` on the dense point set.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.errors import MeshError, PoseError
from mjcodesign.models.types import MAX_OPENING, PALM_HALF
from mjcodesign.objects.mesh import GraspObject
from mjcodesign.scenarios.grasp import REST_GAP, object_vertices, start_openings

__all__ = [
    "ANYGRASP_DEPTH",
    "FRICTION",
    "LOSS_THRESHOLD",
    "MAX_PENETRATION",
    "NOISE_ROTATION",
    "NOISE_TRANSLATION",
    "W_D",
    "W_P",
    "Candidates",
    "Refined",
    "RigidGripper",
    "SamplerOptions",
    "antipodal_pairs",
    "anygrasp_to_world",
    "approach_spread_deg",
    "import_anygrasp",
    "load_external",
    "read_candidates",
    "refine",
    "sample_poses",
    "to_gripper_pose",
]

FRICTION = 0.5
"""Friction coefficient of the antipodal cone test: half the contact's μ = 1 (paper) as a margin."""
W_D = 0.1
"""Weight of the attraction term per mm² (paper: 0.1 d² outside)."""
W_P = 1e3
"""Weight of the penetration term per mm² (paper: 1e3 d² when penetrating)."""
LOSS_THRESHOLD = 1.0
"""A refined pose with a larger loss is dropped (paper: a pose fails when the loss is above 1). With
``W_D`` = 0.1 a finger left more than 3.2 mm from the object fails it."""
MAX_PENETRATION = 1e-3
"""Accepted poses penetrate the object or the ground by at most this much [m] (dense point set)."""
ANYGRASP_DEPTH = 0.05
"""Imported grasp centres sit this far from the fingertips [m]. Measured on the semi-rigid gripper in
MuJoCo (top 4 refined AnyGrasp poses, impulse 0): 013_apple 0/4, 3/4, 3/4 and 014_lemon 0/4, 2/4, 4/4
successes at 20, 35 and 50 mm; nearer the tip the fingers squeeze above round objects' equators."""
NOISE_TRANSLATION = 3e-3
"""Augmentation noise σ on the palm position [m] (paper, NOTES.md)."""
NOISE_ROTATION = 5e-3
"""Augmentation noise σ on each component of the rotation vector [rad] (paper, NOTES.md)."""

_D0 = 1e-3  # the loss measures distances in mm
_TIP_INSET = 0.05  # contacts sit this far from the fingertip along the finger [m] (ANYGRASP_DEPTH)
_MIN_TIP_INSET = 0.004  # ... or this close to the tip for contacts near the ground [m]
_OPEN_CLEARANCE = 0.004  # refinement starts each inner face this far outside the object [m]
_MIN_WIDTH = 0.004  # antipodal pairs closer than this are one surface patch, not two contacts [m]
_COM_SCALE = 0.03  # score decays with the grasp axis' distance to the COM on this scale [m]
_MAX_AXIS_SLOPE = 0.5  # |sin| of the closing axis' elevation: fingers that open along a steep axis
# swing a tip into the ground or over the object at the start opening
_SIDE_CLEARANCE = 0.003  # side grasps: fingers' lower edge above the ground [m]
_MAX_TILT = np.deg2rad(25.0)  # random tilt of the approach about the closing axis
_TOP_MIN_COS = 0.35  # a top approach needs the closing axis this far from vertical (|u_z| < 0.94)
_COARSE_EDGE = 0.008  # refinement point spacing on the finger surfaces [m]
_DENSE_EDGE = 0.002  # check point spacing [m]: features thinner than this can hide between points
_MAX_OBJECT_SAMPLES = 4000  # caps the object points of the opening initialisation
_ITERATIONS = 100
_STEP0, _STEP_MIN, _STEP_MAX = 1e-3, 1e-6, 5e-3  # Rprop steps [m]
_STEP_TOL = 1e-5  # refinement stops when every moving variable's step is below this [m]
_T_RANGE = 0.04  # the approach offset stays within ±this of the candidate's [m]
_CAMERA_HEIGHT = 0.5  # authors' camera: 0.5 m above the ground, looking down (init_pose.py T_cb)
_R_CAMERA = np.diag([-1.0, 1.0, -1.0])  # authors' camera axes in the object (z-up) frame
# AnyGrasp/GraspNet gripper frame (x approach, y closing, z height) -> palm (x, y, z = -approach).
_R_ANYGRASP_PALM = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


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


def _surface_points(mesh, edge: float) -> np.ndarray:
    """Corners plus about one seeded surface sample per ``edge``² of a convex hull [m] (deterministic)."""
    import trimesh

    count = int(np.ceil(mesh.area / edge**2))
    samples, _ = trimesh.sample.sample_surface(mesh, count, seed=0)
    return np.vstack([mesh.vertices, samples])


def _block_points(design: FingerDesign, edge: float) -> tuple[np.ndarray, np.ndarray]:
    """Surface points of every block (finger frame) and whether each lies on a segment's inner face."""
    import trimesh

    pts, inner = [], []
    for blk in design.blocks():
        v = _surface_points(trimesh.convex.convex_hull(blk.vertices()), edge)
        on_top = v[:, 2] >= blk.height(v[:, 0]) - 1e-6
        pts.append(v)
        inner.append(on_top & (blk.kind is BlockKind.SEGMENT))
    return np.vstack(pts), np.concatenate(inner)


def _palm_points(edge: float) -> np.ndarray:
    import trimesh

    return _surface_points(trimesh.creation.box(extents=2 * PALM_HALF), edge) + [0.0, 0.0, PALM_HALF[2]]


@dataclass
class RigidGripper:
    """Surface points of the rigid counterpart in the palm frame at zero opening [m].

    Finger point (x_f, y_f, z_f) of side σ (A: +1, B: −1) sits at palm (σ y_f, σ (s + h_base − z_f), −x_f)
    for opening s (:func:`mjcodesign.mjcf.finger_frame_quat`), so an opening shifts it by σ s along y.
    """

    points: np.ndarray
    """All points at zero opening, shape (n, 3)."""
    side: np.ndarray
    """+1 finger A, −1 finger B, 0 palm, shape (n,)."""
    inner: np.ndarray
    """True on a segment's inner (grasping) face, shape (n,)."""

    @classmethod
    def build(cls, design: FingerDesign, edge: float) -> RigidGripper:
        """Points spaced about ``edge`` [m]."""
        q, inner = _block_points(design, edge)
        parts, sides = [], []
        for s in (1.0, -1.0):
            parts.append(np.c_[s * q[:, 1], s * (design.height_base - q[:, 2]), -q[:, 0]])
            sides.append(np.full(len(q), s))
        palm = _palm_points(edge)
        return cls(
            np.vstack(parts + [palm]),
            np.concatenate(sides + [np.zeros(len(palm))]),
            np.concatenate([inner, inner, np.zeros(len(palm), bool)]),
        )

    def world(self, R: np.ndarray, p: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Points for palm rotations (P, 3, 3), positions (P, 3), openings (P, 2): shape (P, n, 3)."""
        shift = np.where(self.side > 0, s[:, :1], 0.0) + np.where(self.side < 0, s[:, 1:], 0.0)  # (P, n)
        local = self.points[None] + (self.side * shift)[..., None] * np.array([0.0, 1.0, 0.0])
        return np.matmul(local, R.transpose(0, 2, 1)) + p[:, None, :]


def _scene_offset(obj: GraspObject) -> np.ndarray:
    """World position of the object's COM frame origin [m], as :func:`build_scene` places it."""
    return np.array([0.0, 0.0, REST_GAP - float(object_vertices(obj)[:, 2].min())])


def _distances(sdf, gripper: RigidGripper, offset, R, p, s) -> tuple[np.ndarray, ...]:
    """Object and ground signed distances (P, n) and the object's outward unit gradient (P, n, 3)."""
    x = gripper.world(R, p, s)
    d_obj, n_obj = sdf.query((x - offset).reshape(-1, 3))
    P, n = x.shape[:2]
    return d_obj.reshape(P, n), n_obj.reshape(P, n, 3), x[..., 2]


def _loss_grad(gripper, d_obj, n_obj, d_gnd, R):
    """Loss (P,) and its gradient (P, 3) over (t, s1, s2)."""
    a = R[:, :, 2]  # palm z: d(point)/dt
    y = R[:, :, 1]
    # d(point)/d(s1) = +y on finger A, d/d(s2) = -y on finger B; the palm moves with t only.
    dn_dt = np.matmul(n_obj, a[:, :, None])[..., 0]
    dn_dy = np.matmul(n_obj, y[:, :, None])[..., 0]
    pen_o = np.maximum(-d_obj, 0.0) / _D0
    pen_g = np.maximum(-d_gnd, 0.0) / _D0
    loss = W_P * (np.sum(pen_o**2, axis=1) + np.sum(pen_g**2, axis=1))
    # d(pen²)/dd = −2 pen / D0; ground gradient is +z.
    g_o = -2.0 * W_P * pen_o / _D0
    g_g = -2.0 * W_P * pen_g / _D0
    grad = np.zeros((len(R), 3))
    grad[:, 0] = np.sum(g_o * dn_dt + g_g * a[:, 2:3], axis=1)
    for k, sd in ((1, 1.0), (2, -1.0)):
        m = gripper.side == sd
        grad[:, k] = sd * np.sum(g_o[:, m] * dn_dy[:, m] + g_g[:, m] * y[:, 2:3], axis=1)
        sel = np.flatnonzero(m)
        j = sel[np.argmin(d_obj[:, sel], axis=1)]
        rows = np.arange(len(R))
        gap = np.maximum(d_obj[rows, j], 0.0) / _D0
        loss = loss + W_D * gap**2
        g = 2.0 * W_D * gap / _D0
        grad[:, 0] += g * dn_dt[rows, j]
        grad[:, k] += sd * g * dn_dy[rows, j]
    return loss, grad


@dataclass
class Refined:
    """Output of :func:`refine`, per pose."""

    matrices: np.ndarray
    """Refined palm poses (P, 4, 4)."""
    openings: np.ndarray
    """(s1, s2) [m], shape (P, 2)."""
    loss: np.ndarray
    """Loss at the end (coarse points), shape (P,)."""
    min_object: np.ndarray
    """Smallest signed distance to the object on the dense points [m], shape (P,)."""
    min_ground: np.ndarray
    """Smallest height above the ground on the dense points [m], shape (P,)."""
    gap: np.ndarray
    """Each finger's nearest distance to the object [m], shape (P, 2)."""

    @property
    def min_signed_distance(self) -> np.ndarray:
        """Smallest signed distance to the object or the ground [m], shape (P,)."""
        return np.minimum(self.min_object, self.min_ground)


def refine(
    obj: GraspObject,
    matrices: np.ndarray,
    openings: np.ndarray,
    *,
    design: FingerDesign | None = None,
    sdf=None,
    iterations: int = _ITERATIONS,
) -> Refined:
    """Refine palm poses (P, 4, 4) and openings (P, 2) [m] by iRprop− on (t, s1, s2) (module docstring)."""
    from mjcodesign.poses.sdf import MeshSDF

    design = design or FingerDesign()
    sdf = sdf or MeshSDF.from_trimesh(obj.mesh)
    coarse = RigidGripper.build(design, _COARSE_EDGE)
    T = np.array(matrices, dtype=float)
    R, p0 = T[:, :3, :3], T[:, :3, 3]
    offset = _scene_offset(obj)
    x = np.c_[np.zeros(len(T)), np.asarray(openings, dtype=float)]
    # iRprop−: a per-variable step that grows while the gradient keeps its sign and halves when it
    # flips. It ignores the gradient's magnitude, which spans 1e5 between attraction and penetration.
    step = np.full_like(x, _STEP0)
    g_prev = np.zeros_like(x)
    for _ in range(iterations):
        p = p0 + x[:, :1] * R[:, :, 2]
        d_obj, n_obj, d_gnd = _distances(sdf, coarse, offset, R, p, x[:, 1:])
        _, grad = _loss_grad(coarse, d_obj, n_obj, d_gnd, R)
        same = np.sign(grad) * np.sign(g_prev)
        step = np.where(same > 0, np.minimum(step * 1.2, _STEP_MAX), step)
        step = np.where(same < 0, np.maximum(step * 0.5, _STEP_MIN), step)
        grad = np.where(same < 0, 0.0, grad)
        x = x - np.sign(grad) * step
        g_prev = grad
        if not np.any((grad != 0) & (step > _STEP_TOL)):
            break  # every variable has settled (or feels no force)
        x[:, 0] = np.clip(x[:, 0], -_T_RANGE, _T_RANGE)
        x[:, 1:] = np.clip(x[:, 1:], 0.0, MAX_OPENING)
    p = p0 + x[:, :1] * R[:, :, 2]
    d_obj, n_obj, d_gnd = _distances(sdf, coarse, offset, R, p, x[:, 1:])
    loss, _ = _loss_grad(coarse, d_obj, n_obj, d_gnd, R)
    gap = np.stack([d_obj[:, coarse.side == sd].min(axis=1) for sd in (1.0, -1.0)], axis=1)
    dense = RigidGripper.build(design, _DENSE_EDGE)
    d_obj, _, d_gnd = _distances(sdf, dense, offset, R, p, x[:, 1:])
    out = T.copy()
    out[:, :3, 3] = p
    return Refined(out, x[:, 1:].copy(), loss, d_obj.min(axis=1), d_gnd.min(axis=1), gap)


# -- candidates --------------------------------------------------------------------------------------


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


def _frame(approach: np.ndarray, closing: np.ndarray) -> np.ndarray:
    """Palm rotations (P, 3, 3): z = −approach, y = closing (made orthogonal), x = y × z."""
    z = -approach / np.linalg.norm(approach, axis=1, keepdims=True)
    y = closing - np.einsum("pk,pk->p", closing, z)[:, None] * z
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    return np.stack([np.cross(y, z), y, z], axis=2)


def _rotvec(v: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (P, 3) (Rodrigues)."""
    th = np.linalg.norm(v, axis=1)
    k = v / np.maximum(th, 1e-15)[:, None]
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K = K - K.transpose(0, 2, 1)
    s, c = np.sin(th)[:, None, None], np.cos(th)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * K @ K


def _augment(T: np.ndarray, copies: int, rng: np.random.Generator) -> np.ndarray:
    """Each pose followed by ``copies`` noisy copies, shape (P (1 + copies), 4, 4)."""
    if copies == 0:
        return T
    rep = np.repeat(T[:, None], copies, axis=1).reshape(-1, 4, 4)
    noise_r = _rotvec(rng.normal(0.0, NOISE_ROTATION, size=(len(rep), 3)))
    rep[:, :3, :3] = noise_r @ rep[:, :3, :3]
    rep[:, :3, 3] += rng.normal(0.0, NOISE_TRANSLATION, size=(len(rep), 3))
    return np.concatenate([T[:, None], rep.reshape(len(T), copies, 4, 4)], axis=1).reshape(-1, 4, 4)


def _object_points(obj: GraspObject) -> np.ndarray:
    """Seeded surface samples, one per ``_DENSE_EDGE``² up to a cap (COM frame) [m]."""
    import trimesh

    count = int(min(_MAX_OBJECT_SAMPLES, np.ceil(obj.mesh.area / _DENSE_EDGE**2)))
    samples, _ = trimesh.sample.sample_surface(obj.mesh, count, seed=0)
    return samples


def _slab_openings(obj: GraspObject, T: np.ndarray, design: FingerDesign) -> np.ndarray:
    """Per pose, each finger's opening that clears the object's vertices in its sweep slab (P, 2) [m].

    The slab is the finger's width (palm |x| ≤ w/2) and length (−L ≤ palm z ≤ 0); the finger closes
    from there during refinement. NaN where no vertex lies on that side (nothing to clear).
    """
    v = _object_points(obj) + _scene_offset(obj)
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
    fits = ~np.any(ext + _OPEN_CLEARANCE > MAX_OPENING, axis=1)
    s = np.clip(np.nan_to_num(ext, nan=0.0) + _OPEN_CLEARANCE, 0.0, MAX_OPENING)
    return s, fits


def _below_ground(T, s, design) -> np.ndarray:
    """Poses whose gripper stays below the ground wherever the approach offset t moves it (P,)."""
    g = RigidGripper.build(design, _COARSE_EDGE)
    z = g.world(T[:, :3, :3], T[:, :3, 3], s)[..., 2].min(axis=1)
    return z + _T_RANGE * np.abs(T[:, 2, 2]) < -MAX_PENETRATION


def _start_below_ground(obj, T, s, design) -> np.ndarray:
    """Poses that the grasp motion cannot open: too wide, or a finger under the ground (P,).

    The scene starts each finger outside the object (:func:`mjcodesign.scenario.start_openings`).
    """
    from mjcodesign.models.types import GripperPose

    starts = np.zeros_like(s)
    bad = np.zeros(len(T), bool)
    for k in range(len(T)):
        try:
            starts[k] = start_openings(obj, GripperPose.from_matrix(T[k], tuple(s[k])))
        except PoseError:
            bad[k] = True
    g = RigidGripper.build(design, _COARSE_EDGE)
    z = g.world(T[:, :3, :3], T[:, :3, 3], starts)[..., 2].min(axis=1)
    return bad | (z < -MAX_PENETRATION)


def _count(rejected: dict[str, int], reason: str, mask: np.ndarray) -> None:
    if np.any(mask):
        rejected[reason] = rejected.get(reason, 0) + int(np.sum(mask))


def _finish(obj, T, scores, design, rejected, sdf) -> Candidates:
    """Refine, drop (with the reason) and rank candidate poses with prior scores."""
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
    r = refine(obj, T, s0, design=design, sdf=sdf)
    ground = r.min_ground < -MAX_PENETRATION
    collide = ~ground & (r.min_object < -MAX_PENETRATION)
    high = ~(ground | collide) & (r.loss > LOSS_THRESHOLD)
    reach = high & (r.gap.max(axis=1) > _D0 * np.sqrt(LOSS_THRESHOLD / W_D))
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
    wide = 0.5 * width + _OPEN_CLEARANCE > MAX_OPENING
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
    T = _augment(T, options.augment, rng)
    scores = np.repeat(scores, options.augment + 1)
    cands = _finish(obj, T, scores, design, rejected, None)
    return cands.head(n)


def _approach(obj, centre, u, design, top_fraction, rng) -> np.ndarray:
    """Palm poses (P, 4, 4) with the contacts ``_TIP_INSET`` from the fingertips."""
    P = len(centre)
    z = np.array([0.0, 0.0, 1.0])
    world_centre = centre + _scene_offset(obj)
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
    a = np.einsum("pij,pj->pi", _rotvec(u * rng.uniform(-_MAX_TILT, _MAX_TILT, size=(P, 1))), a)
    T = np.tile(np.eye(4), (P, 1, 1))
    T[:, :3, :3] = _frame(a, u)
    # Low contacts slide towards the fingertip so that the tip starts above the ground.
    reach = (world_centre[:, 2] - _SIDE_CLEARANCE) / np.maximum(-a[:, 2], 1e-6)
    inset = np.clip(reach, _MIN_TIP_INSET, _TIP_INSET)
    T[:, :3, 3] = world_centre - a * (design.length - inset)[:, None]
    return T


def _check_cloud(points, normals) -> tuple[np.ndarray, np.ndarray]:
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


# -- external candidates -----------------------------------------------------------------------------


def anygrasp_to_world(
    T_pose: np.ndarray, obj: GraspObject, source_vertices: np.ndarray, *, depth: float | None = None
) -> np.ndarray:
    """The authors' AnyGrasp poses (N, 4, 4) as palm poses in our scene's world (N, 4, 4).

    The authors' ``T_pose`` is the AnyGrasp gripper frame (x approach, y closing, GraspNet) in a camera
    frame 0.5 m above the ground looking down, the camera axes being (−x, y, −z) of the YCB mesh with
    the mesh's vertex mean below it (``init_pose.py``: T_cb, and ``object_loader.py``: the mesh is
    shifted by its vertex mean and lifted onto the ground). So a camera point c lies at
    ``diag(−1, 1, −1) c + (0, 0, 0.5 + min z)`` relative to the vertex mean; our scene puts the COM at
    x = y = 0. The grasp centre lies ``depth`` (default ``ANYGRASP_DEPTH``) from the fingertips along
    the finger; ``source_vertices`` are the source mesh's vertices (its frame, before centring).
    """
    depth = ANYGRASP_DEPTH if depth is None else float(depth)
    if not (0.0 <= depth <= FingerDesign().length):
        raise PoseError(f"depth must be in [0, {FingerDesign().length}] m, got {depth}")
    T_pose = np.asarray(T_pose, dtype=float)
    src = np.asarray(source_vertices, dtype=float)
    mean = src.mean(axis=0)
    lift = np.array([0.0, 0.0, _CAMERA_HEIGHT + float(src[:, 2].min() - mean[2])])
    centre = np.einsum("ij,nj->ni", _R_CAMERA, T_pose[:, :3, 3]) + lift + (mean - obj.com_offset)
    centre = centre + _scene_offset(obj)
    R = _R_CAMERA @ T_pose[:, :3, :3] @ _R_ANYGRASP_PALM
    out = np.tile(np.eye(4), (len(T_pose), 1, 1))
    out[:, :3, :3] = R
    out[:, :3, 3] = centre + R[:, :, 2] * (FingerDesign().length - depth)
    return out


def load_external(path: str | Path) -> np.ndarray:
    """Grasp matrices (N, 4, 4) from an AnyGrasp/GraspNet file, in its camera frame.

    Reads ``.npz`` (key ``T_pose``, N×4×4), ``.npy`` (4×4, N×4×4 or N×17) or text (N×17 rows or 16
    floats a row). GraspNet's 17 floats are score, width, height, depth, rotation (9, row-major),
    translation (3), object id.
    """
    path = Path(path)
    if not path.is_file():
        raise PoseError(f"grasp file not found: {path}")
    try:
        if path.suffix == ".npz":
            with np.load(path) as z:
                if "T_pose" not in z.files:
                    raise PoseError(f"{path}: no T_pose array (keys: {', '.join(z.files)})")
                a = np.asarray(z["T_pose"], dtype=float)
        elif path.suffix == ".npy":
            a = np.asarray(np.load(path), dtype=float)
        else:
            a = np.atleast_2d(np.loadtxt(path, dtype=float, delimiter="," if path.suffix == ".csv" else None))
    except (OSError, ValueError) as exc:
        raise PoseError(f"{path}: not a grasp file ({type(exc).__name__}: {exc})") from exc
    if a.shape == (4, 4):
        a = a[None]
    if a.ndim == 2 and a.shape[1] == 17:
        T = np.tile(np.eye(4), (len(a), 1, 1))
        T[:, :3, :3] = a[:, 4:13].reshape(-1, 3, 3)
        T[:, :3, 3] = a[:, 13:16]
        a = T
    elif a.ndim == 2 and a.shape[1] == 16:
        a = a.reshape(-1, 4, 4)
    if a.ndim != 3 or a.shape[1:] != (4, 4) or len(a) == 0:
        raise PoseError(f"{path}: expected N×4×4 matrices or N×17 GraspNet rows, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise PoseError(f"{path}: grasp file contains NaN or inf")
    R = a[:, :3, :3]
    if np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max() > 1e-3:
        raise PoseError(f"{path}: rotation blocks are not orthonormal")
    return a


def import_anygrasp(
    obj: GraspObject,
    T_pose: np.ndarray,
    source_vertices: np.ndarray,
    *,
    seed: int = 0,
    augment: int = 0,
    depth: float | None = None,
) -> Candidates:
    """AnyGrasp poses mapped (:func:`anygrasp_to_world`), optionally augmented, refined and ranked."""
    if len(source_vertices) == 0:
        raise MeshError("source mesh has no vertices")
    T = anygrasp_to_world(T_pose, obj, source_vertices, depth=depth)
    T = _augment(T, augment, np.random.default_rng(seed))
    return _finish(obj, T, np.ones(len(T)), FingerDesign(), {}, None)


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


def to_gripper_pose(c: Candidates, index: int = 0):
    """Row ``index`` as a :class:`mjcodesign.mjcf.GripperPose`; :class:`PoseError` if there is none."""
    from mjcodesign.models.types import GripperPose

    if not (0 <= index < len(c)):
        raise PoseError(f"no grasp candidate {index} (of {len(c)}); rejected: {c.rejected}")

    return GripperPose.from_matrix(c.matrices[index], tuple(float(v) for v in c.openings[index]))
