"""Statics of the Warp FEM finger: quasi-static Newton with load stepping, and the adjoint gradient.

`FemStatics.solve_static` runs Newton on the free vertices with load stepping. The tangent is assembled
from per-tet blocks (`mjcodesign.sim.fem.body.FemBody.tangent`) plus the Jacobian of
configuration-dependent (tendon) loads, and factorised by SuperLU (scipy). A factorisation is reused as
the preconditioner of GMRES on the current tangent until GMRES stalls; only then is the tangent
refactorised. The first step of every load increment follows the equilibrium path (tangent at the
previous load). A trust region on the step (at most 5 mm per vertex; 10% of the finger length on the
path) keeps large tendon curls on track.

`FemStatics.static_gradient` differentiates a scalar outcome of a static equilibrium with respect to the
22 ln E by the adjoint of the equilibrium, K^T λ = ∂m/∂x, and ``λ·∂f/∂(ln E)`` through ``wp.Tape`` over
the material and force kernels. Finger B's 11 entries are exactly zero.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mjcodesign.errors import SimulationDiverged
from mjcodesign.sim.fem.body import FemBody

__all__ = ["FemStatics"]

_NEWTON_RTOL = 1e-5
"""Newton stops when the free residual is below this fraction of the applied load's norm. Positions are
absolute (≈0.1 m, ulp 3e-17 m), so K·ulp puts a floor near 1e-6 of a δ = 1%·L tip load on the soft
finger; quadratic convergence reaches it in 3–5 iterations."""
_NEWTON_MAX_ITER = 40
"""Newton iterations per load increment; `FemFinger.solve_static` then halves the increment and retries
from the last converged state (the soft 0.02 N quadratic curl takes ~5 per increment; a 0.5 N
linear-tet curl, about 1.4 rad in 2 increments, up to ~32: its trust-region-limited travel)."""
_MAX_CUTBACK_FACTOR = 32
"""Smallest load increment: the requested one divided by this (five halvings)."""
_MAX_STEP = 0.005
"""Largest vertex move of one Newton step [m]; larger steps are scaled down (trust region)."""
_MAX_PREDICTOR_REL = 0.1
"""Largest vertex move of the first step of a load increment, which follows the equilibrium path, as a
fraction of the finger length (13.6 mm). A rigid turn by 0.1 rad, linearised, stretches the tip by
L·0.1²/2 = 0.5% of L, which one Newton step removes (measured). The soft 0.02 N curl in 4 increments
predicts 7.7 mm each; clipped to 5 mm it took 8 iterations per increment, not 5."""
_GMRES_ITER = 8
"""GMRES iterations on a reused factorisation before the tangent is refactorised; where it preconditions
well GMRES reaches ``_GMRES_RTOL`` in 4–6 (soft quadratic curl, measured)."""
_GMRES_PROBE = 3
"""GMRES iterations before its rate is judged: it stops when that rate cannot reach ``_GMRES_RTOL``
within ``_GMRES_ITER`` (far from equilibrium the tangent moves too much for a reused factorisation)."""
_GMRES_RTOL = 1e-6
"""A step's linear residual, as a fraction of the Newton residual. At 1e-4 the bending part of the
residual left in the last step moved the tip by ~1e-13 m, which shifted the finite-difference check of
the static gradient by 2e-4 (1e-6: 2e-5, as with direct solves); at 1e-8 GMRES met the round-off of the
tangent product (SuperLU's own solve leaves 1.2e-8) and gave up."""
_SPLU = {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.1, "options": {"SymmetricMode": True}}
"""SuperLU settings: the tangent's pattern is symmetric. 2.2 s against 3.5 s for the default COLAMD with
partial pivoting on the 44,130 free DOFs of the quadratic h 4 mm mesh (same solution to 1e-8)."""
_STEP_TOL = 1e-11
"""Newton also stops when its step is below this fraction of the finger length (position roundoff)."""


class FemStatics(FemBody):
    """A `FemBody` with a static equilibrium solver and its adjoint gradient."""

    def solve_static(self, load: Callable, *, steps: int = 1, x0: np.ndarray | None = None) -> np.ndarray:
        """Equilibrium positions [m] (n, 3) under ``load``; counts of the work in ``self.solve_stats``.

        The load is ramped in ``steps`` equal increments; each is solved by Newton to ``_NEWTON_RTOL``
        (or a step below ``_STEP_TOL``·L) with a trust region on the step. An increment that does not
        converge in ``_NEWTON_MAX_ITER`` iterations is halved and retried from the last converged state
        (``solve_stats["cutbacks"]``), down to 1/``_MAX_CUTBACK_FACTOR`` of the first; past that it
        raises `SimulationDiverged`. Without ``x0`` the first step of each increment takes the tangent at the previous load
        (from rest: the unloaded tangent), the derivative of the equilibrium path. With the tangent at the
        new load the tendon's follower stiffness is in, but not the compression it builds, and the soft
        finger's first step went half-way (8 Newton iterations per increment against 5, measured).
        """
        x = self.mesh.vertices.copy() if x0 is None else np.array(x0, dtype=float)
        self.solve_stats = {"newton_iterations": 0, "factorisations": 0, "gmres_iterations": 0, "cutbacks": 0}
        lu = None
        done = 0.0 if x0 is None else None  # load scale converged at x (None: x0's, unknown)
        reached, inc = 0.0, 1.0 / steps
        while reached < 1.0:
            scale = min(1.0, reached + inc)
            try:
                x, lu = self._newton(load, scale, done, x, lu, max_iter=_NEWTON_MAX_ITER)
            except SimulationDiverged:
                # Cut the increment back and retry from the last converged state.
                if inc / 2 < 1.0 / (steps * _MAX_CUTBACK_FACTOR):
                    raise
                inc /= 2
                self.solve_stats["cutbacks"] += 1
                continue
            reached = done = scale
        return x

    def _residual(self, load, scale, x, free):
        f_ext, J = load(x)
        r = (self.internal_forces(x) + scale * f_ext).ravel()[free]
        return r, f_ext, J

    def _newton(self, load, scale, done, x, lu, *, max_iter: int = _NEWTON_MAX_ITER):
        """Newton at load ``scale`` from ``x``, converged at load ``done`` (None: unknown).

        Returns the new positions (``x`` itself is left as it was) and the last factorisation.
        """
        free = self.free_dof
        stats = self.solve_stats
        r, f_ext, J = self._residual(load, scale, x, free)
        ref = max(np.linalg.norm(scale * f_ext.ravel()[free]), 1e-12)
        for it in range(max_iter):
            A = self._free_tangent(x, J, done if it == 0 and done is not None else scale)
            dx = None if lu is None else self._krylov_step(A, r, lu)
            if dx is None:
                lu = self.factorise(A)
                stats["factorisations"] += 1
                dx = lu.solve(r)
            stats["newton_iterations"] += 1
            if not np.isfinite(dx).all():
                break
            # A trust region on the step, not a residual line search: bending loads are tiny against
            # the axial stiffness, so a good step can raise the residual a thousandfold.
            radius = _MAX_PREDICTOR_REL * self.design.length if it == 0 and done is not None else _MAX_STEP
            step = min(1.0, radius / max(np.abs(dx).max(), 1e-300))
            xt = x.copy().ravel()
            xt[free] += step * dx
            x = xt.reshape(-1, 3)
            r, f_ext, J = self._residual(load, scale, x, free)
            if step == 1.0 and (
                np.linalg.norm(r) <= _NEWTON_RTOL * ref or np.abs(dx).max() <= _STEP_TOL * self.design.length
            ):
                return x, lu
        raise SimulationDiverged(
            f"FEM Newton did not converge: residual {np.linalg.norm(r) / ref:.2e} of the load after "
            f"{max_iter} iterations"
        )

    @staticmethod
    def factorise(A: sp.csc_matrix):
        """SuperLU factorisation of a free-DOF tangent ``A`` (symmetric pattern; ``_SPLU``)."""
        return spla.splu(A, **_SPLU)

    def _krylov_step(self, A: sp.csc_matrix, r: np.ndarray, lu) -> np.ndarray | None:
        """The step dx of A dx = r (free DOFs), or None if GMRES stalls.

        GMRES is preconditioned with the factorisation ``lu`` of a nearby tangent and gives up short of
        ``_GMRES_RTOL`` after ``_GMRES_ITER`` iterations. Right preconditioning, so GMRES bounds the true
        residual ‖r − A dx‖, started from the step of ``lu`` alone.
        """
        n = len(r)
        op = spla.LinearOperator((n, n), matvec=lambda v: A @ lu.solve(v), dtype=float)
        count = [0]

        def tick(rel_residual):
            # Give up once the mean rate so far cannot reach the tolerance within the budget.
            count[0] += 1
            k = count[0]
            if k >= _GMRES_PROBE and rel_residual ** (_GMRES_ITER / k) > _GMRES_RTOL:
                raise _KrylovStalled

        try:
            y, info = spla.gmres(
                op, r, x0=r.copy(), rtol=_GMRES_RTOL, atol=0.0, restart=_GMRES_ITER, maxiter=1,
                callback=tick, callback_type="pr_norm",
            )  # fmt: skip
        except _KrylovStalled:
            info = 1
        self.solve_stats["gmres_iterations"] += count[0]
        return lu.solve(y) if info == 0 else None

    def static_gradient(self, x: np.ndarray, load: Callable, dmetric_dx: np.ndarray) -> np.ndarray:
        """d(metric)/d(ln E), shape (22,), at the equilibrium ``x`` (n, 3) under the full ``load``.

        Adjoint of r(x, θ) = f_int + f_ext = 0: K^T λ = ∂m/∂x on the free DOFs with K = −∂r/∂x, then
        dm/dθ = λ·∂f_int/∂θ, taken through ``wp.Tape`` over the material and force kernels.
        """
        wp = self.wp
        free = self.free_dof
        K = self.tangent(x)
        _, J = load(x)
        if J is not None:
            K = K - J
        K = K.tocsr()[free][:, free]
        lam = np.zeros(3 * self.mesh.n_vertices)
        lam[free] = spla.spsolve(K.T.tocsc(), np.asarray(dmetric_dx, dtype=float).ravel()[free])
        dev = self.options.device
        xw = wp.array(x, dtype=wp.vec3d, device=dev)
        f = wp.zeros(self.mesh.n_vertices, dtype=wp.vec3d, device=dev, requires_grad=True)
        self.log_e.grad.zero_()
        tape = wp.Tape()
        with tape:
            self.update_material()
            self.launch_forces(xw, f)
        tape.backward(grads={f: wp.array(lam.reshape(-1, 3), dtype=wp.vec3d, device=dev)})
        g = self.log_e.grad.numpy().copy()
        tape.zero()
        return g


class _KrylovStalled(Exception):
    """GMRES cannot converge in its budget (raised from its callback to stop it)."""
