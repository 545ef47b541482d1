"""The Warp FEM's small-deflection statics as an affine function of the block moduli, and its reduction.

At rest the FEM's tangent stiffness is linear elasticity, and each tet carries its block's modulus at
a fixed Poisson ratio, so over the free DOFs

    K(E) = Σ_b E_b K_b,    K_b = the tangent with E = 1 Pa in block b and 0 elsewhere

exactly (to the finite-difference tangent's ~1e-9). :class:`FemLinear` assembles the eleven ``K_b`` of
finger A once (``E = e^-40`` Pa elsewhere, 1e-17 of a block's own: below round-off), and solves any design
with one sparse factorisation for two loads: a unit tip load on the tip face (the cantilever) and the
frictionless tendon at unit tension on the rest shape (the first-order curl). Its outputs are linear
functionals of the displacement (:data:`OUTPUTS`).

:func:`reduce` projects the ``K_b`` onto the span of solved designs' displacements and their sensitivities
to each block's modulus (Galerkin): the reduced
model ``K_r(E) = Σ_b E_b Vᵀ K_b V`` is exact in the same affine form and solves a design in ~0.1 ms
(:class:`mjcodesign.design.calibration.CalibratedFem`). Its error is checked on designs that were not in
the basis (``mjcodesign bench calibration``).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["OUTPUTS", "LOADS", "REDUCE_RTOL", "FemLinear", "reduce"]

LOADS = ("tip", "tendon")
"""The two unit loads: 1 N along +z on the tip face (area weights), and the tendon at 1 N."""
OUTPUTS = (
    ("tip_face_z", "tip_x", "tip_y", "tip_z")
    + tuple(f"face{i}" for i in range(11))
    + tuple(f"mid{i}" for i in range(11))
)
"""Linear outputs of a load: the tip face's mean z displacement [m], the tip vertex's displacement [m],
the spine section's rotation [rad] at every block's distal face and at every block's middle (+ curls
inwards; the linearised `mjcodesign.sim.fem.FemFinger.section_angles`)."""
_SPLU = {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.1, "options": {"SymmetricMode": True}}
"""SuperLU settings of `mjcodesign.sim.fem.statics` (the pattern is symmetric)."""
_OFF = -40.0
"""ln E [ln Pa] of the other blocks while one block's K_b is assembled: 4e-18 Pa."""


class FemLinear:
    """The FEM finger A's linear statics, affine in its 11 block moduli; ``options`` mesh it."""

    def __init__(self, design, options):
        from mjcodesign.design.stiffness import Stiffness
        from mjcodesign.sim.fem import FemFinger

        t0 = time.perf_counter()
        self.design = design
        self.options = options
        nb = design.n_blocks
        fem = FemFinger(design, Stiffness([13.5] * nb, n_blocks=nb), options=options)
        x = fem.mesh.vertices
        free = fem.free_dof
        self.blocks: list[sp.csc_matrix] = []
        for b in range(nb):
            log_e = np.full(2 * nb, _OFF)
            log_e[b] = 0.0
            fem.set_log_e(log_e)
            k = fem.tangent(x).tocsr()[free][:, free]
            k.eliminate_zeros()
            self.blocks.append(k.tocsc())
        n = 3 * fem.mesh.n_vertices
        tip = np.zeros((fem.mesh.n_vertices, 3))
        tip[fem.mesh.tip_face, 2] = fem.mesh.tip_face_weight
        tendon, _ = fem.tendon_load(1.0)(x)
        self.loads = np.stack([tip.ravel()[free], tendon.ravel()[free]], axis=1)
        self.rows = self._rows(fem, x, n)[:, free]
        self.n_vertices = fem.mesh.n_vertices
        self.n_dof = int(free.sum())
        self.setup_s = time.perf_counter() - t0

    def _rows(self, fem, x: np.ndarray, n: int) -> np.ndarray:
        """The output functionals (:data:`OUTPUTS`) as rows over all DOFs."""
        t = self.design.flexure_thickness
        rows = []
        r = np.zeros(n)
        r[3 * fem.mesh.tip_face + 2] = fem.mesh.tip_face_weight
        rows.append(r)
        for k in range(3):
            r = np.zeros(n)
            r[3 * fem.mesh.tip + k] = 1.0
            rows.append(r)

        def section(xs: float) -> np.ndarray:
            on = (np.abs(x[:, 0] - xs) < 1e-9) & (np.abs(x[:, 1]) < 1e-9)
            top = np.flatnonzero(on & (np.abs(x[:, 2] - t) < 1e-9))[0]
            bot = np.flatnonzero(on & (np.abs(x[:, 2]) < 1e-9))[0]
            r = np.zeros(n)  # φ = atan2(−n_x, n_z) with n = x_top − x_bot, linearised: −(u_top − u_bot)_x / t
            r[3 * top], r[3 * bot] = -1.0 / t, 1.0 / t
            return r

        blocks = self.design.blocks()
        rows += [section(b.x1) for b in blocks]
        rows += [section(b.mid) for b in blocks]
        return np.array(rows)

    def stiffness(self, log_e: np.ndarray) -> sp.csc_matrix:
        """K(E) over the free DOFs [N/m] for finger A's 11 ln E."""
        e = np.exp(np.asarray(log_e, dtype=float))
        return sum(
            (float(v) * k for v, k in zip(e, self.blocks, strict=True)), sp.csc_matrix(self.blocks[0].shape)
        )

    def solve(self, log_e: np.ndarray, *, sensitivities: bool = False):
        """(displacements [m] of the two unit loads, shape (n_dof, 2); outputs, shape (2, len(OUTPUTS))).

        With ``sensitivities`` also ``K⁻¹ K_b u`` for every block b and load, shape (n_dof, 2 n_blocks):
        the directions ``∂u/∂E_b = −K⁻¹ K_b u`` (one back-substitution each on the same factorisation).
        """
        lu = spla.splu(self.stiffness(log_e).tocsc(), **_SPLU)
        u = lu.solve(self.loads)
        if not sensitivities:
            return u, (self.rows @ u).T
        return u, (self.rows @ u).T, np.concatenate([lu.solve(k @ u) for k in self.blocks], axis=1)


REDUCE_RTOL = 1e-6
"""Singular values of the (unit-norm) snapshots below this fraction of the largest are dropped. On the
2 mm, 4-layer mesh with 16 training designs and their sensitivities, 1e-6 kept 119 directions and
reproduced 8 unseen designs' tip deflection within 1e-4 and every block's rotation within 1%; 1e-5 (80
directions) gave 0.2% and 8%, displacements alone (32 directions) 4.7% and 62%."""


def reduce(fem: FemLinear, snapshots: np.ndarray, rtol: float = REDUCE_RTOL) -> dict[str, np.ndarray]:
    """The Galerkin reduced model on the span of ``snapshots`` (n_dof, k) [m], as arrays to save.

    ``blocks`` (11, r, r) = Vᵀ K_b V, ``loads`` (r, 2) = Vᵀ f, ``rows`` (n_out, r) = R V, with V an
    orthonormal basis (SVD, directions below ``rtol`` of the largest dropped). Snapshots are scaled to
    unit norm first, so every one counts alike.
    """
    s = snapshots / np.linalg.norm(snapshots, axis=0, keepdims=True)
    u, sv, _ = np.linalg.svd(s, full_matrices=False)
    v = u[:, sv > rtol * sv[0]]
    return {
        "blocks": np.stack([v.T @ (k @ v) for k in fem.blocks]),
        "loads": v.T @ fem.loads,
        "rows": fem.rows @ v,
    }
