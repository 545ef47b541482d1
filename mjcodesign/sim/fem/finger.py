"""Warp tet-FEM reference of one finger: stable Neo-Hookean, quasi-static Newton and explicit dynamics.

The finger is meshed by `mjcodesign.femmesh` (linear tets, one Young's modulus per block, ν = 0.45),
its base face clamped. Two solvers share the Warp kernels of `mjcodesign.fem_kernels`:

* `FemFinger.solve_static`: Newton on the free vertices with load stepping. The tangent is assembled from
  per-tet 12×12 blocks (central differences of the analytic forces in a Warp kernel, float64) plus the
  Jacobian of configuration-dependent (tendon) loads, and factorised by SuperLU (scipy). A factorisation
  is reused as the preconditioner of GMRES on the current tangent until GMRES stalls; only then is the
  tangent refactorised. The first step of every load
  increment follows the equilibrium path (tangent at the previous load). A trust region on the step
  (at most 5 mm per vertex; 10% of the finger length on the path) keeps large tendon curls on track.
* `FemFinger.simulate`: explicit semi-implicit Euler with substeps, gravity, Rayleigh damping and ground
  penalty contact with friction (`fem_kernels.integrate`), the clamped base driven along a path.

Gradients: `FemFinger.static_gradient` differentiates a scalar outcome of a static equilibrium with
respect to the 22 ln E by the adjoint of the equilibrium, K^T λ = ∂m/∂x, and ``λ·∂f/∂(ln E)`` through
``wp.Tape`` over the material and force kernels. Finger B's 11 entries are exactly zero.

Quadratic (10-node) tets, ``FemOptions(order=2)``, statics only, δ_FEM / δ_EB:

    spine layers  h (bulk)  nodes     soft (13.5)   paper-optimized
    2             4 mm      14,805    0.998          0.964
    2             3 mm      15,680    1.0005         0.966
    4             3 mm      27,170    1.0078         0.973

They are within 4% of EB from the coarsest mesh; the CLI and tests use them for the cantilever. Linear
tets (``order=1``, the dynamics element) converge slowly:

Convergence of linear tets against Euler–Bernoulli (`mjcodesign.beam.cantilever_tip_deflection`), tip load giving
δ = 1% of L, ny = 2, x cells in flexures and cuts as thick as a spine layer, measured with this module
(δ_FEM / δ_EB):

    spine layers  h (bulk)  vertices   soft (13.5)   paper-optimized
    4 (uniform x) 1 mm        6,249    0.713
    4             2 mm        5,136    0.749
    8             2 mm       12,378    0.896
    12            2 mm       24,063    0.938
    12            3 mm       22,500    0.933          0.904
    16            3 mm       34,338    0.946          0.917

    same, ν = 0.3:  4 layers 0.965, 8 layers 1.064 (2 mm), 12 layers 1.085 (3 mm)
    prismatic 136×20×4.1 mm bar (no cuts), h = layer thickness everywhere:
        ν = 0.3:  4 layers 0.781, 8 layers 0.881;  ν = 0.45: 4 layers 0.581, 8 layers 0.744

The error falls roughly like h^1 (not h^2) in this range: linear tets are too stiff in bending (shear
locking, see the prismatic bar) and at ν = 0.45 also lock volumetrically. At ν = 0.3 the finger passes
EB and is still rising at 1.085, so the converged 3D finger is likely softer than EB by more than 5%
(cut tapers and section steps that EB treats as fully effective); this is not settled here. The 5%
target is not reached by linear tets with meshes that solve in about a minute on this machine; the
quadratic tets above reach it.

Warp is imported lazily: ``import mjcodesign.fem`` does not import it, building a `FemFinger` does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mjcodesign.design.beam import cantilever_tip_deflection
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.design.tendon_law import tendon_forces
from mjcodesign.errors import DesignError, SimulationDiverged
from mjcodesign.optional import import_warp
from mjcodesign.sim.fem.mesh import FingerMesh, mesh_finger, to_quadratic

__all__ = ["FemOptions", "FemDynamics", "FemFinger"]

_POISSON = 0.45
"""Poisson's ratio of the paper's TPU model (shared/NOTES.md)."""
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
_FD_EPS_REL = 1e-6
"""Step of the finite-difference tangent, as a fraction of the cell size (float64: ~1e-9 rel error)."""
_JAC_EPS = 1e-8
"""Step [m] of the finite-difference Jacobian of the tendon forces w.r.t. the waypoint positions."""


@dataclass(frozen=True)
class FemOptions:
    """Mesh and material options of the FEM finger."""

    h: float = 1e-3
    """Cell size along x and z [m]."""
    spine_layers: int = 4
    """Layers through the 2 mm spine (even)."""
    h_flexure: float | None = None
    """Cell size along x in flexures and cuts [m]; default the spine layer thickness."""
    ny: int = 2
    """Cells across the width (even)."""
    poisson: float = _POISSON
    """Poisson's ratio."""
    device: str = "cpu"
    """Warp device."""
    order: int = 1
    """Tet order: 1 (4 nodes, statics and dynamics) or 2 (10 nodes, statics only; far less locking)."""
    waypoint_layers: bool = True
    """Spine layer boundaries through in-spine waypoints (`mjcodesign.femmesh.mesh_finger`); turn off for
    explicit dynamics, where their 30 µm layers cut the stable step tenfold."""

    def __post_init__(self) -> None:
        if self.order not in (1, 2):
            raise DesignError(f"tet order must be 1 or 2, got {self.order}")
        if not 0.0 <= self.poisson < 0.5:
            raise DesignError(f"Poisson's ratio must be in [0, 0.5), got {self.poisson}")


