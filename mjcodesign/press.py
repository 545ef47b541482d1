"""The ``press`` scenario: one finger, base clamped, curls onto a flat rigid plate under tendon tension.

The plate lies over the finger's inner side, parallel to the line through the segment tops (which taper
from 14 mm at the base to 6 mm at the tip), ``gap`` above it. The tendon closes the finger onto it and
the contact normal force is read along the finger (position ``x`` of the contact in the base frame, which
is the finger's length coordinate while it lies flat on the plate):

* ``distal_third_fraction``: share of the total normal force at ``x > 2L/3``;
* ``centroid_over_length``: force-weighted mean ``x`` divided by ``L``.

The paper's claim (Fig. 2): uniform-pressure routing (tendon moment ∝ (L − x)², the moment of a
uniform pressure) spreads the force along the finger; uniform-height routing (constant moment) loads
the tip. Models: the MuJoCo chain and flex run their dynamics to rest (point-force tendon, gravity off);
the Warp FEM (linear tets; contact at vertices) solves the static equilibrium with frictionless penalty
contact against the plate's signed distance (`mjcodesign.fem_grasp.FemContact.contact_static`).
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import scipy.sparse as sp

from mjcodesign.errors import SimulationDiverged
from mjcodesign.finger import FingerDesign
from mjcodesign.stiffness import Stiffness

__all__ = ["plate_pose", "force_distribution", "press_mujoco", "press_fem", "PLATE_GAP"]

PLATE_GAP = 5e-4
"""Gap between the plate and the segment tops at rest [m]."""
_PLATE_HALF = (0.08, 0.02, 0.005)
"""Plate half extents [m]: longer and wider than the finger, 10 mm thick."""
_PLATE_X0 = 0.02
"""Plate starts past the clamped base segment [m] (x in the finger frame)."""
_MIN_CONTACT_FORCE = 1e-9
"""Total normal force below this [N] means the finger never reached the plate."""


def plate_pose(design: FingerDesign, gap: float = PLATE_GAP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plate centre [m] (3,), rotation (3, 3) and half extents [m] (3,) in the finger frame."""
    slope = (design.height_tip - design.height_base) / design.length
    ang = np.arctan(slope)
    R = np.array([[np.cos(ang), 0.0, -np.sin(ang)], [0.0, 1.0, 0.0], [np.sin(ang), 0.0, np.cos(ang)]])
    half = np.array(_PLATE_HALF)
    x_mid = _PLATE_X0 + half[0] * np.cos(ang)
    z_face = design.height_base + slope * x_mid + gap / np.cos(ang)
    centre = np.array([x_mid, 0.0, z_face]) + R @ np.array([0.0, 0.0, half[2]])
    return centre, R, half


def force_distribution(x: np.ndarray, fn: np.ndarray, length: float) -> dict:
    """Distal-third share and centroid of normal forces ``fn`` [N] acting at ``x`` [m] along the finger."""
    x = np.asarray(x, dtype=float)
    fn = np.clip(np.asarray(fn, dtype=float), 0.0, None)
    total = float(fn.sum())
    if total < _MIN_CONTACT_FORCE:
        raise SimulationDiverged("the finger never touched the plate; raise the tension")
    return {
        "total_force_n": total,
        "distal_third_fraction": float(fn[x > 2.0 * length / 3.0].sum() / total),
        "centroid_over_length": float(np.dot(x, fn) / (total * length)),
    }


_MAX_TIME = 10.0
"""Simulated time [s] allowed to come to rest (the chain rests within 1 s)."""


def press_mujoco(
    design: FingerDesign, stiffness: Stiffness, model: str, tension: float, *, max_time: float = _MAX_TIME
) -> dict:
    """Chain or flex finger pressed onto the plate: dynamics to rest, then the contact forces."""
    from mjcodesign.mjcf import CONTYPE_FINGER, CONTYPE_WORLD, FingerModel, TendonMode, _compile, _finalise
    from mjcodesign.mjcf import build_finger as _build
    from mjcodesign.tendon import TendonDriver
    from mjcodesign.validate import _rest_options, run_to_rest

    model = FingerModel(model)
    opts = _rest_options(design, stiffness.finger(0), None)
    built = _build(design, stiffness, model, options=opts, tendon_mode=TendonMode.POINT_FORCE)
    centre, R, half = plate_pose(design)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    built.spec.worldbody.add_geom(
        name="plate",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=half,
        pos=centre,
        quat=q,
        contype=CONTYPE_WORLD,
        conaffinity=CONTYPE_FINGER,
    )
    m = _compile(built.spec)
    _finalise(m, built.fingers)
    built = replace(built, model=m)
    d = mujoco.MjData(m)
    drv = TendonDriver(built)
    drv.set_tension(d, tension)
    plate = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "plate")
    sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, built.fingers[0].tip_site)
    run_to_rest(m, d, drv.apply, lambda d: d.site_xpos[sid].copy(), max_time=max_time)
    xs, fs = [], []
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        if plate not in (c.geom[0], c.geom[1]):
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        xs.append(float(c.pos[0]))
        fs.append(float(f6[0]))
    out = force_distribution(np.array(xs), np.array(fs), design.length)
    out["n_contacts"] = len(xs)
    return out


def press_fem(fem, tension: float, *, steps: int = 4) -> dict:
    """FEM finger (linear tets) pressed onto the plate: static equilibrium, frictionless contact."""
    from mjcodesign.fem_grasp import FemContact, RigidObject

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
    fn = f_c @ (R @ np.array([0.0, 0.0, -1.0]))  # along the outward normal of the plate's lower face
    out = force_distribution(fem.mesh.vertices[:, 0], fn, fem.design.length)
    out["n_contacts"] = int(np.count_nonzero(fn > 0))
    out["max_penetration_m"] = contact.max_penetration(x)
    return out
