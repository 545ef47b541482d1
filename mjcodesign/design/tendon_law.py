"""The tendon's force law at its waypoints, shared by every finger model and the FEM.

A tendon of tension f_T [N] routed through waypoints P_0..P_{n-1} (from the exit point at the base to
the tip) pushes on each waypoint; :func:`tendon_forces` gives those point forces for the two laws the
project implements (``frictionless``, the exact statics of a frictionless tendon, and ``paper``, the
authors' simulator).
"""

from __future__ import annotations

import numpy as np

from mjcodesign.errors import DesignError

__all__ = ["TENDON_VARIANTS", "tendon_forces", "unit_vectors"]

TENDON_VARIANTS = ("frictionless", "paper")
"""The implemented tendon laws."""


def unit_vectors(v: np.ndarray) -> np.ndarray:
    """``v`` normalised along its last axis (zero vectors stay finite)."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-15)


def tendon_forces(
    points: np.ndarray, normals: np.ndarray, exit_point: np.ndarray, tension: float, variant: str
) -> np.ndarray:
    """Tendon point forces [N] at the waypoints ``points`` (n, 3), the same law as `mjcodesign.models.tendon`.

    ``frictionless``: F_i = f_T (u(P_{i−1} − P_i) + u(P_{i+1} − P_i)) with P_{−1} the exit point, and
    F_tip = f_T u(P_{n−2} − P_{n−1}). ``paper``: the first waypoint carries nothing, middle ones keep the
    part tangent to the surface (normal ``normals[i]`` removed), the tip takes f_T·n (inwards, i.e.
    −f_T times the spine's outward normal).

    `mjcodesign.sim.fem.FemFinger.tendon_load` takes ``normals`` as each block's deformed section axis (spine top minus
    bottom at the block's middle, y = 0), the FEM counterpart of the chain's block z axis. Where this
    differs from the authors' code: they take the normal of the mesh surface face at the waypoint, and
    their waypoints are particles of a coarse mesh; here segment waypoints are vertices and flexure
    waypoints are carried by the flexure's mid-section (`mjcodesign.sim.fem.mesh`). The ``frictionless``
    default is not the authors' model; it is the exact statics of a frictionless tendon.
    """
    if variant not in TENDON_VARIANTS:
        raise DesignError(f"unknown tendon variant {variant!r}; choose from {TENDON_VARIANTS}")
    prev = np.vstack([exit_point[None], points[:-1]])
    f = np.zeros_like(points)
    f[:-1] = tension * (unit_vectors(prev[:-1] - points[:-1]) + unit_vectors(points[1:] - points[:-1]))
    f[-1] = tension * unit_vectors(points[-2] - points[-1])
    if variant == "paper":
        n = unit_vectors(normals)
        f = f - np.sum(f * n, axis=1, keepdims=True) * n
        f[0] = 0.0
        f[-1] = tension * n[-1]
    return f
