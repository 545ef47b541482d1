"""Two FEM fingers on a palm: both meshes as one elastic body, placed as the MuJoCo gripper places them.

`FemGripper` meshes finger A and finger B of a design (`mjcodesign.sim.fem.finger.FemFinger`, linear
tets) and concatenates them, finger A's vertices first, so that one launch of each kernel steps both.
Finger i's blocks take ln E entries ``11 i .. 11 i + 10`` of one array of 22 (its gradient is the
design gradient). The masses are selectively scaled for the explicit step (`FemBody.stable_mass`).

`FemGripper.place` puts the rest meshes where `mjcodesign.models.builder.build_gripper` puts the
chain: the palm at the pose, each finger's base face on its carriage at ``side · (opening +
height_base)`` along the palm's y axis, finger x along palm −z and the inner face (finger z) towards
the palm's mid-plane (`mjcodesign.models.spec.finger_frame_quat`).
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import LOG_E_MAX, Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.models.spec import finger_frame_quat
from mjcodesign.models.types import GripperPose
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.options import FemOptions

__all__ = ["FemGripper", "GAP_STIFFNESS", "GapPairs", "Placement", "SIDES", "quat_matrix"]

SIDES = (1, -1)
"""Side of finger A and finger B along the palm's y axis (the closing axis)."""
GAP_STIFFNESS = float(np.exp(LOG_E_MAX))
"""Pressure stiffness of the segments' contact across a closed flexure gap, times the cell size [Pa]:
the stiffest printable TPU over one cell, whatever the design (so it adds no design gradient). 10 N of
tendon on ~10 face vertices of a 4 mm mesh then closes the gap to ~10 µm."""
_ON_FACE = 1e-9
"""A vertex within this [m] of a cut face's profile lies on it (the mesh puts vertices exactly there)."""


class GapPairs(NamedTuple):
    """Segment–segment contact across the flexure gaps (`mjcodesign.sim.fem.grasp_kernels.gap_contact`).

    Each row is a vertex of one cut face against the rectangle of the facing cut face.
    """

    vertex: np.ndarray
    """The vertex (int32), shape (k,)."""
    quad: np.ndarray
    """The facing face's corners (int32): top at −w/2, top at +w/2, bottom at −w/2, bottom at +w/2,
    shape (k, 4); its outward normal is (top₊ − top₋) × (bottom₋ − top₋), normalised."""
    area: np.ndarray
    """The vertex's lumped contact area [m²], shape (k,)."""


def quat_matrix(quat) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (w, x, y, z)."""
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(quat, dtype=float))
    return R.reshape(3, 3)


class Placement(NamedTuple):
    """The gripper's rest meshes in the world at a pose and openings (lift 0)."""

    vertices: np.ndarray
    """Rest vertex positions [m], both fingers, shape (n_vertices, 3)."""
    exits: np.ndarray
    """Each finger's tendon anchor on its base face [m], shape (2, 3): the exit point (guided routing) or
    the base segment's channel entry (printed; `mjcodesign.sim.fem.body.FemBody.tendon_path`)."""
    axes: np.ndarray
    """Each finger's opening direction (carriage slide) in the world, shape (2, 3)."""
    palm: np.ndarray
    """Palm position [m] (3,)."""
    rotation: np.ndarray
    """Palm rotation (palm frame → world), shape (3, 3)."""


LOCKING_ITERATIONS = 3
"""Fixed-point passes of `locking_shift`: a block's compliance also depends a little on its neighbours'
moduli; three passes bring every block within 0.43% of the converged FEM's on the coarse mesh (nine
designs: the presets, random:0..3 and both alternating extremes; tests/test_fem_locking.py)."""


