"""Options of the Warp FEM finger: mesh and material (`FemOptions`), explicit dynamics (`FemDynamics`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mjcodesign.design.tendon_law import TENDON_VARIANTS
from mjcodesign.errors import DesignError
from mjcodesign.models.types import ROUTINGS

__all__ = ["FemOptions", "FemDynamics"]

_POISSON = 0.45
"""Poisson's ratio of the paper's TPU model (the authors' simulator)."""


@dataclass(frozen=True)
class FemOptions:
    """Mesh, material and tendon options of the FEM finger."""

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
    """Tet order: 1 (4 nodes, statics and dynamics) or 2 (10 nodes, far less locking: statics and the
    two-finger grasp, with HRZ-lumped masses and forces at four quadrature points; about 10x a linear
    grasp's time per substep on the coarse mesh; the single-finger rollout is linear only)."""
    locking_correction: bool = False
    """Two-finger grasp (linear tets): lower every block's modulus so that the mesh's block compliances
    under a tip load equal the converged FEM's (`mjcodesign.sim.fem.gripper.locking_shift`). Linear
    tets lock in bending: on the grasp study's coarse mesh (10 mm, 8 mm flexures, 2 spine layers) the
    flexures are 5.1x and the segments 2.7-3.0x too stiff on the presets, and a semi-rigid
    finger curls 4.4x less than the converged FEM and the chain calibrated to it. Default finger
    geometry only (the calibration's)."""
    flexure_guides: bool = True
    """Two-finger grasp, guided routing only: the tendon passes a guide on every flexure (a rigid lever
    on its mid-section, `mjcodesign.sim.fem.mesh`), as the chain's flexure site does. False keeps the
    older, cruder variant of the printed finger: only the segments' guided waypoints, one a segment at
    the guided heights, and straight across each gap. The printed finger itself is ``routing="printed"``
    (its channels at their measured heights), which refuses ``flexure_guides=False``."""
    tendon_law: str = "frictionless"
    """Two-finger grasp: ``frictionless``, the exact force of a frictionless tendon at its waypoints (it
    compresses the finger by T); ``paper``, the authors' law (`mjcodesign.design.tendon_law`): middle
    waypoints keep only the part across their section's axis, the first takes nothing and the tip a
    push T along its section's axis, so the finger is not compressed."""
    routing: str = "guided"
    """Where the tendon runs, in the statics (`FemBody.tendon_load`) and the two-finger grasp
    (`mjcodesign.sim.fem.gripper_grasp.FemGrasp`, force and position drives): ``guided``, through one
    waypoint per block (`FingerMesh.waypoint_weights`); ``printed``, as in the printed finger, through
    the entry, middle and exit of every segment's channel (`mjcodesign.models.channels.channel_points`,
    embedded in the rest mesh by `mjcodesign.sim.fem.mesh.embed_points`; both take the same weights,
    `FemBody.path_table`) and straight across each flexure gap, anchored at the base segment's channel
    entry on the clamped base face (it moves with the base and its carriage); frictionless law only, and
    the grasp's servo reads this path's length. The single finger's contact rollouts
    (`mjcodesign.sim.fem.contact`) run the guided waypoints and refuse ``printed``."""
    waypoint_layers: bool = True
    """Spine layer boundaries through in-spine waypoints (`mjcodesign.sim.fem.mesh.mesh_finger`); turn
    off for explicit dynamics, where their 30 µm layers cut the stable step tenfold."""

    def __post_init__(self) -> None:
        if self.order not in (1, 2):
            raise DesignError(f"tet order must be 1 or 2, got {self.order}")
        if self.tendon_law not in TENDON_VARIANTS:
            raise DesignError(f"unknown tendon law {self.tendon_law!r}; choose from {TENDON_VARIANTS}")
        if self.routing not in ROUTINGS:
            raise DesignError(f"unknown routing {self.routing!r}; choose from {ROUTINGS}")
        if self.routing == "printed" and self.tendon_law != "frictionless":
            # The paper law needs one section axis per waypoint; a channel has three points per segment.
            raise DesignError("the printed routing runs the frictionless tendon law only")
        if self.routing == "printed" and not self.flexure_guides:
            raise DesignError(
                "flexure_guides=False is a variant of the guided routing; the printed routing runs its "
                "channels straight across every flexure gap already"
            )
        if not 0.0 <= self.poisson < 0.5:
            raise DesignError(f"Poisson's ratio must be in [0, 0.5), got {self.poisson}")


@dataclass(frozen=True)
class FemDynamics:
    """Explicit dynamics options; defaults are the paper's (the authors' simulator)."""

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
    contact_damping_ratio: float = 0.0
    """Two-finger grasp only: > 0 gives every finger vertex's contact this damping ratio ζ instead of
    ``contact_kd`` (area·kd = 2ζ √(ke·area·m)). The paper's kd is 10–20× critical on a vertex of the
    coarse mesh, and it adds to the normal force that bounds friction (documentation: the FEM grasp study);
    MuJoCo's chain contacts are critically damped (ζ = 1). Use it with little selective mass
    scaling: at 10 µs on the coarse mesh (151% added mass) a ζ = 1 grip let a held box slide out,
    at 4 µs (1%) it held it (tests/test_fem_grasp.py)."""
    friction: float = 1.0
    """Coulomb coefficient (the paper's μ = 1)."""
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    """Gravity in the world frame [m/s²]."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise DesignError(f"dt must be positive, got {self.dt}")
        if not (np.isfinite(self.contact_damping_ratio) and self.contact_damping_ratio >= 0):
            raise DesignError(f"contact_damping_ratio must be >= 0, got {self.contact_damping_ratio}")
