"""``bench fem``: the Warp FEM's speed on this machine (explicit steps, static solve, dynamic grasp)."""

from __future__ import annotations

import time

import numpy as np

__all__ = ["bench_fem"]

_GRASP_MESH_H = 4e-3
"""Cell size [m] of the grasp benchmark's FEM mesh (2 spine layers, 1,431 vertices)."""


def bench_fem(
    *, h: float = 3e-3, spine_layers: int = 4, dyn_steps: int = 2000, grasp_horizon: float = 0.2
) -> dict:
    """FEM speed on this machine: explicit steps/s, a static curl and its gradient, a dynamic grasp.

    The mesh has cells of ``h`` [m] and ``spine_layers`` layers through the spine (linear tets);
    ``dyn_steps`` explicit steps are timed. Times [s] of one static curl solve plus its gradient, and of
    the forward and forward-plus-gradient of a dynamic grasp of ``grasp_horizon`` [s].

    The explicit step of ``steps_per_s`` is the smaller of the paper's 2.5 µs and the mesh's CFL estimate.
    The grasp (`mjcodesign.sim.fem.grasp.grasp_scene`) runs the paper's 2.5 µs on a 4 mm mesh without
    waypoint layers, with selective mass scaling; its loss is the time-averaged normal force on the box
    and the gradient is with respect to the 22 ln E (checkpointed ``wp.Tape``).
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.sim.fem import FemDynamics, FemFinger, FemOptions

    design = FingerDesign()
    fem = FemFinger(
        design, Stiffness.preset("paper-optimized"), options=FemOptions(h=h, spine_layers=spine_layers)
    )
    dyn = FemDynamics(dt=min(FemDynamics().dt, fem.stable_dt()))
    fem.rollout(10 * dyn.dt, dynamics=dyn, position=(0, 0, 0.05), frames=1)  # compile and warm up
    t0 = time.perf_counter()
    fem.rollout(dyn_steps * dyn.dt, dynamics=dyn, position=(0, 0, 0.05), frames=1)
    steps_per_s = dyn_steps / (time.perf_counter() - t0)
    load = fem.tendon_load(0.5)
    t0 = time.perf_counter()
    x = fem.solve_static(load, steps=2)
    t1 = time.perf_counter()
    g = np.zeros((fem.mesh.n_vertices, 3))
    g[fem.mesh.tip, 2] = 1.0
    fem.static_gradient(x, load, g)
    t2 = time.perf_counter()
    grasp = _bench_grasp(design, grasp_horizon)
    return {
        "device": fem.options.device,
        "n_tets": fem.mesh.n_tets,
        "n_vertices": fem.mesh.n_vertices,
        "dt_s": dyn.dt,
        "steps_per_s": steps_per_s,
        "grasp_0.2s_forward_s_estimate": 0.2 / dyn.dt / steps_per_s,
        "static_curl_s": t1 - t0,
        "static_gradient_s": t2 - t1,
        **grasp,
    }


def _bench_grasp(design, horizon: float) -> dict:
    """Forward and forward-plus-gradient times of the single-finger grasp over ``horizon`` [s]."""
    from mjcodesign.crosscheck import press_tension
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.sim.fem import FemFinger, FemOptions, grasp_scene

    stiffness = Stiffness.preset("paper-optimized")
    fem = FemFinger(
        design, stiffness, options=FemOptions(h=_GRASP_MESH_H, spine_layers=2, waypoint_layers=False)
    )
    tension = press_tension(stiffness)
    sim = grasp_scene(fem, tension)
    sim.run(10 * sim.dyn.dt, frames=1)  # compile and warm up
    t0 = time.perf_counter()
    fwd = sim.run(horizon, frames=1)
    t1 = time.perf_counter()
    value, grad = sim.mean_force_gradient(horizon)
    t2 = time.perf_counter()
    return {
        "grasp_horizon_s": horizon,
        "grasp_dt_s": sim.dyn.dt,
        "substeps": fwd.steps,
        "grasp_n_vertices": fem.mesh.n_vertices,
        "grasp_added_mass_fraction": sim.added_mass_fraction,
        "grasp_tension_n": tension,
        "grasp_mean_force_n": value,
        "grasp_max_penetration_m": fwd.max_penetration,
        "grasp_forward_s": t1 - t0,
        "grasp_forward_backward_s": t2 - t1,
        "grasp_gradient_norm": float(np.linalg.norm(grad)),
    }
