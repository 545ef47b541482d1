"""What the Warp FEM's scenarios return: frozen records with their units, one per scenario.

`FemCantilever` (:meth:`~mjcodesign.sim.fem.finger.FemFinger.cantilever`), `FemCurl`
(:meth:`~mjcodesign.sim.fem.finger.FemFinger.curl`), `FemPress` (:func:`~mjcodesign.sim.fem.press.press_fem`)
`FemContactRun` (:meth:`~mjcodesign.sim.fem.contact.FemContact.run`), `FemBuckling` and
`FemPathStability` (:mod:`mjcodesign.sim.fem.stability`). A JSON row builder can call
:func:`dataclasses.asdict` on them (arrays stay arrays).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FemCantilever", "FemCurl", "FemPress", "FemContactRun", "FemBuckling", "FemPathStability"]


@dataclass(frozen=True, eq=False)
class FemCantilever:
    """A tip load along +z spread over the tip face, against Euler–Bernoulli."""

    force_n: float
    """The tip load [N]."""
    tip_deflection_m: float
    """Mean tip-face deflection along z [m] (tip-face area weights)."""
    analytic_m: float
    """Euler–Bernoulli tip deflection of the same load [m] (`mjcodesign.design.beam`)."""
    rel_error: float
    """``|tip_deflection_m − analytic_m| / analytic_m``."""
    n_vertices: int
    """Mesh vertices (nodes, for quadratic tets)."""
    n_tets: int
    """Mesh tetrahedra."""
    positions: np.ndarray
    """Deformed vertices [m], shape (n_vertices, 3), finger frame."""


@dataclass(frozen=True, eq=False)
class FemCurl:
    """A free tendon curl at equilibrium (gravity off)."""

    tension_n: float
    """Tendon tension [N]."""
    tip_displacement_m: tuple[float, float, float]
    """Displacement of the tip vertex [m], finger frame."""
    bend_angle_rad: float
    """Rotation of the tip block's distal section [rad]; + curls inwards."""
    block_angles_rad: tuple[float, ...]
    """Rotation of each block's distal section relative to the previous block's [rad], (n_blocks,)."""
    positions: np.ndarray
    """Deformed vertices [m], shape (n_vertices, 3), finger frame."""


@dataclass(frozen=True, eq=False)
class FemPress:
    """The finger pressed onto the press scenario's plate by its tendon (static, frictionless contact).

    The first three fields are :data:`mjcodesign.scenarios.press.PRESS_METRICS`.
    """

    total_force_n: float
    """Total normal force of the plate on the finger [N]."""
    distal_third_fraction: float
    """Share of that force at x > 2L/3 (rest positions along the finger)."""
    centroid_over_length: float
    """Force-weighted mean rest x of the contacts over the finger length L."""
    n_contacts: int
    """Vertices pushed by the plate."""
    max_penetration_m: float
    """Deepest vertex inside the plate [m]."""


@dataclass(frozen=True, eq=False)
class FemContactRun:
    """An explicit-dynamics rollout of a finger next to a static rigid object (world frame)."""

    times: np.ndarray
    """Frame times [s], shape (k,): 0, every ``steps // frames`` steps, and the end (k ≈ frames + 1)."""
    tip: np.ndarray
    """Tip vertex position at ``times`` [m], shape (k, 3)."""
    x: np.ndarray
    """Final vertex positions [m], shape (n_vertices, 3)."""
    object_force: np.ndarray
    """Final contact force of the object on each vertex [N], shape (n_vertices, 3)."""
    mean_normal_force: float
    """Time-averaged normal force on the object over the rollout [N]."""
    max_penetration: float
    """Deepest final vertex inside the object [m]."""
    steps: int
    """Explicit steps taken."""


@dataclass(frozen=True, eq=False)
class FemBuckling:
    """The unloaded finger's critical tendon tensions (`FemStability.buckling_tension`)."""

    follower_eigenvalue_per_n: float
    """λ_max(G_q C) [1/N]: the tendon's own stiffness at rest against the compliance at its points."""
    follower_tension_n: float
    """1 / ``follower_eigenvalue_per_n`` [N]; ``inf`` when that is not positive (no buckling)."""
    linearised_eigenvalue_per_n: float
    """μ_max of −(K₁ − G₀) v = μ K₀ v [1/N]: linear buckling with the unit tension's prestress."""
    linearised_tension_n: float
    """1 / ``linearised_eigenvalue_per_n`` [N]; ``inf`` when that is not positive."""
    mode_block_angles: tuple[float, ...]
    """The linearised mode's section rotation of each block relative to the previous one, largest
    |entry| 1, (n_blocks,)."""
    mode_block: int
    """The block that turns most in the mode. Read at the spine's sections, whose top vertices sit on
    the cuts' feet: a mode that wrinkles a foot misleads it (``mode_block_energy`` does not)."""
    mode_block_energy: tuple[float, ...]
    """The linearised mode's share of its elastic energy ½ vᵀK₀v in each block, summing to 1, (n_blocks,)."""
    mode_energy_at_feet: float
    """Its share within 0.5 mm of a cut's foot (a segment's trapezoid cut meeting the spine's top)."""
    mode_energy_at_tendon: float
    """Its share in the tets that touch a vertex a tendon point loads (the support of the points' weights)."""
    global_tension_n: float
    """The linearised pencil's critical tension [N] over the global modes only: Rayleigh–Ritz on the
    static responses to each segment's rigid in-plane loads; at least ``linearised_tension_n``."""
    global_mode_block_energy: tuple[float, ...]
    """The global mode's share of its elastic energy in each block, (n_blocks,)."""
    global_mode_energy_at_feet: float
    """The global mode's share within 0.5 mm of a cut's foot."""


@dataclass(frozen=True, eq=False)
class FemPathStability:
    """Equilibria along increasing tension and their tangent's smallest eigenvalue."""

    tensions_n: tuple[float, ...]
    """Tendon tensions [N], increasing."""
    eigenvalues: tuple[float, ...]
    """Eigenvalue nearest zero of A(x, T) v = λ K₀ v at each equilibrium [-] (1 at rest)."""
    bend_angles_rad: tuple[float, ...]
    """Rotation of the tip block's distal section at each equilibrium [rad]; + curls inwards."""
    critical_tension_n: float
    """Where λ first crosses zero, linear between bracketing tensions [N]; ``inf`` if it never does."""
    failed_tension_n: float | None
    """The tension [N] whose equilibrium Newton did not find (the path ends there), or None."""
