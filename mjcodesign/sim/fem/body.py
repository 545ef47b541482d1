"""The Warp FEM finger as an elastic body: mesh, per-block material, forces, tangent stiffness, loads.

`FemBody` meshes one finger (`mjcodesign.sim.fem.mesh`; linear or quadratic tets, one Young's modulus
per block, stable Neo-Hookean), clamps its base face and evaluates what both solvers need through the
Warp kernels of `mjcodesign.sim.fem.kernels`: elastic forces and energy, the tangent stiffness
(finite differences of the analytic forces per tet, float64), the tendon load with its Jacobian, a
tip-face load, section angles and the explicit step's stability limit. The statics
(`mjcodesign.sim.fem.statics`) and the scenarios and dynamics (`mjcodesign.sim.fem.finger`) build on it.

Warp is imported lazily: importing this module does not import it, building a `FemBody` does.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from mjcodesign.design.finger import FingerDesign, Routing
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.design.tendon_law import tendon_forces
from mjcodesign.errors import DesignError
from mjcodesign.optional import import_warp
from mjcodesign.sim.fem.mesh import FingerMesh, embed_points, mesh_finger, to_quadratic
from mjcodesign.sim.fem.options import FemOptions

__all__ = ["FemBody"]

_FD_EPS_REL = 1e-6
"""Step of the finite-difference tangent, as a fraction of the cell size (float64: ~1e-9 rel error)."""
_JAC_EPS = 1e-8
"""Step [m] of the finite-difference Jacobian of the tendon forces w.r.t. the waypoint positions."""


class FemBody:
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
        self.update_material()
        n = m.n_vertices
        free = np.ones(n, dtype=bool)
        free[m.base] = False
        self.free_dof = np.repeat(free, 3)
        self.mass = np.zeros(n)
        tet_mass = self._vol * design.density
        if o.order == 1:
            np.add.at(self.mass, m.tets[:, :4].ravel(), np.repeat(tet_mass / 4.0, 4))
        else:  # HRZ lumping of the 10-node tet: the consistent diagonal (6/420 corners, 32/420 midsides), scaled to m
            share = np.r_[np.full(4, 6.0), np.full(6, 32.0)] / 216.0
            np.add.at(self.mass, m.tets.ravel(), (tet_mass[:, None] * share[None]).ravel())
        nd = 3 * m.tets.shape[1]
        dofs = (3 * m.tets[:, :, None] + np.arange(3)).reshape(n_t, nd)
        self._rows = np.repeat(dofs, nd, axis=1).ravel()
        self._cols = np.tile(dofs, (1, nd)).ravel()
        self._wk = sp.kron(sp.csr_matrix(m.waypoint_weights), sp.eye(3), format="csr")
        self._normal_rows = self._section_normal_rows()
        # The tendon's anchor [m] (3,) on the clamped base face, the weights of its further points
        # (k, n_vertices) (`tendon_path`) and the block each of those points lies in (k,).
        if o.routing == "printed":
            self.anchor, self.path_weights, self.path_blocks = self._channel_path()
        else:
            self.anchor, self.path_weights = design.tendon_exit(), m.waypoint_weights
            self.path_blocks = np.arange(design.n_blocks)
        self._free_pattern = None  # built by the first static solve (`_free_tangent`)

    def _k(self, name: str):
        """The kernel ``name`` for this tet order (``p2_`` prefix for quadratic tets)."""
        return getattr(_kernels(), name if self.options.order == 1 else f"p2_{name}")

    @property
    def _dim(self):
        """Launch shape of the force and energy kernels: per tet, or per tet and quadrature point."""
        return self.mesh.n_tets if self.options.order == 1 else (self.mesh.n_tets, 4)

    # -- material and forces -----------------------------------------------------------------------
    def update_material(self) -> None:
        """Per-tet Lamé parameters ``mu``, ``lam`` from ``log_e`` (a Warp launch; taped by the gradients)."""
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
        self.update_material()

    def launch_forces(self, x, f) -> None:
        """Accumulate the elastic forces [N] at Warp positions ``x`` into the Warp array ``f``."""
        self.wp.launch(
            self._k("elastic_forces"),
            dim=self._dim,
            inputs=[x, self.tets, self.dm_inv, self.vol, self.mu, self.lam],
            outputs=[f],
            device=self.options.device,
        )

    def launch_damping(self, v, f, beta: float) -> None:
        """Accumulate stiffness-proportional damping −β K₀ v [N] at Warp velocities ``v`` into ``f``.

        ``beta`` [s] is the Rayleigh β; K₀ the small-strain stiffness (linear tets only).
        """
        wp = self.wp
        wp.launch(
            _kernels().damping_forces,
            dim=self.mesh.n_tets,
            inputs=[v, self.tets, self.dm_inv, self.vol, self.mu, self.lam, wp.float64(beta)],
            outputs=[f],
            device=self.options.device,
        )

    def internal_forces(self, x: np.ndarray) -> np.ndarray:
        """Elastic vertex forces [N] at positions ``x`` (n, 3)."""
        wp = self.wp
        xw = wp.array(x, dtype=wp.vec3d, device=self.options.device)
        f = wp.full(self.mesh.n_vertices, wp.vec3d(np.nan, np.nan, np.nan), dtype=wp.vec3d, device=xw.device)
        f.zero_()
        self.launch_forces(xw, f)
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
    def section_pairs(self) -> np.ndarray:
        """Each block's spine section at its middle (y = 0): (top vertex, bottom vertex), (n_blocks, 2)."""
        v = self.mesh.vertices
        t = self.design.flexure_thickness
        out = []
        for b in self.design.blocks():
            on = (np.abs(v[:, 0] - b.mid) < 1e-9) & (np.abs(v[:, 1]) < 1e-9)
            top = np.flatnonzero(on & (np.abs(v[:, 2] - t) < 1e-9))
            bot = np.flatnonzero(on & (np.abs(v[:, 2]) < 1e-9))
            if len(top) != 1 or len(bot) != 1:
                raise DesignError(f"mesh has no spine section at the middle of block {b.index}")
            out.append((top[0], bot[0]))
        return np.array(out, dtype=np.int32)

    def _section_normal_rows(self) -> sp.csr_matrix:
        """Rows giving each block's section axis (top − bottom of the spine at y = 0, x = block mid)."""
        pairs = self.section_pairs()
        rows = np.zeros((len(pairs), self.mesh.n_vertices))
        rows[np.arange(len(pairs)), pairs[:, 0]] = 1.0
        rows[np.arange(len(pairs)), pairs[:, 1]] = -1.0
        return sp.kron(sp.csr_matrix(rows), sp.eye(3), format="csr")

    def _channel_path(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The printed routing: its anchor [m] (3,), the weights of its other channel points (17, n) and their blocks (17,).

        The anchor is the base segment's channel entry, on the clamped base face (its weights touch
        base vertices only, so it moves with the base alone); the rows are the 17 further entry, middle
        and exit points of `mjcodesign.models.channels.channel_points` embedded in the rest mesh, each in
        its segment's tet.
        """
        from mjcodesign.models.channels import channel_points

        if self.design.routing is not Routing.UNIFORM_PRESSURE:
            raise DesignError(
                f"the printed routing runs through the printed finger's channels; a "
                f"{self.design.routing.value} design has none"
            )
        points = channel_points(self.design).reshape(-1, 3)
        W, tet = embed_points(self.mesh, points)
        on_base = np.zeros(self.mesh.n_vertices, dtype=bool)
        on_base[self.mesh.base] = True
        if np.any(np.abs(W[0, ~on_base]) > 1e-12):
            raise DesignError("the printed tendon's first channel entry is not on the clamped base face")
        return points[0], W[1:], self.mesh.tet_block[tet[1:]]

    def tendon_path(self, x: np.ndarray) -> np.ndarray:
        """The tendon's polyline [m] at positions ``x`` (n, 3): the anchor, then its points, (k + 1, 3).

        Guided routing: the exit point at the base face and one waypoint per block; printed: the base
        segment's channel entry and the 17 further channel points (`FemOptions.routing`).
        """
        return np.vstack([self.anchor[None], self.path_weights @ x])

    def tendon_length(self, x: np.ndarray) -> float:
        """Length [m] of the tendon's polyline (`tendon_path`) at positions ``x`` (n, 3)."""
        return float(np.linalg.norm(np.diff(self.tendon_path(x), axis=0), axis=1).sum())

    def tendon_load(self, tension: float, variant: str = "frictionless") -> Callable:
        """A configuration-dependent load ``x -> (f (n, 3), J = ∂f/∂x (3n, 3n))`` of the tendon [N].

        The law of `mjcodesign.design.tendon_law.tendon_forces` at the routing's points
        (`FemOptions.routing`), spread to the vertices by their weights; ∂f/∂x by central differences
        over the points. The frictionless law is f = −T ∂ℓ/∂x, ℓ the `tendon_length`; the printed
        routing runs it only (`DesignError` for ``paper``, which needs one section axis per block).
        """
        Wk, S, forces = self._point_law(tension, variant)

        def load(x: np.ndarray):
            q = S @ x.ravel()
            f = (Wk.T @ forces(q)).reshape(-1, 3)
            J = Wk.T @ sp.csr_matrix(self._point_jacobian(forces, q)) @ S
            return f, J

        return load

    def _point_law(self, tension: float, variant: str) -> tuple[sp.csr_matrix, sp.csr_matrix, Callable]:
        """The tendon law over its points: (Wk, S, F).

        Wk (3k, 3n) gives the k tendon points' coordinates from the vertex coordinates; S (m, 3n) the
        law's inputs q, Wk then (guided routing) each block's section axis rows; F(q) the point forces
        [N], shape (3k,).
        """
        printed = self.options.routing == "printed"
        if printed and variant != "frictionless":
            raise DesignError("the printed routing runs the frictionless tendon law only")
        Wk = sp.kron(sp.csr_matrix(self.path_weights), sp.eye(3), format="csr") if printed else self._wk
        S = Wk if printed else sp.vstack([Wk, self._normal_rows], format="csr")
        k = Wk.shape[0] // 3

        def forces(q: np.ndarray) -> np.ndarray:
            q = q.reshape(-1, 3)
            return tendon_forces(q[:k], q if printed else q[k:], self.anchor, tension, variant).ravel()

        return Wk, S, forces

    @staticmethod
    def _point_jacobian(forces: Callable, q: np.ndarray) -> np.ndarray:
        """∂F/∂q of the point law ``forces`` at ``q`` (m,) by central differences, shape (3k, m)."""
        F = forces(q)
        dF = np.empty((len(F), len(q)))
        for j in range(len(q)):
            dq = np.zeros_like(q)
            dq[j] = _JAC_EPS
            dF[:, j] = (forces(q + dq) - forces(q - dq)) / (2 * _JAC_EPS)
        return dF

    def tip_face_load(self, force: np.ndarray) -> Callable:
        """A dead load ``force`` [N] (3,) spread over the tip face by area."""
        f = np.zeros((self.mesh.n_vertices, 3))
        f[self.mesh.tip_face] = self.mesh.tip_face_weight[:, None] * np.asarray(force, dtype=float)[None]
        return lambda x: (f, None)

    # -- geometry and stability -------------------------------------------------------------------
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

    def stable_mass(self, dt: float, extra: np.ndarray | None = None) -> np.ndarray:
        """Vertex masses [kg] that keep an explicit step ``dt`` [s] stable: m_v ≥ k_v dt² / 4.

        k_v is the largest of the vertex's three row sums Σ_j |K_ij| of the rest stiffness, plus
        ``extra`` [N/m] (n_vertices,), a bound on other springs at the vertex (contact): a Gershgorin
        bound on the largest eigenvalue of M⁻¹K, so ω_max dt ≤ 2 (selective mass scaling).
        """
        K = self.tangent(self.mesh.vertices)
        k_v = np.asarray(abs(K).sum(axis=1)).ravel().reshape(-1, 3).max(axis=1)
        if extra is not None:
            k_v = k_v + extra
        return np.maximum(self.mass, k_v * dt**2 / 4.0)

    def waypoint_table(self) -> tuple[np.ndarray, np.ndarray]:
        """The waypoint rows as padded tables: vertex indices (int32) and weights, (n_blocks, k).

        The single finger's explicit tendon (the contact rollouts) takes these; it runs the guided
        waypoints only, so `DesignError` with ``FemOptions(routing="printed")`` (the two-finger grasp
        takes either routing's `path_table`).
        """
        if self.options.routing != "guided":
            raise DesignError(
                "the single finger's explicit tendon (contact rollouts) runs the guided waypoints; "
                "its printed routing is statics only (the two-finger grasp runs it)"
            )
        return self.path_table()

    def path_table(self) -> tuple[np.ndarray, np.ndarray]:
        """The tendon's points after its anchor as padded tables: vertex indices (int32) and weights, (k, m).

        The rows of `tendon_path` after the anchor: the guided waypoints or the printed channel points
        (`FemOptions.routing`); unused slots hold vertex 0 with weight 0.
        """
        W = self.path_weights
        k = max(int(np.count_nonzero(r)) for r in W)
        idx = np.zeros((len(W), k), dtype=np.int32)
        w = np.zeros((len(W), k))
        for b, row in enumerate(W):
            nz = np.flatnonzero(row)
            idx[b, : len(nz)], w[b, : len(nz)] = nz, row[nz]
        return idx, w

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


def _kernels():
    from mjcodesign.sim.fem import kernels

    return kernels
