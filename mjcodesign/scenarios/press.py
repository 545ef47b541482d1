"""The ``press`` scenario: one finger, base clamped, curls onto a flat rigid plate under tendon tension.

The plate lies over the finger's inner side, parallel to the line through the segment tops (which taper
from 14 mm at the base to 6 mm at the tip), ``gap`` above it. The tendon closes the finger onto it and
the contact normal force is read along the finger (position ``x`` of the contact in the base frame, which
is the finger's length coordinate while it lies flat on the plate):

* ``distal_third_fraction``: share of the total normal force at ``x > 2L/3``;
* ``centroid_over_length``: force-weighted mean ``x`` divided by ``L``.

The paper's claim (Fig. 2): uniform-pressure routing (tendon moment ∝ (L − x)², the moment of a
uniform pressure) spreads the force along the finger; uniform-height routing (constant moment) loads
the tip. Models: the MuJoCo chain and flex run their dynamics to rest (point-force tendon, gravity off);
the Warp FEM (linear tets; contact at vertices) solves the static equilibrium with frictionless penalty
contact against the plate's signed distance (`mjcodesign.sim.fem.press.press_fem`, which uses
:func:`plate_pose` and :func:`force_distribution` from here).
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import SimulationDiverged
from mjcodesign.models.simulate import check_state

__all__ = [
    "PRESS_METRICS",
    "plate_pose",
    "plate_box",
    "plate_contacts",
    "force_distribution",
    "press_mujoco",
    "settled",
    "PLATE_GAP",
]

PLATE_GAP = 5e-4
"""Gap between the plate and the segment tops at rest [m]."""
_PLATE_HALF = (0.08, 0.02, 0.005)
"""Plate half extents [m]: longer and wider than the finger, 10 mm thick."""
_PLATE_X0 = 0.02
"""Plate starts past the clamped base segment [m] (x in the finger frame)."""
PRESS_METRICS = ("total_force_n", "distal_third_fraction", "centroid_over_length")
"""What a press reports (:func:`force_distribution`): total normal force [N], distal-third share,
centroid over the finger length."""
_MIN_CONTACT_FORCE = 1e-9
"""Total normal force below this [N] means the finger never reached the plate."""


def plate_pose(design: FingerDesign, gap: float = PLATE_GAP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plate centre [m] (3,), rotation (3, 3) and half extents [m] (3,) in the finger frame."""
    slope = (design.height_tip - design.height_base) / design.length
    ang = np.arctan(slope)
    R = np.array([[np.cos(ang), 0.0, -np.sin(ang)], [0.0, 1.0, 0.0], [np.sin(ang), 0.0, np.cos(ang)]])
    half = np.array(_PLATE_HALF)
    x_mid = _PLATE_X0 + half[0] * np.cos(ang)
    z_face = design.height_base + slope * x_mid + gap / np.cos(ang)
    centre = np.array([x_mid, 0.0, z_face]) + R @ np.array([0.0, 0.0, half[2]])
    return centre, R, half


def force_distribution(x: np.ndarray, fn: np.ndarray, length: float) -> dict:
    """Distal-third share and centroid of normal forces ``fn`` [N] acting at ``x`` [m] along the finger."""
    x = np.asarray(x, dtype=float)
    fn = np.clip(np.asarray(fn, dtype=float), 0.0, None)
    total = float(fn.sum())
    if total < _MIN_CONTACT_FORCE:
        raise SimulationDiverged("the finger never touched the plate; raise the tension")
    return {
        "total_force_n": total,
        "distal_third_fraction": float(fn[x > 2.0 * length / 3.0].sum() / total),
        "centroid_over_length": float(np.dot(x, fn) / (total * length)),
    }


_MAX_TIME = 10.0
"""Simulated time [s] allowed to settle (the chain settles within 1 s, the trilinear flex within ~3 s)."""
_WINDOW = 0.1
"""The force distribution is averaged over windows of this length [s]..."""
_SAMPLES_PER_WINDOW = 20
"""...sampled this many times per window (every few steps)."""
_MIN_TIME = 2.0
"""Settling is judged from this time on [s]: the chain's approach to the plate is not monotonic in its
first second (window-mean force 0.0092, 0.0087, 0.0086, 0.0088... N), which a line fit reads as noise."""
_TREND_WINDOWS = 10
"""Settling is judged on a straight-line fit through the last this many window means (1 s)."""
_DRIFT_FORCE_REL = 0.005
"""Settled: over the fit's span the total force drifts by at most this fraction of its mean, and..."""
_DRIFT_SHARE = 0.005
"""...the distal-third share and the centroid (/L) by at most this, beyond twice the fitted slope's
standard error. The chain creeps smoothly (time constant ~0.7 s, no noise), so the slope bound settles
it; the trilinear flex keeps a micrometre jitter on the plate (window means scatter ~1% in force, 0.5%
in share), so a pose or window-to-window criterion never settles it, while the drift test does."""