def locking_shift(finger, log_e: np.ndarray) -> np.ndarray:
    """The ln E shift of each of ``finger``'s blocks that makes its tip-load block compliances the converged FEM's.

    ``finger`` is a linear-tet `FemFinger` (its row of ``log_e`` (22,) is the design's); its block ``i``
    turns by ``Δφ_i`` under a tip load ``F``, so its compliance is ``Δφ_i / (F (L − x_i))`` (``x_i`` the
    block's middle), as `mjcodesign.design.calibration.block_compliance` gives it for the converged FEM.
    Each pass adds ln(mesh / converged) to the shift (`LOCKING_ITERATIONS`). The load bends the
    Euler–Bernoulli beam by `mjcodesign.scenarios.static.AUTO_DEFLECTION` of the length (linear range).
    Leaves ``finger`` at the shifted moduli.
    """
    from mjcodesign.design.beam import cantilever_tip_deflection
    from mjcodesign.design.calibration import block_compliance, moment_arms
    from mjcodesign.scenarios.static import AUTO_DEFLECTION

    design = finger.design
    nb = design.n_blocks
    rows = slice(finger.finger * nb, (finger.finger + 1) * nb)
    log_e = np.asarray(log_e, dtype=float).ravel()
    young = np.exp(log_e[rows])
    target = block_compliance(design, young)
    arm = moment_arms(design)
    force = AUTO_DEFLECTION * design.length / cantilever_tip_deflection(design, young, 1.0)
    m = finger.mesh
    load = np.zeros((m.n_vertices, 3))
    load[m.tip_face, 2] = force * m.tip_face_weight
    shift = np.zeros(nb)
    for _ in range(LOCKING_ITERATIONS):
        trial = log_e.copy()
        trial[rows] += shift
        finger.set_log_e(trial)
        x = finger.solve_static(lambda x: (load, None))
        turn = np.abs(np.diff(np.r_[0.0, finger.section_angles(x)]))
        shift += np.log(turn / (force * arm) / target)
    final = log_e.copy()
    final[rows] += shift
    finger.set_log_e(final)
    return shift


