"""``bench fem``: the Warp FEM's speed on this machine (explicit steps, static solve, dynamic grasps).

The two-finger grasp (`_bench_gripper`) times one whole grasp of the paper's scenario
(`mjcodesign.sim.fem.gripper_grasp.FemGrasp`, 0.70 s at 2.5 µs: 280,800 substeps) forward and forward
plus the L_opt gradient (`mjcodesign.sim.fem.grasp_adjoint.loss_gradient`), wall and process CPU time,
on a mesh given by name (`GRIPPER_MESHES`). Throughput is vertices × substeps per second; the authors'
simulator ran 0.17 M/s on this project's 2-core machine.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["bench_fem"]

GRIPPER_MESHES = {
    "coarse": {"h": 10e-3, "h_flexure": 8e-3, "spine_layers": 2},
    "default": {"h": 4e-3, "spine_layers": 2},
    "fine": {"h": 3e-3, "spine_layers": 4},
    "corrected": {"h": 10e-3, "h_flexure": 8e-3, "spine_layers": 2, "locking_correction": True},
}
"""Meshes of the two-finger grasp benchmark: ``coarse`` 396 vertices a finger (the authors' whole mesh had
432 particles), ``default`` `GRASP_OPTIONS` (1,431), ``fine`` 3,339 (cantilever 0.73 of beam theory on
the soft finger, docs/benchmarks.md), ``corrected`` the coarse mesh with its locking corrected
(`FemOptions.locking_correction`): its cantilever within 1.3% of the refined FEM's (tests/test_fem_locking.py)."""
_GRASP_MESH_H = 4e-3
"""Cell size [m] of the grasp benchmark's FEM mesh (2 spine layers, 1,431 vertices)."""


def bench_fem(
    *,
    h: float = 3e-3,
    spine_layers: int = 4,
    dyn_steps: int = 2000,
    grasp_horizon: float = 0.2,
    gripper: str | None = "coarse",
    gradient: bool = True,
    gripper_only: bool = False,
    gripper_dt: float | None = None,
) -> dict:
    """FEM speed on this machine: explicit steps/s, a static curl and its gradient, a dynamic grasp.

    The mesh has cells of ``h`` [m] and ``spine_layers`` layers through the spine (linear tets);
    ``dyn_steps`` explicit steps are timed. Times [s] of one static curl solve plus its gradient, and of
    the forward and forward-plus-gradient of a dynamic grasp of ``grasp_horizon`` [s].

    The explicit step of ``steps_per_s`` is the smaller of the paper's 2.5 µs and the mesh's CFL estimate.
    The grasp (`mjcodesign.sim.fem.grasp.grasp_scene`) runs the paper's 2.5 µs on a 4 mm mesh without
    waypoint layers, with selective mass scaling; its loss is the time-averaged normal force on the box
    and the gradient is with respect to the 22 ln E (checkpointed ``wp.Tape``).

    ``gripper`` names the mesh (`GRIPPER_MESHES`) of the two-finger grasp to time, or None to skip it;
    ``gradient`` also times its forward plus gradient; ``gripper_dt`` [s] its substep (default the
    paper's 2.5 µs); ``gripper_only`` skips the single-finger benches.
    """
    if gripper_only:
        return {} if gripper is None else _bench_gripper(gripper, gradient=gradient, dt=gripper_dt)
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
    two = {} if gripper is None else _bench_gripper(gripper, gradient=gradient, dt=gripper_dt)
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
        **two,
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


def _bench_gripper(mesh: str, *, gradient: bool, dt: float | None = None) -> dict:
    """Times of one whole two-finger grasp (forward; forward + L_opt gradient) on the mesh ``mesh``."""
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError
    from mjcodesign.models.types import FingerModel
    from mjcodesign.objects import box_object
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene
    from mjcodesign.sim.fem import FemDynamics, FemOptions
    from mjcodesign.sim.fem.grasp_adjoint import loss_gradient
    from mjcodesign.sim.fem.gripper_grasp import GRASP_TENSION, FemGrasp

    if mesh not in GRIPPER_MESHES:
        raise DesignError(f"unknown gripper mesh {mesh!r}: choose from {', '.join(GRIPPER_MESHES)}")
    obj = box_object((0.04, 0.04, 0.06), 100.0)
    design = FingerDesign()
    scene = build_scene(
        obj, design, Stiffness.preset("semi-rigid"), FingerModel.CHAIN, auto_pose(obj, design)
    )
    options = FemOptions(waypoint_layers=False, **GRIPPER_MESHES[mesh])
    dynamics = FemDynamics() if dt is None else FemDynamics(dt=dt)
    grasp = FemGrasp(
        scene, GraspScenario(tendon=TendonForce(tension=GRASP_TENSION)), options=options, dynamics=dynamics
    )
    grasp.run(steps=10)  # compile and warm up
    c0, t0 = time.process_time(), time.perf_counter()
    run = grasp.run()
    c1, t1 = time.process_time(), time.perf_counter()
    out = {
        "gripper_mesh": mesh,
        "gripper_n_vertices": run.n_vertices,
        "gripper_n_tets": grasp.gripper.n_tets,
        "gripper_dt_s": run.dt,
        "gripper_substeps": run.substeps,
        "gripper_added_mass_fraction": run.added_mass_fraction,
        "gripper_outcome": run.outcome.reason,
        "gripper_forward_s": t1 - t0,
        "gripper_forward_cpu_s": c1 - c0,
        "gripper_vertex_substeps_per_s": run.n_vertices * run.substeps / (t1 - t0),
        "gripper_vertex_substeps_per_cpu_s": run.n_vertices * run.substeps / (c1 - c0),
    }
    if gradient:
        loss, grad, _ = loss_gradient(grasp)
        c2, t2 = time.process_time(), time.perf_counter()
        out.update(
            gripper_forward_gradient_s=t2 - t1,
            gripper_forward_gradient_cpu_s=c2 - c1,
            gripper_l_opt=loss,
            gripper_gradient_norm=float(np.linalg.norm(grad)),
        )
    return out
