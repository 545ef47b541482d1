"""Stability of a clamped chain finger under its tendon: tangent stiffness and buckling tension.

A tendon at tension T adds T ∂²ℓ/∂θ² to the hinges' stiffness. Drawn straight across a hinge from a
before it to b after it (along the string), ∂²ℓ/∂θ² = −ab/(a+b), so the printed routing
(:attr:`SimOptions.routing`) softens every flexure it spans and buckles it past T = k (a+b)/(ab), a and
b its guides' distances (:func:`~mjcodesign.models.channels.flexure_guides`); the guided routing's
fixed tendon has constant levers and no such term. Both are read here from MuJoCo's own forces, not from a formula;
:func:`string_buckling_tension` is the closed form for one flexure as one hinge or n hinges, and
:func:`beam_string_buckling_tension` its limit, the flexure as an Euler–Bernoulli beam.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjcodesign.errors import DesignError
from mjcodesign.models.types import Built, FingerModel, TendonMode

__all__ = [
    "tangent_stiffness",
    "equality_basis",
    "buckling_tension",
    "string_buckling_tension",
    "beam_string_buckling_tension",
]

_FD = 1e-6  # central-difference step of a hinge angle [rad]: forces are smooth, round-off ~1e-10 relative
_NO_BUCKLING = 1e-6  # [1/N]: an eigenvalue below it is a critical tension past 1 MN, i.e. none
_RANK = 1e-12  # singular values of the equalities' Jacobian below this share of the largest are zero


def _check(built: Built) -> None:
    m = built.model
    if (
        len(built.fingers) != 1
        or built.finger_model is not FingerModel.CHAIN
        or built.tendon_mode is not TendonMode.NATIVE
        or m.nq != m.nv
        or m.nv != len(built.fingers[0].joints)
    ):
        raise DesignError("stability needs one clamped chain finger with its native tendon (build_finger)")


def _forces(built: Built, d: mujoco.MjData, q: np.ndarray, tension: float) -> np.ndarray:
    """Hinge springs plus the tendon's generalised force [N m] at angles ``q``, at rest."""
    d.qpos[:] = q
    d.qvel[:] = 0.0
    d.ctrl[:] = tension / len(built.fingers[0].actuators)
    mujoco.mj_forward(built.model, d)
    return d.qfrc_passive + d.qfrc_actuator


def tangent_stiffness(built: Built, tension: float, q: np.ndarray | None = None) -> np.ndarray:
    """−∂(spring + tendon force)/∂θ [N m / rad] at angles ``q`` (default straight), shape (nv, nv).

    MuJoCo's forces differenced centrally, then symmetrised; gravity is MuJoCo's too (build without it
    for the tendon's part alone).
    """
    _check(built)
    m = built.model
    d = mujoco.MjData(m)
    q = np.zeros(m.nq) if q is None else np.asarray(q, dtype=float)
    K = np.zeros((m.nv, m.nv))
    for j in range(m.nv):
        step = np.zeros(m.nv)
        step[j] = _FD
        K[:, j] = -(_forces(built, d, q + step, tension) - _forces(built, d, q - step, tension)) / (2 * _FD)
    return 0.5 * (K + K.T)


def equality_basis(built: Built) -> np.ndarray:
    """Hinge-angle directions [rad] the model's joint equalities allow at the straight finger, shape (nv, r).

    Orthonormal columns spanning the null space of the equalities' Jacobian at θ = 0, each row
    e_{j1} − a₁ e_{j2} for MuJoCo's θ_{j1} = a₀ + a₁ θ_{j2} + … (``eq_data``'s polynomial); the identity
    without equalities. :class:`DesignError` for an equality of another kind.
    """
    m = built.model
    rows = []
    for e in range(m.neq):
        if m.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or m.eq_obj2id[e] < 0:
            raise DesignError("stability reads joint equalities between two hinges only")
        row = np.zeros(m.nv)
        row[m.jnt_dofadr[m.eq_obj1id[e]]] += 1.0
        row[m.jnt_dofadr[m.eq_obj2id[e]]] -= m.eq_data[e, 1]
        rows.append(row)
    if not rows:
        return np.eye(m.nv)
    _, sing, vt = np.linalg.svd(np.array(rows))
    return vt[int(np.sum(sing > _RANK * sing[0])) :].T


