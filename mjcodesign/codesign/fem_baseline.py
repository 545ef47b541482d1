"""Baseline 1: the same design descent with the differentiable FEM's gradient instead of the surrogate's.

Each object is grasped at one pose (the top-down :func:`~mjcodesign.scenarios.grasp.auto_pose`; the
FEM grasp has no pose search), with a short grasp (the FEM takes ~10⁵ substeps per 0.1 s on a CPU).
Every iteration runs :func:`mjcodesign.sim.fem.fem_grasp_loss_and_grad` once per object at the
current design, sums the losses and gradients (d L / d ln E), and takes the same AdamW step on z as
Algorithm 1 (lr 0.1, ``ln E = 13.5 + 3.5 · sigmoid(z)``). Its L_opt is the FEM module's ``paper_loss``
(the authors' weights; vertical = palm z, which is the world's vertical at the top-down pose; the
ground contact is a count of FEM points, piecewise constant, so it carries no gradient).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from mjcodesign.codesign.optimize import log_e_of, z_of
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E
from mjcodesign.errors import DesignError
from mjcodesign.objects import GraspObject
from mjcodesign.scenarios.drive import TendonForce
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose

__all__ = ["FEM_SCENARIO", "FemDescent", "fem_descent"]

FEM_SCENARIO = GraspScenario(
    settle_s=0.0, close_s=0.002, tighten_s=0.004, lift_s=0.004, hold_s=0.008, post_hold_s=0.002,
    tendon=TendonForce(tension=2.0), lift=0.002, impulse=0.0,
)  # fmt: skip
"""A 20 ms grasp that starts 2 mm from the object (tests/test_fem_grasp.py's gradient case)."""
_START_GAP = 0.002  # [m] the carriages start this far outside the pose's openings
_DT = 1e-5  # [s] FEM step: the gradient test's (the paper's 2.5 µs is 4x the cost)
_SEGMENT = 300  # substeps per taped segment of the adjoint


@dataclass
class FemDescent:
    """Per-iteration losses, gradient norms and wall times of the FEM descent."""

    objects: tuple[str, ...]
    loss: list[list[float]] = field(default_factory=list)
    """L_opt per iteration and object."""
    grad_norm: list[float] = field(default_factory=list)
    """‖Σ_objects d L / d ln E‖ per iteration."""
    iteration_s: list[float] = field(default_factory=list)
    iteration_cpu_s: list[float] = field(default_factory=list)
    """Process CPU time per iteration (the host is shared: wall time carries the others' load)."""
    designs: list[list[float]] = field(default_factory=list)
    """ln E at each iteration."""

    def summary(self) -> dict:
        """JSON-ready, with the median time per iteration."""
        return {
            "objects": list(self.objects),
            "iterations": len(self.iteration_s),
            "loss": self.loss,
            "total_loss": [float(sum(v)) for v in self.loss],
            "grad_norm": self.grad_norm,
            "iteration_s": self.iteration_s,
            "median_iteration_s": float(np.median(self.iteration_s)) if self.iteration_s else None,
            "iteration_cpu_s": self.iteration_cpu_s,
            "designs": self.designs,
        }


def fem_descent(
    objects: dict[str, GraspObject],
    iterations: int,
    *,
    init_log_e: float = 15.6,
    lr: float = 0.1,
    weight_decay: float = 0.01,
    scenario: GraspScenario = FEM_SCENARIO,
    options=None,
) -> FemDescent:
    """``iterations`` AdamW steps on one design through the FEM gradient (module docstring)."""
    import torch

    from mjcodesign.sim.fem import FemDynamics, FemOptions, fem_grasp_loss_and_grad

    if iterations < 1 or not objects:
        raise DesignError("the FEM descent needs an object and an iteration or more")
    opts = options or FemOptions(h=10e-3, h_flexure=8e-3, spine_layers=2, waypoint_layers=False)
    dyn = FemDynamics(dt=_DT, contact_kd=0.0)
    poses = {n: auto_pose(o) for n, o in objects.items()}
    out = FemDescent(tuple(objects))
    z = torch.tensor(z_of(np.full(N_LOG_E, init_log_e)), dtype=torch.float64, requires_grad=True)
    opt = torch.optim.AdamW([z], lr=lr, weight_decay=weight_decay)
    for _ in range(iterations):
        t, cpu = time.perf_counter(), time.process_time()
        zs = z.detach().numpy().copy()
        log_e = log_e_of(zs)
        grad, losses = np.zeros(N_LOG_E), []
        for n, obj in objects.items():
            p = poses[n]
            r = fem_grasp_loss_and_grad(
                log_e, obj, p, scenario=scenario, options=opts, dynamics=dyn, segment=_SEGMENT,
                start_openings=tuple(o + _START_GAP for o in p.openings),
            )  # fmt: skip
            grad += r.grad
            losses.append(float(r.loss))
        s = 1.0 / (1.0 + np.exp(-zs))
        opt.zero_grad(set_to_none=True)
        z.grad = torch.from_numpy(grad * (LOG_E_MAX - LOG_E_MIN) * s * (1.0 - s))  # d ln E / d z
        opt.step()
        out.iteration_s.append(time.perf_counter() - t)
        out.iteration_cpu_s.append(time.process_time() - cpu)
        out.loss.append(losses)
        out.grad_norm.append(float(np.linalg.norm(grad)))
        out.designs.append(log_e.tolist())
    return out
