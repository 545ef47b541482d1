"""Stability of the FEM finger under its tendon: the buckling tension at rest and along the loaded path.

The static residual at tension T is r(x, T) = f_int(x) + T f_t(x), with f_t = −∂ℓ/∂x the frictionless
tendon's load per unit tension (ℓ its length, `FemBody.tendon_length`). Its tangent is

    A(x, T) = K(x) − T G(x),   K = −∂f_int/∂x (elastic),   G = ∂f_t/∂x = −∂²ℓ/∂x²,

and the finger is unstable where A turns singular. `FemStability.buckling_tension` reads that off the
unloaded finger in two ways:

* **Follower only** (the tendon's own stiffness at the rest shape, no prestress): K₀ v = T G₀ v. G₀ acts
  through the k tendon points alone, G₀ = Wᵀ G_q W (W the points' weights, (3k, 3n); G_q the law's
  Jacobian over the points, (3k, 3k)), so with p = W v the problem is p = T W K₀⁻¹ Wᵀ G_q p = T C G_q p:
  T_crit = 1/λ_max(G_q C), C = W K₀⁻¹ Wᵀ the compliance at the points (3k solves of one factorisation).
  The length of a polyline is convex in its points, so G_q is negative semidefinite and C positive
  definite: λ(G_q C) = λ(C^½ G_q C^½) ≤ 0 and this tension is infinite. A frictionless tendon pulled
  across a fixed, unstressed mesh only stiffens it; the chain's buckling (a string across a hinge,
  ∂²ℓ/∂θ² = −ab/(a+b)) comes from the hinge's rotation, which the continuum carries as the stress the
  tendon's compression leaves in the spine.
* **Linearised** (classical linear buckling, prestress in): along the linear path x = X + T u₁,
  K₀ u₁ = f_t(X), the tangent is A ≈ K₀ + T (K_σ[u₁] − G₀), K_σ the initial-stress stiffness of the
  unit tension's small-strain stress (`FemStability.stress_stiffness`). It is singular at T with
  −(K_σ − G₀) v = (1/T) K₀ v: T_crit = 1/μ_max of that symmetric pencil (Lanczos on K₀⁻¹(G₀ − K_σ),
  K₀ factorised once). The initial-displacement part of dK/dx[u₁] is left out: the printed tendon curls
  the finger at first order, and the first-order Taylor term of those rotations is no rotation; with it
  (central differences of K along u₁) the pencil turned singular at 0.46 mN on the converged mesh
  (ln E 15), a thousandth of the compression's own buckling, with the curl's shape as its mode.

Where the linearised mode lives is read from its elastic energy ½ vᵀK₀v, tet by tet: its share in each
block, within `_NEAR` of a cut's foot (the edge across the width where a segment's trapezoid cut meets
the spine's top, a re-entrant corner whose stress is singular) and in the tets around the vertices the
tendon's points load (where a point force's singular stress would sit).
**Global modes**: the same pencil restricted (Rayleigh–Ritz) to the static responses K₀⁻¹ f to each
segment's rigid in-plane loads f (the inertial loads of a unit acceleration along x, along z and about y
through its centre of mass): the finger's flexures and segments bending as wholes, without the local
wrinkles a sharp corner's singular prestress admits on a fine mesh. Its tension bounds the linearised
one from above (a subspace's largest μ is at most the whole pencil's).

`FemStability.path_stability` follows the loaded path instead: static equilibria at increasing T and the
smallest eigenvalue λ of A(x(T), T) v = λ K₀ v there (1 at rest; it falls fast as the finger curls,
since a turned block's axial stiffness no longer lies along K₀'s, but it reaches zero only where A is
singular); the path is unstable past its first zero. The printed spans are sloped, so the finger curls from the
first newton; the curl moves the compression off the spine's axis.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mjcodesign.design.finger import BlockKind
from mjcodesign.errors import DesignError, SimulationDiverged
from mjcodesign.sim.fem.mesh import P2_EDGES
from mjcodesign.sim.fem.results import FemBuckling, FemPathStability
from mjcodesign.sim.fem.statics import FemStatics

__all__ = ["FemStability"]

_QA, _QB = 0.5854101966249685, 0.1381966011250105
"""The 10-node kernels' 4-point rule of degree 2: barycentric (a, b, b, b) and permutations, weights 1/4."""
_EIG_TOL = 1e-8
"""Relative accuracy of the Lanczos eigenvalues (ARPACK ``tol``)."""
_N_MODES = 3
"""Eigenpairs Lanczos converges at once; more than one keeps the largest from being missed."""
_MODE_STEP = 1e-6
"""Displacement [m] (largest vertex) at which a mode's section rotations are read, linear to 1e-6."""
_NEAR = 0.5e-3
"""Radius [m] within which a tet (its centroid) counts as at a cut's foot: a quarter of the 2 mm spine,
below the printed channel's 0.6 mm radius; a flexure bending as a whole (8 mm long) keeps most of its
energy farther out."""
_NO_BUCKLING = 1e-9
"""[1/N]: an eigenvalue below this is a critical tension past 1 GN, i.e. none (the follower eigenvalue's
round-off is ~1e-12)."""


