"""Static checks of the finger models: cantilever tip load against Euler–Bernoulli, free tendon curl."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import mujoco
import numpy as np

from mjcodesign.design.beam import cantilever_tip_deflection
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, SimulationDiverged
from mjcodesign.models.builder import build_finger
from mjcodesign.models.simulate import check_state
from mjcodesign.models.types import Built, FingerModel, SimOptions, TendonMode

__all__ = ["run_to_rest", "validate_beam", "curl", "bend_angles", "AUTO_DEFLECTION"]

AUTO_DEFLECTION = 0.01
"""Default tip load gives δ = 1% of L: deep in the small-deflection range of beam theory."""
_SMALL_DEFLECTION = 0.05
"""Above δ/L = 5% geometric nonlinearity makes linear beam theory an unfair reference."""
_REST_REL = 1e-5
"""At rest: the metric moved less than this fraction of its total change over one check window."""
_EFFECTIVE_MASS = 0.24
"""Tip-equivalent mass of a uniform cantilever, as a fraction of its mass (first mode)."""


def run_to_rest(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    apply: Callable[[mujoco.MjData], None],
    metric: Callable[[mujoco.MjData], float | np.ndarray],
    *,
    max_time: float = 30.0,
    window: float = 0.1,
    min_time: float = 0.2,
) -> float | np.ndarray:
    """Step until ``metric`` stops changing; return its change from the unloaded state.

    ``apply`` is called before every step (loads may depend on the configuration).
    """
    mujoco.mj_forward(m, d)
    x0 = np.asarray(metric(d), dtype=float)
    n_win = max(1, int(round(window / m.opt.timestep)))
    last = x0
    while d.time < max_time:
        for _ in range(n_win):
            apply(d)
            mujoco.mj_step(m, d)
        check_state(d)
        x = np.asarray(metric(d), dtype=float)
        total = np.max(np.abs(x - x0))
        if d.time >= min_time and np.max(np.abs(x - last)) <= _REST_REL * max(total, 1e-12):
            out = x - x0
            return float(out) if out.ndim == 0 else out
        last = x
    raise SimulationDiverged(f"did not come to rest within {max_time:.1f} s of simulated time")


def rest_options(design: FingerDesign, young: np.ndarray, options: SimOptions | None) -> SimOptions:
    """Gravity off, and Rayleigh damping near-critical for the first bending mode (statics only)."""
    options = options or SimOptions()
    k_tip = 1.0 / cantilever_tip_deflection(design, young, 1.0)
    omega = np.sqrt(k_tip / (_EFFECTIVE_MASS * design.mass))
    beta = float(np.clip(2.0 / omega, options.timestep, 0.5))
    return replace(options, gravity=False, damping_time=beta)


def _tip_loader(built: Built, force: float):
    m = built.model
    h = built.fingers[0]
    if built.finger_model is FingerModel.CHAIN:
        sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, h.tip_site)
        body = int(m.site_bodyid[sid])

        def apply(d):
            d.qfrc_applied[:] = 0.0
            mujoco.mj_applyFT(
                m, d, np.array([0, 0, force]), np.zeros(3), d.site_xpos[sid], body, d.qfrc_applied
            )

        return apply, (lambda d: float(d.site_xpos[sid, 2]))
    from mjcodesign.models.flex import TipLoad

    tl = TipLoad(m, h, force)
    return tl.apply, tl.position


def validate_beam(
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel | str,
    *,
    force: float | None = None,
    options: SimOptions | None = None,
    dynamic: bool | None = None,
    observe=None,
) -> dict:
    """Clamp finger A at its base, load its tip, and compare the deflection with Euler–Bernoulli.

    The chain runs its dynamics to rest. Flex models by default solve ``K u = f`` with MuJoCo's compiled
    cell stiffness, the small-deflection rest state of the same model (a test checks that both agree);
    ``dynamic=True`` runs them to rest instead (minutes for the quadratic flex). ``observe(built,
    data)``, if given, is called with the model and its data at rest (the linear solve's displacement
    loaded into the flex nodes).
    """
    model = FingerModel(model)
    young = stiffness.finger(0)
    if force is None:
        force = AUTO_DEFLECTION * design.length / cantilever_tip_deflection(design, young, 1.0)
    if not np.isfinite(force) or force <= 0:
        raise DesignError(f"tip force must be positive and finite, got {force}")
    dynamic = (not model.is_flex) if dynamic is None else dynamic
    opts = rest_options(design, young, options)
    t0 = time.perf_counter()
    built = build_finger(design, stiffness, model, options=opts, tendon_mode=TendonMode.NATIVE)
    settled = None
    if dynamic:
        d = mujoco.MjData(built.model)
        apply, metric = _tip_loader(built, force)
        delta = run_to_rest(built.model, d, apply, metric, max_time=max(30.0, 40 * opts.damping_time))
        settled = float(d.time)
    else:
        from mjcodesign.models.flex import load_nodes, static_tip_solve

        delta, u = static_tip_solve(built.model, built.fingers[0], force)
        if observe is not None:
            d = load_nodes(built.model, built.fingers[0], u)
    if observe is not None:
        observe(built, d)
    analytic = cantilever_tip_deflection(design, young, force)
    return {
        "model": model.value,
        "force_n": float(force),
        "tip_deflection_m": float(delta),
        "analytic_m": float(analytic),
        "rel_error": float(abs(delta - analytic) / analytic),
        "deflection_over_length": float(analytic / design.length),
        "small_deflection": bool(analytic / design.length <= _SMALL_DEFLECTION),
        "method": "dynamics-to-rest" if dynamic else "linear-static",
        "settled_s": settled,
        "wall_time_s": time.perf_counter() - t0,
    }


def bend_angles(built: Built, d: mujoco.MjData) -> np.ndarray:
    """Bend of every block of finger A [rad], shape (n_blocks,); positive curls inwards."""
    m = built.model
    h = built.fingers[0]
    if built.finger_model is FingerModel.CHAIN:
        q = np.array(
            [d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)]] for j in h.joints]
        )
        # A block's bend is the sum of its hinges' (two per block with SimOptions.hinges_per_block=2)
        return np.bincount(h.joint_blocks, weights=q, minlength=built.design.n_blocks)
    # Flex: direction of the spine (bottom mid-width node line) at block boundaries.
    nx, ny, nz, n_cells, order = h.grid
    gj = ny // 2
    pts = []
    base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, h.base_body)
    for gi in range(nx):
        if gi == 0:
            pts.append(d.xpos[base] + d.xmat[base].reshape(3, 3) @ np.array([0, 0, 0]))
            continue
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{h.prefix}n{gi}_{j}_0") for j in range(ny)]
        pts.append(d.xpos[ids].mean(axis=0) if ny == 2 else d.xpos[ids[gj]])
    pts = np.array(pts)
    xs = np.linspace(0, built.design.length, nx)
    seg = np.diff(pts, axis=0)
    phi = np.unwrap(np.arctan2(seg[:, 2], seg[:, 0]))
    xm = 0.5 * (xs[1:] + xs[:-1])
    edges = [0.0] + [b.x1 for b in built.design.blocks()]
    phi_at = np.interp(edges, xm, phi, left=0.0, right=phi[-1])
    phi_at[0] = 0.0
    return np.diff(phi_at)


def curl(
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel | str,
    tension: float,
    *,
    tendon_mode: TendonMode = TendonMode.NATIVE,
    variant: str = "frictionless",
    options: SimOptions | None = None,
    observe=None,
) -> dict:
    """Free tendon curl of finger A to rest at ``tension`` [N]: tip position and per-block bend.

    ``observe(built, data)``, if given, is called with the model and its data at rest.
    """
    from mjcodesign.models.tendon import TendonDriver

    model = FingerModel(model)
    opts = rest_options(design, stiffness.finger(0), options)
    built = build_finger(design, stiffness, model, options=opts, tendon_mode=tendon_mode)
    d = mujoco.MjData(built.model)
    drv = TendonDriver(built, variant)
    drv.set_tension(d, tension)
    sid = mujoco.mj_name2id(built.model, mujoco.mjtObj.mjOBJ_SITE, built.fingers[0].tip_site)
    tip = run_to_rest(
        built.model,
        d,
        drv.apply,
        lambda d: d.site_xpos[sid].copy(),
        max_time=max(30.0, 40 * opts.damping_time),
    )
    angles = bend_angles(built, d)
    if observe is not None:
        observe(built, d)
    return {
        "model": model.value,
        "tension_n": float(tension),
        "tip_displacement_m": [float(v) for v in tip],
        "bend_angle_rad": float(np.sum(angles)),
        "block_angles_rad": [float(a) for a in angles],
    }
