"""Adjoint gradient of a FEM contact rollout: the time-averaged normal force on the object w.r.t. ln E.

``wp.Tape`` over segments of the rollout, replayed in reverse from checkpoints of the forward pass
(memory O(checkpoints + segment), time about two forwards plus one backward). The per-tet gradients of
the Lamé parameters are summed over the segments and taken back to the 22 ln E through the material
kernel once at the end.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SEGMENT", "mean_force_gradient", "end_segment", "log_e_gradient"]

SEGMENT = 200
"""Steps per taped segment of the adjoint (memory ~ segment × a few state arrays)."""


def mean_force_gradient(contact, duration: float, *, segment: int = SEGMENT) -> tuple[float, np.ndarray]:
    """Time-averaged normal contact force on the object [N] over ``duration`` [s], and its gradient.

    ``contact`` is a `mjcodesign.sim.fem.contact.FemContact`. The gradient is with respect to the 22
    ln(E / Pa), shape (22,); finger B's entries are zero.
    """
    wp = contact.wp
    dev = contact.dev
    fem = contact.fem
    n_steps = contact.steps(duration)
    fwd, states = contact.run_checkpointed(duration, frames=1, every=segment)
    horizon = n_steps * contact.dyn.dt
    n = fem.mesh.n_vertices
    adj_x = np.zeros((n, 3))
    adj_v = np.zeros((n, 3))
    g_mu = np.zeros(fem.mesh.n_tets)
    g_lam = np.zeros(fem.mesh.n_tets)
    seed = wp.array([1.0 / horizon], dtype=wp.float64, device=dev)
    for c in reversed(range(len(states))):
        xs, vs = states[c]
        x = wp.array(xs, dtype=wp.vec3d, device=dev, requires_grad=True)
        v = wp.array(vs, dtype=wp.vec3d, device=dev, requires_grad=True)
        x_start, v_start = x, v
        impulse = wp.zeros(1, dtype=wp.float64, device=dev, requires_grad=True)
        tape = wp.Tape()
        with tape:
            for s in range(c * segment + 1, min((c + 1) * segment, n_steps) + 1):
                x, v, _ = contact.step(x, v, s, impulse, contact.buffers(requires_grad=True), reuse=False)
        tape.backward(
            grads={
                x: wp.array(adj_x, dtype=wp.vec3d, device=dev),
                v: wp.array(adj_v, dtype=wp.vec3d, device=dev),
                impulse: seed,
            }
        )
        adj_x = x_start.grad.numpy().copy()
        adj_v = v_start.grad.numpy().copy()
        end_segment(tape, fem, g_mu, g_lam)
    return fwd.mean_normal_force, log_e_gradient(fem, g_mu, g_lam)


def end_segment(tape, body, g_mu: np.ndarray, g_lam: np.ndarray) -> None:
    """After a taped segment's backward: collect the material gradients and release the tape.

    Adds ``body``'s per-tet μ', λ' gradients to ``g_mu``, ``g_lam`` (in place) and zeroes them. ``body`` has Warp arrays ``mu`` and ``lam`` (a `FemBody`, or the two-finger `FemGripper`).
    """
    g_mu += body.mu.grad.numpy()
    g_lam += body.lam.grad.numpy()
    tape.zero()
    body.mu.grad.zero_()
    body.lam.grad.zero_()
    tape.reset()


def log_e_gradient(fem, g_mu: np.ndarray, g_lam: np.ndarray) -> np.ndarray:
    """Gradient w.r.t. the 22 ln E from the per-tet gradients w.r.t. μ' and λ' (through the material).

    ``fem`` has ``log_e``, ``mu``, ``lam``, ``update_material`` and ``options.device`` (a `FemBody`, or
    the two-finger `FemGripper`).
    """
    wp = fem.wp
    dev = fem.options.device
    fem.log_e.grad.zero_()
    tape = wp.Tape()
    with tape:
        fem.update_material()
    tape.backward(
        grads={
            fem.mu: wp.array(g_mu, dtype=wp.float64, device=dev),
            fem.lam: wp.array(g_lam, dtype=wp.float64, device=dev),
        }
    )
    g = fem.log_e.grad.numpy().copy()
    tape.zero()
    fem.mu.grad.zero_()
    fem.lam.grad.zero_()
    return g