class FemGripper:
    """Finger A and finger B of ``stiffness`` as one tet body (A's vertices first), linear or quadratic tets.

    ``dt`` [s] is the explicit step that the masses are scaled for.
    """

    def __init__(
        self, design: FingerDesign, stiffness: Stiffness, *, options: FemOptions | None = None, dt: float
    ):
        options = options or FemOptions(waypoint_layers=False)
        self.design = design
        self.options = options
        self.fingers = tuple(FemFinger(design, stiffness, finger=i, options=options) for i in range(2))
        a = self.fingers[0]
        wp = self.wp = a.wp
        dev = self.device = options.device
        n = self.n_per_finger = a.mesh.n_vertices
        nb = self.n_blocks = design.n_blocks
        self.n_vertices = 2 * n
        tets = a.mesh.tets.astype(np.int32)
        self.n_tets = 2 * len(tets)
        self.tets = wp.array(np.vstack([tets, tets + n]), dtype=wp.int32, device=dev)
        self.dm_inv = wp.array(
            np.concatenate([f.dm_inv.numpy() for f in self.fingers]), dtype=wp.mat33d, device=dev
        )
        self.vol = wp.array(
            np.concatenate([f.vol.numpy() for f in self.fingers]), dtype=wp.float64, device=dev
        )
        block = a.mesh.tet_block.astype(np.int32)
        self.tet_block_np = np.concatenate([block, block + nb])
        """Block of every tet, finger B's offset by n_blocks, shape (n_tets,)."""
        self.tet_block = wp.array(self.tet_block_np, dtype=wp.int32, device=dev)
        self._tets_np = np.vstack([tets, tets + n])
        x = a.mesh.vertices[tets]
        self._rest_volume6 = np.tile(
            np.linalg.det(np.stack([x[:, k] - x[:, 0] for k in (1, 2, 3)], axis=2)), 2
        )
        self.log_e = wp.array(stiffness.log_e.ravel(), dtype=wp.float64, device=dev, requires_grad=True)
        self.log_e_shift = wp.zeros(2 * nb, dtype=wp.float64, device=dev)
        """Constant added to ``log_e`` before the material (`FemOptions.locking_correction`; else 0)."""
        self.log_e_material = wp.zeros(2 * nb, dtype=wp.float64, device=dev, requires_grad=True)
        self._set_shift(stiffness.log_e.ravel())
        self.mu = wp.zeros(self.n_tets, dtype=wp.float64, device=dev, requires_grad=True)
        self.lam = wp.zeros(self.n_tets, dtype=wp.float64, device=dev, requires_grad=True)
        self.update_material()
        self.dt = float(dt)
        self.mass = np.concatenate([f.mass for f in self.fingers])
        """True vertex masses [kg] (gravity acts on these)."""
        self.area = np.cbrt(self.mass / design.density) ** 2
        """Lumped contact patch of every vertex [m²]: its volume share to the power 2/3."""
        self.pinned = np.zeros(2 * n, dtype=np.int32)
        self.pinned[a.mesh.base] = 1
        self.pinned[a.mesh.base + n] = 1
        self.finger_of = np.repeat(np.arange(2, dtype=np.int32), n)
        if options.routing == "printed":  # the printed finger's channels, the statics' own embedding
            idx, w = a.path_table()
            section = a.section_pairs()[a.path_blocks]
        else:
            idx, w = a.waypoint_table()
            section = a.section_pairs()
            if not options.flexure_guides:  # the segments' waypoints only (`FemOptions.flexure_guides`)
                keep = [b.index for b in design.blocks() if b.kind is BlockKind.SEGMENT]
                idx, w, section = idx[keep], w[keep], section[keep]
        self.waypoint_section = np.vstack([section, section + n])
        """The spine section (top, bottom vertex) at each tendon point's block middle: the axis of the
        authors' tendon law (`FemOptions.tendon_law`; guided routing only)."""
        self.n_waypoints = len(idx)
        """Tendon points per finger after its anchor (the rows of ``waypoint_idx`` / ``waypoint_w`` for
        each finger): the guided waypoints, or the printed routing's 17 channel points
        (`mjcodesign.sim.fem.body.FemBody.path_table`)."""
        self.waypoint_idx = np.vstack([idx, idx + n])
        self.waypoint_w = np.vstack([w, w])
        self.gaps = self._gap_pairs()
        self.gap_ke = GAP_STIFFNESS / options.h
        """Pressure stiffness of the segments' contact across a closed gap [Pa/m]."""
        self._scale_mass()

    def _gap_pairs(self) -> GapPairs:
        """Both fingers' cut-face vertices against the facing cut faces, across every flexure gap.

        At high tension a gap closes and the segments bear on each other; without this contact the
        tendon's whole compression crushes the 2 mm flexure (a soft finger at 10 N inverted its flexure
        tets within 30 ms and the explicit step blew up).
        """
        v = self.fingers[0].mesh.vertices
        d = self.design
        half = 0.5 * d.width
        blocks = d.blocks()
        rows = []
        for flex in blocks[1:-1:2]:
            before, after = blocks[flex.index - 1], blocks[flex.index + 1]
            faces = [
                _cut_face(v, before, before.x1 - before.cut1, before.x1),
                _cut_face(v, after, after.x0 + after.cut0, after.x0),
            ]
            for mine, other in ((faces[0], faces[1]), (faces[1], faces[0])):
                corners = [_at(v, x, y, z) for x, z in other[1] for y in (-half, half)]
                c = v[corners]
                normal = np.cross(c[2] - c[0], c[1] - c[0])
                if normal @ (v[mine[0]].mean(axis=0) - c.mean(axis=0)) < 0:  # outward: towards the gap
                    corners = [corners[1], corners[0], corners[3], corners[2]]
                rows += [(i, corners) for i in mine[0]]
        vertex = np.array([r[0] for r in rows], dtype=np.int32)
        quad = np.array([r[1] for r in rows], dtype=np.int32)
        n = self.n_per_finger
        area = self.area[vertex]
        return GapPairs(np.r_[vertex, vertex + n], np.vstack([quad, quad + n]), np.r_[area, area])

    def _set_shift(self, log_e: np.ndarray) -> None:
        """``log_e_shift`` for the design ``log_e`` (22,), and the fingers' statics at the shifted moduli."""
        nb = self.n_blocks
        shift = np.zeros(2 * nb)
        if self.options.locking_correction:
            for i, f in enumerate(self.fingers):  # each left at its shifted row: the masses are scaled
                shift[i * nb : (i + 1) * nb] = locking_shift(f, log_e)  # for the stiffness the dynamics sees
        self.log_e_shift.assign(shift)

    def update_material(self) -> None:
        """Per-tet Lamé parameters from ``log_e`` plus ``log_e_shift`` (Warp launches; taped by the gradient)."""
        from mjcodesign.sim.fem import kernels

        wp = self.wp
        wp.launch(
            kernels.add_shift,
            dim=2 * self.n_blocks,
            inputs=[self.log_e, self.log_e_shift],
            outputs=[self.log_e_material],
            device=self.device,
        )
        wp.launch(
            kernels.lame_parameters,
            dim=self.n_tets,
            inputs=[self.log_e_material, self.tet_block, 0, wp.float64(self.options.poisson)],
            outputs=[self.mu, self.lam],
            device=self.device,
        )

    def volume_ratio(self, x: np.ndarray) -> np.ndarray:
        """Volume ratio J of every tet at vertex positions ``x`` [m] (n_vertices, 3): ≤ 0 is inverted."""
        p = x[self._tets_np]
        d = np.linalg.det(np.stack([p[:, k] - p[:, 0] for k in (1, 2, 3)], axis=2))
        return d / self._rest_volume6

    def _scale_mass(self) -> None:
        gaps = self.gaps
        k = np.zeros(self.n_vertices)  # the gap contact's stiffness at each vertex, corners included
        np.add.at(k, gaps.vertex, self.gap_ke * gaps.area)
        np.add.at(k, gaps.quad.ravel(), np.repeat(self.gap_ke * gaps.area, 4))
        n = self.n_per_finger
        self.inertial = np.concatenate(
            [f.stable_mass(self.dt, k[i * n : (i + 1) * n]) for i, f in enumerate(self.fingers)]
        )
        """Inertial vertex masses [kg], selectively scaled for the step ``dt``."""
        self.added_mass_fraction = float(self.inertial.sum() / self.mass.sum() - 1.0)

    def set_log_e(self, log_e: np.ndarray, *, rescale_mass: bool = True) -> None:
        """Replace the 22 ln(E / Pa) (finger A base to tip, then finger B) and rescale the masses.

        ``rescale_mass=False`` keeps the masses scaled for the design built before (as the gradient
        does: a finite-difference check of it perturbs E with the masses fixed).
        """
        log_e = np.asarray(log_e, dtype=float).ravel()
        if np.array_equal(log_e, self.log_e.numpy()):
            return
        self.log_e.assign(log_e)
        if rescale_mass:
            for f in self.fingers:
                f.set_log_e(log_e)
            self._set_shift(log_e)  # a new design: its own locking shift (a constant of the gradient)
        self.update_material()
        if rescale_mass:
            self._scale_mass()

    def _elastic_launch(self, name: str, x, out) -> tuple:
        """(kernel, dim, inputs, outputs) of the elastic kernel ``name`` at ``x`` into ``out``.

        Linear tets: one thread per tet; quadratic: the ``p2_`` kernel, per tet and quadrature point.
        """
        from mjcodesign.sim.fem import kernels

        if self.options.order == 1:
            kernel, dim = getattr(kernels, name), self.n_tets
        else:
            kernel, dim = getattr(kernels, f"p2_{name}"), (self.n_tets, 4)
        return kernel, dim, [x, self.tets, self.dm_inv, self.vol, self.mu, self.lam], [out]

    def force_launch(self, x, f) -> tuple:
        """(kernel, dim, inputs, outputs) accumulating the elastic forces [N] at ``x`` into ``f``."""
        return self._elastic_launch("elastic_forces", x, f)

    def warp_positions(self, x):
        """``x`` as a Warp vec3d array (a Warp array as it is, numpy copied)."""
        if isinstance(x, self.wp.array):
            return x
        return self.wp.array(np.asarray(x, dtype=float), dtype=self.wp.vec3d, device=self.device)

    def elastic_forces(self, x) -> np.ndarray:
        """Elastic vertex forces [N] (n_vertices, 3) at positions ``x`` [m] (n_vertices, 3; numpy or Warp)."""
        xw = self.warp_positions(x)
        f = self.wp.zeros(self.n_vertices, dtype=self.wp.vec3d, device=self.device)
        kernel, dim, inputs, outputs = self.force_launch(xw, f)
        self.wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.device)
        return f.numpy()

    def energy(self, x) -> float:
        """Elastic energy [J] of both fingers at positions ``x`` [m] (n_vertices, 3; numpy or Warp)."""
        e = self.wp.zeros(1, dtype=self.wp.float64, device=self.device)
        kernel, dim, inputs, outputs = self._elastic_launch("elastic_energy", self.warp_positions(x), e)
        self.wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.device)
        return float(e.numpy()[0])

    def tendon_points_disjoint(self) -> bool:
        """True if no two of a finger's tendon points weigh the same free vertex.

        The position servo's implicit damper (`mjcodesign.sim.fem.grasp_kernels.tendon_damping`) sums
        each point's own part of the tendon's compliance, which needs it. Both fingers have the same table.
        """
        free = self.pinned[: self.n_per_finger] == 0
        rows = zip(self.waypoint_idx[: self.n_waypoints], self.waypoint_w[: self.n_waypoints], strict=True)
        used = np.concatenate([np.unique(i[(w != 0) & free[i]]) for i, w in rows])
        return len(used) == len(np.unique(used))

    def place(self, pose: GripperPose, openings) -> Placement:
        """The rest meshes at the palm ``pose`` with the carriages at ``openings`` [m] (lift 0)."""
        R = quat_matrix(pose.quat)
        palm = np.asarray(pose.position, dtype=float)
        rest = self.fingers[0].mesh.vertices
        exit_point = self.fingers[0].anchor  # the exit point, or the printed base channel's entry
        verts, exits, axes = [], [], []
        for side, opening in zip(SIDES, openings, strict=True):
            Rf = R @ quat_matrix(finger_frame_quat(side))
            origin = palm + R @ np.array([0.0, side * (opening + self.design.height_base), 0.0])
            verts.append(rest @ Rf.T + origin)
            exits.append(Rf @ exit_point + origin)
            axes.append(R @ np.array([0.0, float(side), 0.0]))
        return Placement(np.vstack(verts), np.array(exits), np.array(axes), palm, R)


def _cut_face(v: np.ndarray, block, x_top: float, x_bottom: float) -> tuple[np.ndarray, list]:
    """The vertices on a segment's cut face, and the face's top and bottom (x, z) [m], finger frame.

    The face is the segment's top profile between ``x_top`` and ``x_bottom``.
    """
    lo, hi = min(x_top, x_bottom), max(x_top, x_bottom)
    inside = (v[:, 0] >= lo - _ON_FACE) & (v[:, 0] <= hi + _ON_FACE)
    on = inside & (np.abs(v[:, 2] - block.height(v[:, 0])) < _ON_FACE)
    return np.flatnonzero(on), [(x_top, float(block.height(x_top))), (x_bottom, float(block.spine))]


def _at(v: np.ndarray, x: float, y: float, z: float) -> int:
    """The vertex at (x, y, z) [m] of the rest mesh."""
    hit = np.flatnonzero(np.linalg.norm(v - np.array([x, y, z]), axis=1) < _ON_FACE)
    if len(hit) != 1:
        raise DesignError(f"the finger mesh has no vertex at a cut face corner ({x:.4f}, {y:.4f}, {z:.4f}) m")
    return int(hit[0])