@dataclass(frozen=True)
class FemDynamics:
    """Explicit dynamics options; defaults are the paper's (shared/NOTES.md)."""

    dt: float = 2.5e-6
    """Substep [s] (4000 fps × 100 substeps in the paper)."""
    mass_damping: float = 0.5
    """Rayleigh α [1/s] (the paper's damping 0.5)."""
    stiffness_damping: float = 0.0
    """Rayleigh β [s]; explicit stability needs β well below dt·(h/c)⁻¹ scale, 0 by default."""
    contact_ke: float = 1e3 / 1e-4
    """Ground penalty stiffness [Pa/m]: the paper's ke = 1e3 N/m per vertex over a 1 cm² patch."""
    contact_kd: float = 10.0 / 1e-4
    """Ground penalty damping [Pa·s/m] (the paper's kd = 10 per vertex over 1 cm²)."""
    friction: float = 1.0
    """Coulomb coefficient (the paper's μ = 1)."""
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    """Gravity in the world frame [m/s²]."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise DesignError(f"dt must be positive, got {self.dt}")


class FemFinger:
    """One finger (``finger`` 0 = A, 1 = B of ``stiffness``) as a tet FEM model, base clamped at x = 0."""

    def __init__(
        self,
        design: FingerDesign,
        stiffness: Stiffness,
        *,
        finger: int = 0,
        options: FemOptions | None = None,
    ):
        self.design = design
        self.options = options or FemOptions()
        self.finger = int(finger)
        o = self.options
        mesh = mesh_finger(
            design,
            o.h,
            spine_layers=o.spine_layers,
            ny=o.ny,
            h_flexure=o.h_flexure,
            waypoint_layers=o.waypoint_layers,
        )
        self.mesh: FingerMesh = mesh if o.order == 1 else to_quadratic(mesh, design.length)
        wp = self.wp = import_warp()
        m = self.mesh
        dev = o.device
        x = m.vertices[m.tets[:, :4]]
        dm = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2)
        self._vol = np.abs(np.linalg.det(dm)) / 6.0
        self.x_rest = wp.array(m.vertices, dtype=wp.vec3d, device=dev)
        self.tets = wp.array(m.tets.astype(np.int32), dtype=wp.int32, device=dev)
        self.dm_inv = wp.array(np.linalg.inv(dm), dtype=wp.mat33d, device=dev)
        self.vol = wp.array(self._vol, dtype=wp.float64, device=dev)
        self.tet_block = wp.array(m.tet_block.astype(np.int32), dtype=wp.int32, device=dev)
        n_t = m.n_tets
        self.log_e = wp.array(stiffness.log_e.ravel(), dtype=wp.float64, device=dev, requires_grad=True)
        self.mu = wp.zeros(n_t, dtype=wp.float64, device=dev, requires_grad=True)
        self.lam = wp.zeros(n_t, dtype=wp.float64, device=dev, requires_grad=True)
        self._n_blocks = stiffness.n_blocks
        self._update_material()
        n = m.n_vertices
        free = np.ones(n, dtype=bool)
        free[m.base] = False
        self.free_dof = np.repeat(free, 3)
        self.mass = np.zeros(n)
        np.add.at(self.mass, m.tets[:, :4].ravel(), np.repeat(self._vol * design.density / 4.0, 4))
        nd = 3 * m.tets.shape[1]
        dofs = (3 * m.tets[:, :, None] + np.arange(3)).reshape(n_t, nd)
        self._rows = np.repeat(dofs, nd, axis=1).ravel()
        self._cols = np.tile(dofs, (1, nd)).ravel()
        self._wk = sp.kron(sp.csr_matrix(m.waypoint_weights), sp.eye(3), format="csr")
        self._normal_rows = self._section_normal_rows()
        self._free_pattern = None  # built by the first static solve (`_free_tangent`)

    def _k(self, name: str):
        """The kernel ``name`` for this tet order (``p2_`` prefix for quadratic tets)."""
        return getattr(_kernels(), name if self.options.order == 1 else f"p2_{name}")

    @property
    def _dim(self):
        """Launch shape of the force and energy kernels: per tet, or per tet and quadrature point."""
        return self.mesh.n_tets if self.options.order == 1 else (self.mesh.n_tets, 4)

    # -- material and forces -----------------------------------------------------------------------
    def _update_material(self) -> None:
        wp = self.wp
        wp.launch(
            _kernels().lame_parameters,
            dim=self.mesh.n_tets,
            inputs=[
                self.log_e,
                self.tet_block,
                self.finger * self._n_blocks,
                wp.float64(self.options.poisson),
            ],
            outputs=[self.mu, self.lam],
            device=self.options.device,
        )

    def set_log_e(self, log_e: np.ndarray) -> None:
        """Replace the 22 ln(E / Pa) (finger A base to tip, then finger B)."""
        self.log_e.assign(np.asarray(log_e, dtype=float).ravel())
        self._update_material()

    def _launch_forces(self, x, f) -> None:
        self.wp.launch(
            self._k("elastic_forces"),
            dim=self._dim,
            inputs=[x, self.tets, self.dm_inv, self.vol, self.mu, self.lam],
            outputs=[f],
            device=self.options.device,
        )

    def internal_forces(self, x: np.ndarray) -> np.ndarray:
        """Elastic vertex forces [N] at positions ``x`` (n, 3)."""
        wp = self.wp
        xw = wp.array(x, dtype=wp.vec3d, device=self.options.device)
        f = wp.full(self.mesh.n_vertices, wp.vec3d(np.nan, np.nan, np.nan), dtype=wp.vec3d, device=xw.device)
        f.zero_()
        self._launch_forces(xw, f)
        return f.numpy()

    def energy(self, x: np.ndarray) -> float:
        """Elastic energy [J] at positions ``x`` (n, 3)."""
        wp = self.wp
        xw = wp.array(x, dtype=wp.vec3d, device=self.options.device)
        e = wp.zeros(1, dtype=wp.float64, device=xw.device)
        wp.launch(
            self._k("elastic_energy"),
            dim=self._dim,
            inputs=[xw, self.tets, self.dm_inv, self.vol, self.mu, self.lam],
            outputs=[e],
            device=xw.device,
        )
        return float(e.numpy()[0])

    def tangent(self, x: np.ndarray) -> sp.csr_matrix:
        """Elastic tangent stiffness K = −∂f/∂x [N/m] at ``x``, shape (3n, 3n)."""
        n = 3 * self.mesh.n_vertices
        return sp.csr_matrix((self._tet_hessians(x).ravel(), (self._rows, self._cols)), shape=(n, n))

    def _tet_hessians(self, x: np.ndarray) -> np.ndarray:
        """Per-tet blocks of K [N/m], shape (n_tets, 3·nodes, 3·nodes), DOFs as in ``self._rows``."""
        wp = self.wp
        xw = wp.array(x, dtype=wp.vec3d, device=self.options.device)
        nd = 3 * self.mesh.tets.shape[1]
        k = wp.full((self.mesh.n_tets, nd, nd), np.nan, dtype=wp.float64, device=xw.device)
        wp.launch(
            self._k("elastic_hessian_fd"),
            dim=(self.mesh.n_tets, nd),
            inputs=[
                xw,
                self.tets,
                self.dm_inv,
                self.vol,
                self.mu,
                self.lam,
                wp.float64(_FD_EPS_REL * self.options.h),
            ],
            outputs=[k],
            device=xw.device,
        )
        return k.numpy()

    def _free_tangent(self, x: np.ndarray, J, scale: float) -> sp.csc_matrix:
        """K − scale·J on the free DOFs at ``x``, summed straight into its CSC pattern."""
        if self._free_pattern is None:
            free = self.free_dof
            keep = free[self._rows] & free[self._cols]
            index = np.cumsum(free) - 1
            nf = int(free.sum())
            flat = index[self._cols[keep]].astype(np.int64) * nf + index[self._rows[keep]]
            cells, where = np.unique(flat, return_inverse=True)
            indptr = np.searchsorted(cells // nf, np.arange(nf + 1))
            self._free_pattern = (keep, where, (cells % nf).astype(np.int32), indptr, nf)
        keep, where, indices, indptr, nf = self._free_pattern
        data = np.bincount(where, weights=self._tet_hessians(x).ravel()[keep], minlength=len(indices))
        K = sp.csc_matrix((data, indices, indptr), shape=(nf, nf))
        if J is not None and scale != 0.0:
            free = self.free_dof
            K = (K - scale * J.tocsr()[free][:, free]).tocsc()
        return K

    # -- loads ------------------------------------------------------------------------------------
    def _section_normal_rows(self) -> sp.csr_matrix:
        """Rows giving each block's section axis (top − bottom of the spine at y = 0, x = block mid)."""
        v = self.mesh.vertices
        t = self.design.flexure_thickness
        rows = []
        for b in self.design.blocks():
            on = (np.abs(v[:, 0] - b.mid) < 1e-9) & (np.abs(v[:, 1]) < 1e-9)
            top = np.flatnonzero(on & (np.abs(v[:, 2] - t) < 1e-9))
            bot = np.flatnonzero(on & (np.abs(v[:, 2]) < 1e-9))
            if len(top) != 1 or len(bot) != 1:
                raise DesignError(f"mesh has no spine section at the middle of block {b.index}")
            r = np.zeros(len(v))
            r[top[0]], r[bot[0]] = 1.0, -1.0
            rows.append(r)
        return sp.kron(sp.csr_matrix(np.array(rows)), sp.eye(3), format="csr")

    def tendon_load(self, tension: float, variant: str = "frictionless") -> Callable:
        """A configuration-dependent load ``x -> (f (n, 3), J = ∂f/∂x (3n, 3n))`` of the tendon [N]."""
        exit_point = self.design.tendon_exit()
        nb = self.design.n_blocks
        S = sp.vstack([self._wk, self._normal_rows], format="csr")

        def forces(q: np.ndarray) -> np.ndarray:
            q = q.reshape(2 * nb, 3)
            return tendon_forces(q[:nb], q[nb:], exit_point, tension, variant).ravel()

        def load(x: np.ndarray):
            q = S @ x.ravel()
            F = forces(q)
            dF = np.empty((len(F), len(q)))
            for j in range(len(q)):
                dq = np.zeros_like(q)
                dq[j] = _JAC_EPS
                dF[:, j] = (forces(q + dq) - forces(q - dq)) / (2 * _JAC_EPS)
            f = (self._wk.T @ F).reshape(-1, 3)
            J = self._wk.T @ sp.csr_matrix(dF) @ S
            return f, J

        return load

    def tip_face_load(self, force: np.ndarray) -> Callable:
        """A dead load ``force`` [N] (3,) spread over the tip face by area."""
        f = np.zeros((self.mesh.n_vertices, 3))
        f[self.mesh.tip_face] = self.mesh.tip_face_weight[:, None] * np.asarray(force, dtype=float)[None]
        return lambda x: (f, None)

    # -- statics ----------------------------------------------------------------------------------
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
                lu = spla.splu(A, **_SPLU)
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

    def cantilever(self, force: float | None = None) -> dict:
        """Tip load along +z on the tip face; mean tip-face deflection [m] against Euler–Bernoulli.

        ``positions`` are the deformed vertices [m] (n, 3).
        """
        young = np.exp(self.log_e.numpy().reshape(-1, self._n_blocks)[self.finger])
        if force is None:
            from mjcodesign.scenarios.static import AUTO_DEFLECTION

            force = AUTO_DEFLECTION * self.design.length / cantilever_tip_deflection(self.design, young, 1.0)
        x = self.solve_static(self.tip_face_load(np.array([0.0, 0.0, force])))
        u = x - self.mesh.vertices
        delta = float(self.mesh.tip_face_weight @ u[self.mesh.tip_face, 2])
        analytic = cantilever_tip_deflection(self.design, young, force)
        return {
            "force_n": float(force),
            "tip_deflection_m": delta,
            "analytic_m": float(analytic),
            "rel_error": abs(delta - analytic) / analytic,
            "n_vertices": self.mesh.n_vertices,
            "n_tets": self.mesh.n_tets,
            "positions": x,
        }

    def section_angles(self, x: np.ndarray) -> np.ndarray:
        """Rotation [rad] of the spine section at every block's distal face, (n_blocks,); + curls inwards."""
        v = self.mesh.vertices
        t = self.design.flexure_thickness
        out = []
        for b in self.design.blocks():
            on = (np.abs(v[:, 0] - b.x1) < 1e-9) & (np.abs(v[:, 1]) < 1e-9)
            top = np.flatnonzero(on & (np.abs(v[:, 2] - t) < 1e-9))[0]
            bot = np.flatnonzero(on & (np.abs(v[:, 2]) < 1e-9))[0]
            n = x[top] - x[bot]
            out.append(np.arctan2(-n[0], n[2]))
        return np.unwrap(np.array(out))

    def curl(self, tension: float, variant: str = "frictionless", *, steps: int | None = None) -> dict:
        """Free tendon curl to equilibrium at ``tension`` [N] (gravity off), like `validate.curl`."""
        if steps is None:
            steps = 4
        x = self.solve_static(self.tendon_load(tension, variant), steps=steps)
        phi = self.section_angles(x)
        return {
            "model": "fem",
            "tension_n": float(tension),
            "tip_displacement_m": [float(c) for c in x[self.mesh.tip] - self.mesh.vertices[self.mesh.tip]],
            "bend_angle_rad": float(phi[-1]),
            "block_angles_rad": [float(a) for a in np.diff(np.r_[0.0, phi])],
            "positions": x,
        }

    def stable_dt(self) -> float:
        """CFL estimate of the largest stable explicit step [s]: min over tets of altitude / P-wave speed."""
        x = self.mesh.vertices[self.mesh.tets]
        faces = [(1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)]
        area = np.max(
            [
                0.5 * np.linalg.norm(np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]), axis=1)
                for a, b, c in faces
            ],
            axis=0,
        )
        altitude = 3.0 * self._vol / area
        mu = 0.75 * self.mu.numpy()
        lam = self.lam.numpy() - 5.0 / 6.0 * mu
        speed = np.sqrt((lam + 2.0 * mu) / self.design.density)
        return float(np.min(altitude / speed))

    # -- dynamics ---------------------------------------------------------------------------------
    def rollout(
        self,
        duration: float,
        *,
        dynamics: FemDynamics | None = None,
        rotation: np.ndarray | None = None,
        position=(0.0, 0.0, 0.0),
        base_velocity=(0.0, 0.0, 0.0),
        frames: int = 10,
    ) -> np.ndarray:
        """Explicit dynamics from rest; the finger frame placed at ``rotation``/``position`` in the world.

        The base face moves at ``base_velocity`` [m/s] (lift); the ground is the plane z = 0. Returns the
        tip vertex's world position [m] at ``frames + 1`` evenly spaced times, shape (frames + 1, 3).
        """
        if self.options.order != 1:
            raise DesignError("explicit dynamics supports linear tets only (order=1)")
        wp = self.wp
        k = _kernels()
        dyn = dynamics or FemDynamics()
        dev = self.options.device
        R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
        x0 = self.mesh.vertices @ R.T + np.asarray(position, dtype=float)
        n = self.mesh.n_vertices
        pinned = np.zeros(n, dtype=np.int32)
        pinned[self.mesh.base] = 1
        area = np.cbrt(self.mass / self.design.density) ** 2  # lumped contact patch per vertex [m²]
        xa = wp.array(x0, dtype=wp.vec3d, device=dev)
        xb = wp.zeros_like(xa)
        va = wp.zeros_like(xa)
        vb = wp.zeros_like(xa)
        f = wp.zeros_like(xa)
        rest = wp.array(x0, dtype=wp.vec3d, device=dev)
        mass = wp.array(self.mass, dtype=wp.float64, device=dev)
        area_w = wp.array(area, dtype=wp.float64, device=dev)
        pin = wp.array(pinned, dtype=wp.int32, device=dev)
        n_steps = max(1, int(round(duration / dyn.dt)))
        per_frame = max(1, n_steps // frames)
        vel = np.asarray(base_velocity, dtype=float)
        out = [x0[self.mesh.tip].copy()]
        f64 = wp.float64
        for s in range(1, n_steps + 1):
            f.zero_()
            self._launch_forces(xa, f)
            if dyn.stiffness_damping > 0:
                wp.launch(
                    k.damping_forces,
                    dim=self.mesh.n_tets,
                    inputs=[
                        va,
                        self.tets,
                        self.dm_inv,
                        self.vol,
                        self.mu,
                        self.lam,
                        f64(dyn.stiffness_damping),
                    ],
                    outputs=[f],
                    device=dev,
                )
            off = vel * s * dyn.dt
            wp.launch(
                k.integrate,
                dim=n,
                inputs=[
                    xa,
                    va,
                    f,
                    mass,
                    area_w,
                    pin,
                    rest,
                    wp.vec3d(*off),
                    wp.vec3d(*dyn.gravity),
                    f64(dyn.mass_damping),
                    f64(dyn.contact_ke),
                    f64(dyn.contact_kd),
                    f64(dyn.friction),
                    f64(dyn.dt),
                ],
                outputs=[xb, vb],
                device=dev,
            )
            xa, xb = xb, xa
            va, vb = vb, va
            if s % per_frame == 0:
                tip = xa.numpy()[self.mesh.tip].copy()
                if not np.isfinite(tip).all():
                    raise SimulationDiverged(f"FEM dynamics diverged at t = {s * dyn.dt:.2e} s; lower dt")
                out.append(tip)
        return np.array(out)

    # -- gradients --------------------------------------------------------------------------------
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
            self._update_material()
            self._launch_forces(xw, f)
        tape.backward(grads={f: wp.array(lam.reshape(-1, 3), dtype=wp.vec3d, device=dev)})
        g = self.log_e.grad.numpy().copy()
        tape.zero()
        return g


class _KrylovStalled(Exception):
    """GMRES cannot converge in its budget (raised from its callback to stop it)."""


def _kernels():
    from mjcodesign.sim.fem import kernels as fem_kernels

    return fem_kernels
