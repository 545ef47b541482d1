"""Gradient of the authors' co-design loss L_opt over the FEM grasp with respect to the 22 ln E.

L_opt (`mjcodesign.sim.fem.grasp_outcome.paper_loss`) reads the body force (the mean over the hold
span of the fingers' wrench, a sum the forward pass accumulates) and the displacement (the object's
position relative to the palm at the end of tightening and at the end; the palm is driven, so only
the object's positions carry a gradient).

``wp.Tape`` over segments of the rollout, replayed in reverse from checkpoints of the forward pass
(memory O(checkpoints + segment), time about two forwards plus one backward), as
`mjcodesign.sim.fem.adjoint` does for the single finger. A segment boundary falls at the end of
tightening, where the displacement's first position seeds the object's adjoint; the object's previous
normal load (it sets where friction turns viscous) is carried across segments with the state. Held
fixed: the closest object face of every vertex (piecewise constant) and the selectively scaled masses
(a numerical device of the explicit step, set from the design the grasp was built with).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from mjcodesign.errors import SimulationDiverged, UnsupportedError
from mjcodesign.scenarios.outcome import Outcome
from mjcodesign.sim.fem.adjoint import end_segment, log_e_gradient
from mjcodesign.sim.fem.grasp_outcome import FemGraspRun, paper_loss

__all__ = ["SEGMENT", "FemLossGradient", "fem_grasp_loss_and_grad", "loss_gradient"]

_NO_POSITION_GRADIENT = (
    "the FEM's L_opt gradient is of the force-mode tendon (the paper's); the position servo's implicit "
    "damper updates the state in place, off the tape"
)
SEGMENT = 200
"""Substeps per taped segment (memory ~ segment × a dozen arrays of the vertices)."""


def loss_gradient(grasp, *, segment: int = SEGMENT) -> tuple[float, np.ndarray, FemGraspRun]:
    """(L_opt, ∂L_opt/∂(ln E) of shape (22,), the forward run) of a `FemGrasp` rolled out whole.

    Raises `SimulationDiverged` if the forward pass diverged (its outcome names where),
    `UnsupportedError` for a position-mode tendon.
    """
    if grasp.position_mode:
        raise UnsupportedError(_NO_POSITION_GRADIENT)
    wp = grasp.wp
    dev = grasp.dev
    g = grasp.gripper
    sch = grasp.schedule
    n = sch.n_steps
    starts = sorted(set(range(1, n + 1, segment)) | {sch.grasp_step + 1})
    run = grasp.run(checkpoints=starts)
    if run.substeps < n:
        raise SimulationDiverged(run.outcome.reason)
    loss, d_force, d_disp = paper_loss(run.outcome.body_force, run.outcome.displacement, run.ground_points)
    R = grasp.placement.rotation
    hold_seed = wp.array(np.stack([R @ d_force[3:], R @ d_force[:3]]), dtype=wp.vec3d, device=dev)
    d_pos = R @ d_disp  # ∂L/∂(COM at the end); minus this at the end of tightening
    adj = [
        np.zeros((g.n_vertices, 3)),
        np.zeros((g.n_vertices, 3)),
        d_pos,
        np.zeros(4),
        np.zeros(3),
        np.zeros(3),
    ]
    adj_load = 0.0  # the last substep's normal load moves nothing
    g_mu = np.zeros(g.n_tets)
    g_lam = np.zeros(g.n_tets)
    ends = [*starts[1:], n + 1]
    for a, b in reversed(list(zip(starts, ends, strict=True))):
        *arrays, load = run.checkpoints[a]
        st = grasp.state_from(arrays, requires_grad=True)
        first = st
        prev = wp.array([load], dtype=wp.float64, device=dev, requires_grad=True)
        first_load = prev
        hold_sum = wp.zeros(2, dtype=wp.vec3d, device=dev, requires_grad=True)
        tape = wp.Tape()
        with tape:
            for s in range(a, b):
                st, buf = grasp.taped_step(st, s, prev, hold_sum)
                prev = buf.load
        grads = {arr: wp.array(seed, dtype=arr.dtype, device=dev) for arr, seed in zip(st, adj, strict=True)}
        grads[hold_sum] = hold_seed
        grads[prev] = wp.array([adj_load], dtype=wp.float64, device=dev)
        tape.backward(grads=grads)
        adj = [arr.grad.numpy().reshape(seed.shape).copy() for arr, seed in zip(first, adj, strict=True)]
        adj_load = float(first_load.grad.numpy()[0])
        if a == sch.grasp_step + 1:
            adj[2] = adj[2] - d_pos
        end_segment(tape, g, g_mu, g_lam)
    return loss, log_e_gradient(g, g_mu, g_lam), run


class FemLossGradient(NamedTuple):
    """What `fem_grasp_loss_and_grad` returns."""

    loss: float
    """The authors' L_opt of the grasp (`mjcodesign.sim.fem.grasp_outcome.paper_loss`)."""
    grad: np.ndarray
    """∂L_opt/∂(ln E), shape (22,): finger A's 11 blocks base to tip, then finger B's."""
    outcome: Outcome
    """The grasp's outcome (as MuJoCo's: body force, Δq, success)."""
    run: FemGraspRun
    """The forward run (frames, hold wrench, wall time)."""


def fem_grasp_loss_and_grad(
    log_e,
    obj,
    pose,
    *,
    scenario=None,
    design=None,
    options=None,
    dynamics=None,
    start_openings=None,
    segment: int = SEGMENT,
    gripper=None,
) -> FemLossGradient:
    """L_opt of one FEM grasp and its gradient w.r.t. the 22 ln E: the differentiable simulator's baseline.

    ``log_e``: a `Stiffness` or 22 ln(E / Pa) (finger A base to tip, then B); ``obj`` a
    `mjcodesign.objects.GraspObject` with its convex decomposition; ``pose`` a `GripperPose`.
    ``scenario`` (default `GraspScenario` at `GRASP_TENSION`, the grasp study's 4 N),
    ``design`` (default `FingerDesign`), ``options``/``dynamics`` the mesh and step (defaults
    `GRASP_OPTIONS`, the paper's 2.5 µs), ``start_openings`` the carriages at t = 0 [m] (default the
    scene's, clear of the object), ``segment`` substeps per taped segment, ``gripper`` a built
    `FemGripper` of the same geometry, mesh and step to reuse (its ln E is overwritten).

    Raises `SimulationDiverged` when the forward pass blows up, `UnsupportedError` for a position-mode
    tendon, `PoseError`/`DesignError` on bad input.
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models.types import FingerModel
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, build_scene
    from mjcodesign.sim.fem.gripper_grasp import GRASP_TENSION, FemGrasp

    stiffness = log_e if isinstance(log_e, Stiffness) else Stiffness(np.asarray(log_e, dtype=float).ravel())
    design = design or FingerDesign()
    scenario = scenario or GraspScenario(tendon=TendonForce(tension=GRASP_TENSION))
    scene = build_scene(obj, design, stiffness, FingerModel.CHAIN, pose)
    if start_openings is not None:
        scene = dataclasses.replace(scene, start_openings=tuple(float(s) for s in start_openings))
    grasp = FemGrasp(scene, scenario, options=options, dynamics=dynamics, gripper=gripper)
    loss, grad, run = loss_gradient(grasp, segment=segment)
    return FemLossGradient(loss, grad, run.outcome, run)
