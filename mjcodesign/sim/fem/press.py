"""The ``press`` scenario in the Warp FEM: the finger's static equilibrium against the plate.

The scenario itself (plate, metrics, the MuJoCo models) is `mjcodesign.scenarios.press`. The FEM uses
linear tets, so contact acts at corner vertices: frictionless penalty contact against the plate's signed
distance (`mjcodesign.sim.fem.contact.FemContact.contact_static`), solved with the tendon by Newton.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mjcodesign.scenarios.press import force_distribution, plate_pose
from mjcodesign.sim.fem.contact import FemContact
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.results import FemPress
from mjcodesign.sim.fem.rigid import RigidObject

__all__ = ["press_fem"]


def press_fem(fem: FemFinger, tension: float, *, steps: int = 4, observe=None) -> FemPress:
    """FEM finger (linear tets) pressed onto the plate at ``tension`` [N]: static equilibrium, frictionless.

    The load is ramped in ``steps`` increments. ``observe(positions, contact_forces)``, if given, is
    called with the rest positions [m] (n, 3) and the plate's force on every vertex [N] (n, 3).
    """
    centre, R, half = plate_pose(fem.design)
    contact = FemContact(fem, RigidObject.box(centre, half, R))
    tendon = fem.tendon_load(tension)

    def load(x):
        f_t, J_t = tendon(x)
        f_c, k_c = contact.contact_static(x)
        J_c = sp.block_diag(list(-k_c), format="csr")
        return f_t + f_c, J_t + J_c

    x = fem.solve_static(load, steps=steps)
    f_c, _ = contact.contact_static(x)
    if observe is not None:
        observe(x, f_c)
    fn = f_c @ (R @ np.array([0.0, 0.0, -1.0]))  # along the outward normal of the plate's lower face
    dist = force_distribution(fem.mesh.vertices[:, 0], fn, fem.design.length)
    return FemPress(
        total_force_n=dist["total_force_n"],
        distal_third_fraction=dist["distal_third_fraction"],
        centroid_over_length=dist["centroid_over_length"],
        n_contacts=int(np.count_nonzero(fn > 0)),
        max_penetration_m=contact.max_penetration(x),
    )