class FemStability(FemStatics):
    """A `FemStatics` with the buckling tension of its tendon (frictionless law)."""

    def buckling_tension(self) -> FemBuckling:
        """The unloaded finger's critical tensions [N], follower only, linearised and over the global modes.

        With where the linearised and the global mode keep their elastic energy (module docstring).
        """
        X = self.mesh.vertices
        free = self.free_dof
        K0 = self._free_tangent(X, None, 0.0)
        lu = self.factorise(K0)
        Wk, S, forces = self._point_law(1.0, "frictionless")
        f1, J1 = self.tendon_load(1.0)(X)
        # Follower only: λ_max(G_q C), C = W K₀⁻¹ Wᵀ on the free DOFs.
        G_q = self._point_jacobian(forces, S @ X.ravel())[:, : Wk.shape[0]]
        Wf = Wk.tocsc()[:, free]
        C = Wf @ lu.solve(Wf.T.toarray())
        lam = float(np.max(np.linalg.eigvals(G_q @ C).real))
        follower = 1.0 / lam if lam > _NO_BUCKLING else float("inf")
        # Linearised: −(K_σ[u₁] − G₀) v = μ K₀ v, μ_max = 1/T_crit.
        u1 = np.zeros(3 * self.mesh.n_vertices)
        u1[free] = lu.solve(f1.ravel()[free])
        B = self.stress_stiffness(u1.reshape(-1, 3)).tocsr()[free][:, free] - J1.tocsr()[free][:, free]
        B = 0.5 * (B + B.T)
        n = K0.shape[0]
        mu, vecs = spla.eigsh(
            -B, k=_N_MODES, M=K0, Minv=spla.LinearOperator((n, n), matvec=lu.solve), which="LA", tol=_EIG_TOL
        )
        top = int(np.argmax(mu))
        linear = 1.0 / mu[top] if mu[top] > _NO_BUCKLING else float("inf")
        mode = self._mode_rotations(vecs[:, top])
        # Global modes: Rayleigh–Ritz on the responses to the segments' rigid loads.
        V = np.linalg.qr(lu.solve(self._segment_loads()[free]))[0]
        K_r, B_r = V.T @ (K0 @ V), V.T @ (-(B @ V))
        mu_r, a = sla.eigh(0.5 * (B_r + B_r.T), 0.5 * (K_r + K_r.T))
        glob = 1.0 / mu_r[-1] if mu_r[-1] > _NO_BUCKLING else float("inf")
        H = self._tet_hessians(X)
        shares = self._energy_shares(vecs[:, top], H)
        global_shares = self._energy_shares(V @ a[:, -1], H)
        feet, points = self._near_feet_and_tendon()
        blocks = self.design.n_blocks
        return FemBuckling(
            follower_eigenvalue_per_n=lam,
            follower_tension_n=float(follower),
            linearised_eigenvalue_per_n=float(mu[top]),
            linearised_tension_n=float(linear),
            mode_block_angles=tuple(float(a) for a in mode),
            mode_block=int(np.argmax(np.abs(mode))),
            mode_block_energy=tuple(np.bincount(self.mesh.tet_block, shares, minlength=blocks).tolist()),
            mode_energy_at_feet=float(shares[feet].sum()),
            mode_energy_at_tendon=float(shares[points].sum()),
            global_tension_n=float(glob),
            global_mode_block_energy=tuple(
                np.bincount(self.mesh.tet_block, global_shares, minlength=blocks).tolist()
            ),
            global_mode_energy_at_feet=float(global_shares[feet].sum()),
        )

    def _segment_loads(self) -> np.ndarray:
        """Each segment's rigid in-plane loads [N], shape (3n, 3·n_segments).

        m_a·e_x, m_a·e_z and m_a·ŷ × (X_a − c) on its vertices a (lumped masses m_a, c its centre of mass).
        """
        m = self.mesh
        loads = []
        for b in self.design.blocks():
            if b.kind is not BlockKind.SEGMENT:
                continue
            idx = np.unique(m.tets[m.tet_block == b.index])
            mass = self.mass[idx]
            r = m.vertices[idx] - mass @ m.vertices[idx] / mass.sum()
            for field in (np.eye(3)[0], np.eye(3)[2], np.c_[r[:, 2], np.zeros(len(r)), -r[:, 0]]):
                f = np.zeros((m.n_vertices, 3))
                f[idx] = mass[:, None] * field
                loads.append(f.ravel())
        return np.array(loads).T

    def _energy_shares(self, v_free: np.ndarray, hessians: np.ndarray) -> np.ndarray:
        """Each tet's share of the elastic energy ½ vᵀK₀v of the free-DOF vector ``v_free``, (n_tets,)."""
        v = np.zeros(3 * self.mesh.n_vertices)
        v[self.free_dof] = v_free
        ve = v.reshape(-1, 3)[self.mesh.tets].reshape(self.mesh.n_tets, -1)
        e = np.einsum("ti,tij,tj->t", ve, hessians, ve)
        return e / e.sum()

    def _near_feet_and_tendon(self) -> tuple[np.ndarray, np.ndarray]:
        """Two boolean masks over the tets, (n_tets,): at a cut's foot; around the tendon's loads.

        The first holds the tets whose centroid lies within `_NEAR` of a cut's foot, the second those that
        touch a vertex a tendon point loads (the support of ``path_weights``).
        """
        X = self.mesh.vertices
        centroid = X[self.mesh.tets[:, :4]].mean(axis=1)
        feet = np.array(
            [
                (x, b.spine)
                for b in self.design.blocks()
                if b.kind is BlockKind.SEGMENT
                for x, cut in ((b.x0, b.cut0), (b.x1, b.cut1))
                if cut > 0
            ]
        )
        to_foot = np.linalg.norm(centroid[:, None, [0, 2]] - feet[None], axis=2).min(axis=1)
        loaded = np.flatnonzero(np.abs(np.asarray(self.path_weights)).sum(axis=0) > 0)
        return to_foot < _NEAR, np.isin(self.mesh.tets, loaded).any(axis=1)

    def path_stability(self, tensions, *, on_point: Callable[[float, float, float], None] | None = None):
        """Equilibria at the increasing ``tensions`` [N] and the smallest eigenvalue of their tangent.

        Each equilibrium starts from the previous one (the first from rest, in 4 increments); λ is the
        eigenvalue nearest zero of A(x, T) v = λ K₀ v (shift-invert Lanczos), 1 at rest. The path stops
        at the first λ ≤ 0 or where Newton fails (`SimulationDiverged`: ``failed_tension_n``). Its
        critical tension is where λ first crosses zero, linear between the bracketing tensions, or
        ``inf`` when it stays positive. ``on_point(T, λ, bend)`` is called after each equilibrium.
        Returns a `FemPathStability`.
        """
        tensions = np.asarray(tensions, dtype=float)
        if tensions.ndim != 1 or len(tensions) == 0 or np.any(np.diff(tensions) <= 0) or tensions[0] <= 0:
            raise DesignError("path_stability needs increasing positive tensions")
        X = self.mesh.vertices
        K0 = self._free_tangent(X, None, 0.0)
        n = K0.shape[0]
        x, eig, bend, failed = None, [], [], None
        for T in tensions:
            load = self.tendon_load(float(T))
            try:
                x = self.solve_static(load, steps=4) if x is None else self.solve_static(load, x0=x)
            except SimulationDiverged:
                failed = float(T)
                break
            _, J = load(x)
            A = self._free_tangent(x, J, 1.0)
            lu = self.factorise(A)
            lam = spla.eigsh(
                A, k=1, M=K0, sigma=0.0, which="LM", OPinv=spla.LinearOperator((n, n), matvec=lu.solve),
                tol=_EIG_TOL,
            )[0]  # fmt: skip
            eig.append(float(lam[0]))
            bend.append(float(self.section_angles(x)[-1]))
            if on_point is not None:
                on_point(float(T), eig[-1], bend[-1])
            if eig[-1] <= 0.0:
                break
        crit = float("inf")
        if eig and eig[-1] <= 0.0:
            i = len(eig) - 1
            t0, e0 = (0.0, 1.0) if i == 0 else (tensions[i - 1], eig[i - 1])
            crit = float(t0 + (tensions[i] - t0) * e0 / (e0 - eig[i]))
        return FemPathStability(
            tensions_n=tuple(float(t) for t in tensions[: len(eig)]),
            eigenvalues=tuple(eig),
            bend_angles_rad=tuple(bend),
            critical_tension_n=crit,
            failed_tension_n=failed,
        )

    def stress_stiffness(self, u: np.ndarray) -> sp.csr_matrix:
        """Initial-stress stiffness K_σ [N/m] of the small-strain stress of displacement ``u`` (n, 3) [m].

        K_σ[a, b] = ∫ ∇N_a · σ ∇N_b dV · I₃ (3n, 3n), σ = λ tr ε I + 2μ ε, ε = sym ∇u, with the physical
        Lamé parameters the stable Neo-Hookean linearises to (μ = ¾ μ', λ = λ' − ⅚ μ); one quadrature
        point for 4-node tets, the kernels' 4-point rule for 10-node ones. Compression makes it negative.
        """
        m = self.mesh
        corners = m.vertices[m.tets[:, :4]]
        dm_inv = np.linalg.inv(np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1)))
        grad_l = np.concatenate([-dm_inv.sum(axis=1, keepdims=True), dm_inv], axis=1)  # (n_tets, 4, 3)
        mu = 0.75 * self.mu.numpy()
        lam = self.lam.numpy() - 5.0 / 6.0 * mu
        ue = np.asarray(u, dtype=float)[m.tets]  # (n_tets, nodes, 3)
        k = np.zeros(m.tets.shape + (m.tets.shape[1],))
        for bary, weight in _quadrature(m.tets.shape[1]):
            if m.tets.shape[1] == 4:
                grad_n = grad_l
            else:
                corner = (4.0 * bary - 1.0)[None, :, None] * grad_l
                edge = [4.0 * (bary[i] * grad_l[:, j] + bary[j] * grad_l[:, i]) for i, j in P2_EDGES]
                grad_n = np.concatenate([corner, np.stack(edge, axis=1)], axis=1)
            h = np.einsum("tai,taj->tij", ue, grad_n)
            eps = 0.5 * (h + np.transpose(h, (0, 2, 1)))
            tr = np.trace(eps, axis1=1, axis2=2)
            sigma = lam[:, None, None] * tr[:, None, None] * np.eye(3) + 2.0 * mu[:, None, None] * eps
            k += weight * self._vol[:, None, None] * np.einsum("tai,tij,tbj->tab", grad_n, sigma, grad_n)
        nd = 3 * m.tets.shape[1]
        blocks = np.einsum("tab,kl->takbl", k, np.eye(3)).reshape(-1, nd, nd)
        n = 3 * m.n_vertices
        return sp.csr_matrix((blocks.ravel(), (self._rows, self._cols)), shape=(n, n))

    def _mode_rotations(self, v_free: np.ndarray) -> np.ndarray:
        """Each block's section rotation relative to the previous one in mode ``v_free``, max |.| = 1."""
        v = np.zeros(3 * self.mesh.n_vertices)
        v[self.free_dof] = v_free
        v = (v * _MODE_STEP / np.abs(v).max()).reshape(-1, 3)
        phi = self.section_angles(self.mesh.vertices + v) - self.section_angles(self.mesh.vertices - v)
        rel = np.diff(np.r_[0.0, phi])
        return rel / rel[np.argmax(np.abs(rel))]


def _quadrature(nodes: int) -> list[tuple[np.ndarray, float]]:
    """(barycentric point (4,), weight as a fraction of the volume) of the rule for ``nodes``-node tets."""
    if nodes == 4:
        return [(np.full(4, 0.25), 1.0)]
    return [(np.where(np.arange(4) == q, _QA, _QB), 0.25) for q in range(4)]