def press_mujoco(
    design: FingerDesign,
    stiffness: Stiffness,
    model: str,
    tension: float,
    *,
    max_time: float = _MAX_TIME,
    observe=None,
) -> dict:
    """Chain or flex finger pressed onto the plate: dynamics until the contact forces settle.

    Returns the force distribution's window means (:func:`_settle_on_plate`). ``observe(built, data)``,
    if given, is called with the model (plate included) and its data at the end.
    """
    from mjcodesign.models.builder import apply_cell_moduli
    from mjcodesign.models.builder import build_finger as _build
    from mjcodesign.models.spec import compile_spec
    from mjcodesign.models.tendon import TendonDriver
    from mjcodesign.models.types import CONTYPE_FINGER, CONTYPE_WORLD, FingerModel, TendonMode
    from mjcodesign.scenarios.static import rest_options

    model = FingerModel(model)
    opts = rest_options(design, stiffness.finger(0), None)
    built = _build(design, stiffness, model, options=opts, tendon_mode=TendonMode.POINT_FORCE)
    # The flex collides with a skin of its collision radius around its surface: the plate keeps the same
    # gap from that skin as from the chain's and the FEM's surfaces (at the bare surface the skin would
    # touch the plate from the start and load the proximal segments: 28.1 mN, distal share 0.49).
    skin = float(built.model.flex_radius.max()) if model.is_flex else 0.0
    centre, R, half = plate_pose(design, PLATE_GAP + skin)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    built.spec.worldbody.add_geom(
        name="plate",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=half,
        pos=centre,
        quat=q,
        contype=CONTYPE_WORLD,
        conaffinity=CONTYPE_FINGER,
    )
    m = compile_spec(built.spec)
    apply_cell_moduli(m, built.fingers)
    built = replace(built, model=m)
    d = mujoco.MjData(m)
    drv = TendonDriver(built)
    drv.set_tension(d, tension)
    out = _settle_on_plate(m, d, drv.apply, design.length, max_time)
    if observe is not None:
        observe(built, d)
    return out


