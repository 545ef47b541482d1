"""Stability of a clamped chain finger under its tendon: tangent stiffness and buckling tension.

A tendon at tension T adds T ∂²ℓ/∂θ² to the hinges' stiffness. Drawn straight across a hinge from a
before it to b after it, ∂²ℓ/∂θ² = −ab/(a+b), so the printed routing (:attr:`SimOptions.routing`)
softens every flexure it spans and buckles it past T = k (a+b)/(ab); the guided routing's fixed tendon
has constant levers and no such term. Both are read here from MuJoCo's own forces, not from a formula.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjcodesign.errors import DesignError
from mjcodesign.models.types import Built, FingerModel, TendonMode

__all__ = ["tangent_stiffness", "buckling_tension"]

_FD = 1e-6  # central-difference step of a hinge angle [rad]: forces are smooth, round-off ~1e-10 relative
_NO_BUCKLING = 1e-6  # [1/N]: an eigenvalue below it is a critical tension past 1 MN, i.e. none


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


def buckling_tension(built: Built) -> tuple[float, np.ndarray]:
    """Smallest tension [N] at which the straight finger's tangent stiffness turns singular, and its mode.

    K(T) = K₀ + T H is linear in T (H from the difference at 1 N), so T_crit = 1/μ_max with μ the
    eigenvalues of −L⁻¹ H L⁻ᵀ (K₀ = L Lᵀ). The mode is the hinge angles, largest |entry| 1, shape (nv,).
    ``inf`` and zeros when no tension buckles it (a fixed tendon: H = 0).
    """
    K0 = tangent_stiffness(built, 0.0)
    H = tangent_stiffness(built, 1.0) - K0
    Li = np.linalg.inv(np.linalg.cholesky(K0))
    mu, vecs = np.linalg.eigh(-Li @ H @ Li.T)
    if mu[-1] <= _NO_BUCKLING:
        return float("inf"), np.zeros(built.model.nv)
    mode = Li.T @ vecs[:, -1]
    return float(1.0 / mu[-1]), mode / mode[np.argmax(np.abs(mode))]