def buckling_tension(built: Built) -> tuple[float, np.ndarray]:
    """Smallest tension [N] at which the straight finger's tangent stiffness turns singular, and its mode.

    K(T) = K₀ + T H is linear in T (H from the difference at 1 N), restricted to the angles the model's
    joint equalities allow (:func:`equality_basis` N: Nᵀ K N, a rigid tie), so T_crit = 1/μ_max with μ the
    eigenvalues of −L⁻¹ Nᵀ H N L⁻ᵀ (Nᵀ K₀ N = L Lᵀ). The mode is the hinge angles, largest |entry| 1,
    shape (nv,). ``inf`` and zeros when no tension buckles it (a fixed tendon: H = 0).
    """
    K0 = tangent_stiffness(built, 0.0)
    H = tangent_stiffness(built, 1.0) - K0
    N = equality_basis(built)
    Li = np.linalg.inv(np.linalg.cholesky(N.T @ K0 @ N))
    mu, vecs = np.linalg.eigh(-Li @ (N.T @ H @ N) @ Li.T)
    if mu[-1] <= _NO_BUCKLING:
        return float("inf"), np.zeros(built.model.nv)
    mode = N @ (Li.T @ vecs[:, -1])
    return float(1.0 / mu[-1]), mode / mode[np.argmax(np.abs(mode))]


def string_buckling_tension(k: float, x0: float, x1: float, x_a: float, x_b: float, hinges: int) -> float:
    """Buckling tension [N] of one flexure as ``hinges`` equal hinges under a straight string.

    The flexure runs from ``x0`` to ``x1`` [m] with stiffness ``k`` [N·m/rad], the string from ``x_a``
    before it to ``x_b`` after it. The hinges sit at the middles of the flexure's n equal parts, each
    n·k stiff; with the chord along the finger, the string's length to second order in the hinge angles θ
    is ℓ₀ − z Σθ_i + ½ θᵀHθ with
        H_ij = −(x_b − max(x_i, x_j)) + (x_b − x_i)(x_b − x_j) / (x_b − x_a),
    and T_crit = 1 / λ_max(−H, n k I). n = 1 is the single hinge's k (a+b)/(ab); n → ∞ an Euler–Bernoulli
    flexure with EI = k (x1 − x0), approached as 1/n².
    """
    dx = (x1 - x0) / hinges
    x = x0 + dx * (np.arange(hinges) + 0.5)
    H = -(x_b - np.maximum.outer(x, x)) + np.outer(x_b - x, x_b - x) / (x_b - x_a)
    return float(hinges * k / np.max(np.linalg.eigvalsh(-H)))


def beam_string_buckling_tension(k: float, x0: float, x1: float, x_a: float, x_b: float) -> float:
    """Buckling tension [N] of one flexure as an Euler–Bernoulli beam under a straight string.

    The limit n → ∞ of :func:`string_buckling_tension`, same arguments (``x_a ≤ x0 < x1 ≤ x_b``), with
    EI = k l, l = x1 − x0. There −H is the Green's function of −d²/dx² on (x_a, x_b) with zero ends, so a
    buckling mode θ(x) on the flexure is u/μ with −u'' = θ: u is a sine of wavenumber ω = √(T/EI) on the
    flexure and straight from there to zero at both string ends. Matching u'/u at the flexure's ends,
        ω l = atan(1 / (ω a₀)) + atan(1 / (ω b₁)),   a₀ = x0 − x_a,  b₁ = x_b − x1,
    whose left side rises from 0 and right side falls from π: one root in (0, π/l), T_crit = EI ω².
    l → 0 gives the single hinge's k (a+b)/(ab). :class:`DesignError` where the flexure leaves the span.
    """
    from scipy.optimize import brentq  # lazily: importing this package stays numpy-only

    length, a0, b1 = x1 - x0, x0 - x_a, x_b - x1
    if not (length > 0 and a0 >= 0 and b1 >= 0):
        raise DesignError(
            f"the flexure [{x0:.6g}, {x1:.6g}] m must lie within the string's span [{x_a:.6g}, {x_b:.6g}] m"
        )

    def mismatch(w: float) -> float:
        return w * length - np.arctan2(1.0, w * a0) - np.arctan2(1.0, w * b1)

    omega = brentq(mismatch, 1e-12 / length, np.pi / length, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    return float(k * length * omega**2)