def _settle_on_plate(m, d, apply, length: float, max_time: float) -> dict:
    """Step until the force distribution on the plate stops drifting (judged from :data:`_MIN_TIME` on).

    Returns its mean over the last :data:`_TREND_WINDOWS` windows, ``n_contacts`` at the end and
    ``settled_s``.
    """
    n_win = max(1, int(round(_WINDOW / m.opt.timestep)))
    every = max(1, n_win // _SAMPLES_PER_WINDOW)
    means: list[np.ndarray] = []
    while d.time < max_time:
        samples = []
        for step in range(n_win):
            apply(d)
            mujoco.mj_step(m, d)
            if (step + 1) % every == 0:
                pts, _, fs = plate_contacts(m, d)
                if fs.sum() > _MIN_CONTACT_FORCE:
                    r = force_distribution(pts[:, 0], fs, length)
                    samples.append([r[k] for k in PRESS_METRICS])
        check_state(d)
        if len(samples) < _SAMPLES_PER_WINDOW // 2:  # not (yet) on the plate for most of the window
            means.clear()
            continue
        means.append(np.mean(samples, axis=0))
        if (
            d.time >= _MIN_TIME
            and len(means) >= _TREND_WINDOWS
            and settled(np.array(means[-_TREND_WINDOWS:]))
        ):
            out = dict(
                zip(PRESS_METRICS, (float(v) for v in np.mean(means[-_TREND_WINDOWS:], axis=0)), strict=True)
            )
            out["n_contacts"] = int(len(plate_contacts(m, d)[2]))
            out["settled_s"] = float(d.time)
            return out
    raise SimulationDiverged(
        f"the force on the plate did not settle within {max_time:.1f} s of simulated time"
    )


def settled(y: np.ndarray) -> bool:
    """No drift beyond the tolerances in window means ``y`` (n, 3): slope over the span, less 2 s.e."""
    n = len(y)
    t = np.arange(n) - 0.5 * (n - 1)
    slope = t @ (y - y.mean(axis=0)) / (t @ t)
    resid = y - y.mean(axis=0) - np.outer(t, slope)
    se = np.sqrt((resid**2).sum(axis=0) / (n - 2) / (t @ t))
    drift = (np.abs(slope) - 2.0 * se).clip(0.0) * (n - 1)
    tol = np.array([_DRIFT_FORCE_REL * abs(y[:, 0].mean()), _DRIFT_SHARE, _DRIFT_SHARE])
    return bool(np.all(drift <= tol))


def plate_box(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plate of a press model as placed: centre [m], rotation (3, 3), half extents [m]."""
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "plate")
    return d.geom_xpos[g].copy(), d.geom_xmat[g].reshape(3, 3).copy(), m.geom_size[g].copy()


def plate_contacts(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contacts with the geom named ``plate``: points, forces on the finger, normal forces.

    Points [m] (k, 3); the plate's force on the finger [N] (k, 3), in world (here the finger frame)
    axes; its normal component [N] (k,).
    """
    plate = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "plate")
    pts, forces, normal = [], [], []
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        if plate not in (c.geom[0], c.geom[1]):
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        # f6[:3] (normal, tangents) acts on geom2, in the contact frame whose normal runs geom1 -> geom2.
        f = c.frame.reshape(3, 3).T @ f6[:3]
        pts.append(c.pos.copy())
        forces.append(f if c.geom[0] == plate else -f)
        normal.append(f6[0])
    return np.reshape(pts, (-1, 3)), np.reshape(forces, (-1, 3)), np.asarray(normal, dtype=float)


_LCP_TOL = 1e-9
"""Linear press: largest allowed penetration [m] and complementarity residual [m·N] of the contact
solution (the NNLS active set solves it to round-off; 1 nm is far below the 0.5 mm gap)."""


def press_linear(
    design: FingerDesign, stiffness: Stiffness, model: str, tension: float, *, observe=None
) -> dict:
    """Flex finger pressed onto the plate by a linear static contact solve (small deflection).

    ``K u = f + Gᵀλ`` with MuJoCo's compiled stiffness ``K`` (`mjcodesign.models.flex.assemble_stiffness`),
    the tendon's first-order load ``f`` (`mjcodesign.models.flex.linear_tendon_load`) and unilateral
    frictionless contacts at the flex surface vertices, which keep their collision radius from the
    plate's lower face (gap ``s = s0 + G u ≥ 0``, normal force ``λ ≥ 0``, ``λ·s = 0``). Eliminating ``u``
    leaves a strictly convex QP in ``λ`` (``A = G K⁻¹ Gᵀ``), solved exactly as a non-negative least
    squares problem. The finger rises 0.5 mm onto the plate and barely bends, so the linear solve is the
    press's own limit, not an approximation of a large deflection; a test checks it against the
    trilinear flex's dynamics. ``observe(built, data, (points, forces), (centre, rotation, half))`` gets
    the model with the displacement loaded, the contact forces on the finger [N] and the plate.
    """
    import scipy.linalg as sla
    from scipy.optimize import nnls

    from mjcodesign.models.builder import build_finger
    from mjcodesign.models.flex import assemble_stiffness, grid_weights, linear_tendon_load, load_nodes
    from mjcodesign.models.types import FingerModel, SimOptions, TendonMode

    model = FingerModel(model)
    if not model.is_flex:
        raise ValueError(f"the linear press needs a flex model, not {model.value}")
    built = build_finger(
        design, stiffness, model, tendon_mode=TendonMode.POINT_FORCE, options=SimOptions(gravity=False)
    )
    m, h = built.model, built.fingers[0]
    nx, ny, nz, n_cells, order = h.grid
    K = assemble_stiffness(m, h)
    _, f = linear_tendon_load(design, h, tension)
    fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, h.flex)
    a, nv = m.flex_vertadr[fid], m.flex_vertnum[fid]
    verts = np.asarray(m.flex_vert[a : a + nv], dtype=float)  # rest positions, finger frame
    skin = float(m.flex_radius[fid])
    centre, R, half = plate_pose(design, PLATE_GAP + skin)
    normal = R @ np.array([0.0, 0.0, -1.0])  # the lower face's outward normal, towards the finger
    face = centre + half[2] * normal
    local = (verts - face) @ R  # plate axes: candidates lie under the face's rectangle
    under = (np.abs(local[:, 0]) <= half[0]) & (np.abs(local[:, 1]) <= half[1])
    cand = np.flatnonzero(under)
    Wv = grid_weights(design, n_cells, order, verts[cand])
    G = np.kron(Wv, normal[None, :])  # row i: n · (displacement of vertex i)
    s0 = (verts[cand] - face) @ normal - skin
    free = np.arange(3 * ny * nz, K.shape[0])  # gi = 0 is clamped
    Kf = sla.cho_factor(K[np.ix_(free, free)])
    Gf = G[:, free]
    KiG = sla.cho_solve(Kf, Gf.T)
    A = Gf @ KiG
    q = s0 + Gf @ sla.cho_solve(Kf, f[free])
    # min ½λᵀAλ + qᵀλ, λ ≥ 0, with A = L Lᵀ: ½‖Lᵀλ + L⁻¹q‖² + const, an NNLS problem.
    L = np.linalg.cholesky(A + 1e-12 * np.trace(A) / len(A) * np.eye(len(A)))
    lam, _ = nnls(L.T, -sla.solve_triangular(L, q, lower=True), maxiter=50 * len(A))
    gap = q + A @ lam
    if gap.min() < -_LCP_TOL or abs(lam @ gap) > _LCP_TOL * max(lam.sum(), 1.0):
        raise SimulationDiverged(
            f"linear press contact solve did not converge: penetration {-gap.min():.2e} m, "
            f"complementarity {abs(lam @ gap):.2e}"
        )
    u = np.zeros(K.shape[0])
    u[free] = sla.cho_solve(Kf, f[free]) + KiG @ lam
    if observe is not None:
        d = load_nodes(m, h, u[free])
        on = lam > 0
        pts = verts[cand[on]] + (Wv[on] @ u.reshape(-1, 3))
        observe(built, d, (pts, np.outer(lam[on], normal)), (centre, R, half))
    out = force_distribution(verts[cand, 0], lam, design.length)
    out["n_contacts"] = int(np.count_nonzero(lam > 0))
    return out
