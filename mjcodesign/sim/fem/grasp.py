"""The FEM's single-finger grasp: a finger hanging from its clamped base closes on a static box.

The scene of `mjcodesign bench fem` and of the FEM backend's grasp
(`mjcodesign.sim.fem.backend.FemBackend.grasp`): one `mjcodesign.sim.fem.contact.FemContact`, no free
object and no second finger.
"""

from __future__ import annotations

import numpy as np

from mjcodesign.scenarios.press import plate_pose
from mjcodesign.sim.fem.contact import FemContact
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.options import FemDynamics
from mjcodesign.sim.fem.rigid import RigidObject

__all__ = ["grasp_scene"]

_GRASP_GAP = 2e-4
"""Gap [m] between the grasp box and the segment tops."""
_GRASP_BASE_HEIGHT = 0.2
"""Height of the grasp finger's base above the ground [m]."""
_GRASP_RAMP = 0.05
"""Tendon tension ramp of the grasp [s]."""


def grasp_scene(
    fem: FemFinger, tension: float, *, ramp: float = _GRASP_RAMP, dynamics: FemDynamics | None = None
) -> FemContact:
    """The finger hanging from its clamped base (as in a top grasp) closing under ``tension`` [N] on a box.

    The finger frame maps x (along the finger) to world −z and z (its inner side) to world +x, base at
    0.2 m. The box is the press scenario's plate (`mjcodesign.scenarios.press.plate_pose`) lowered to
    0.2 mm from the segment tops: the finger's first bending mode has a period near 2 s, so a wider gap
    would not close within a 0.2 s horizon. The tension ramps up over ``ramp`` [s]; ``dynamics``
    defaults to the paper's.
    """
    R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # columns: finger x, y, z in world
    base = np.array([0.0, 0.0, _GRASP_BASE_HEIGHT])
    centre, Rp, half = plate_pose(fem.design, gap=_GRASP_GAP)
    box = RigidObject.box(R @ centre + base, half, R @ Rp)
    return FemContact(fem, box, rotation=R, position=base, dynamics=dynamics, tension=tension, ramp=ramp)
