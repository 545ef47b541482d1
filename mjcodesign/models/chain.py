"""Hinge-chain (pseudo-rigid-body) finger.

Each block's bending compliance is lumped into one hinge at the block's midpoint (hinges at block
boundaries overshoot by 12–25%, shared/NOTES.md). Its stiffness and axis come from
:attr:`SimOptions.stiffness_model`:

* ``fem`` (default): ``k_i = 1 / c_i`` with ``c_i`` block i's rotation per unit moment in the calibrated
  FEM (:func:`mjcodesign.design.calibration.block_compliance`, per design in ~0.1 ms), about an axis at
  the block's fitted bending height (a segment bends at its flexure roots, ~1.4 mm up);
* ``beam``: Euler–Bernoulli, ``k_i = E_i I_i / l_i`` with ``I_i = l_i / ∫ dx / I(x)`` the block's
  series-equivalent section, about the section's mid-height (exact for uniform designs only).

Rigid piece ``k`` spans from block ``k``'s midpoint to block ``k+1``'s midpoint; piece 0's proximal
half belongs to the base. Adjacent pieces are parent and child, so MuJoCo never collides them; the
finger's geoms share one contact bit and never collide with each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from mjcodesign.design.beam import block_effective_ei
from mjcodesign.design.calibration import block_compliance, calibration_for
from mjcodesign.design.finger import Block, BlockKind, FingerDesign
from mjcodesign.models.types import CONTYPE_FINGER, CONTYPE_WORLD, FingerHandle, FingerModel, SimOptions

__all__ = ["add_chain_finger", "hinge_stiffness", "hinge_axes", "contact_solrefs"]

# Contact stiffness of a block face: a flat punch of the block's width, k_c = E w (N/m), and a
# time constant from the block's mass, tau = 2 pi sqrt(m / k_c), floored at MuJoCo's stable 2 dt.
_CONTACT_DAMPRATIO = 1.0


def hinge_stiffness(design: FingerDesign, young: np.ndarray, model: str = "fem") -> np.ndarray:
    """Hinge stiffness [N m / rad] of every block, shape (n_blocks,), for the stiffness ``model``.

    ``fem``: the inverse of the calibrated FEM's block compliance; ``beam``: k_i = E_i I_i / l_i.
    """
    young = np.asarray(young, dtype=float)
    if model == "fem":
        return 1.0 / block_compliance(design, young)
    return np.array(
        [block_effective_ei(b, e) / b.length for b, e in zip(design.blocks(), young, strict=True)]
    )


def hinge_axes(design: FingerDesign, model: str = "fem") -> np.ndarray:
    """Height of every hinge's axis above the spine's underside [m], shape (n_blocks,).

    ``fem``: the calibrated bending heights; ``beam``: half the section height at the block's middle.
    """
    if model == "fem":
        return calibration_for(design).axis_heights.copy()
    return np.array([_neutral_axis(b) for b in design.blocks()])


def contact_solrefs(blocks: list[Block], young: np.ndarray, density: float, timestep: float) -> np.ndarray:
    """(time constant [s], damping ratio) of every block's contacts from its modulus, shape (n_blocks, 2)."""
    k_c = np.asarray(young, dtype=float) * np.array([b.width for b in blocks])
    mass = np.array([b.volume for b in blocks]) * density
    tau = 2.0 * np.pi * np.sqrt(mass / k_c)
    return np.column_stack([np.maximum(tau, 2.0 * timestep), np.full(len(blocks), _CONTACT_DAMPRATIO)])


def _neutral_axis(block: Block) -> float:
    return 0.5 * float(block.height(block.mid))


def _piece_profile(block: Block, a: float, b: float) -> np.ndarray:
    """Side profile (x, z) of the part of ``block`` between x=a and x=b: a convex polygon."""
    knots = [a, b] + [x for x in (block.x0 + block.cut0, block.x1 - block.cut1) if a < x < b]
    knots = sorted(set(knots))
    top = [(x, float(block.height(x))) for x in knots]
    return np.array([(a, 0.0), (b, 0.0)] + top[::-1])


def _add_piece(
    spec,
    body,
    block: Block,
    a: float,
    b: float,
    origin: float,
    name: str,
    solref,
    friction: float,
    density: float,
) -> None:
    if b - a < 1e-9:
        return
    prof = _piece_profile(block, a, b)
    prof[:, 0] -= origin
    half = 0.5 * block.width
    common = dict(
        contype=CONTYPE_FINGER,
        conaffinity=CONTYPE_WORLD,
        solref=solref,
        friction=[friction, 0.005, 0.0001],
        density=density,
        group=2,
    )
    if block.kind is BlockKind.FLEXURE:
        h = block.height0
        body.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.5 * (b - a), half, 0.5 * h],
            pos=[0.5 * (a + b) - origin, 0, 0.5 * h],
            rgba=[0.85, 0.5, 0.2, 1],
            **common,
        )
        return
    verts = np.vstack([np.c_[prof[:, 0], np.full(len(prof), s), prof[:, 1]] for s in (-half, half)])
    spec.add_mesh(name=name, uservert=verts.ravel().tolist())
    body.add_geom(
        name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, rgba=[0.2, 0.6, 0.85, 1], **common
    )


@dataclass
class _ChainBuilder:
    """Adds one chain finger's bodies, hinges, pieces and sites to a spec, base to tip."""

    spec: mujoco.MjSpec
    design: FingerDesign
    young: np.ndarray
    prefix: str
    options: SimOptions
    handle: FingerHandle
    blocks: list[Block] = field(init=False)
    solrefs: list[tuple[float, float]] = field(init=False)

    def __post_init__(self) -> None:
        self.blocks = self.design.blocks()
        rows = contact_solrefs(self.blocks, self.young, self.design.density, self.options.timestep)
        self.solrefs = [(float(tau), float(ratio)) for tau, ratio in rows]

    def piece(self, body, i: int, a: float, b: float, origin: float, end: str) -> None:
        """Block ``i``'s piece between x=a and x=b on ``body`` (frame at x=origin); ``end`` is p or d."""
        _add_piece(
            self.spec,
            body,
            self.blocks[i],
            a,
            b,
            origin,
            f"{self.prefix}b{i}_{end}",
            self.solrefs[i],
            self.options.friction,
            self.design.density,
        )

    def split(self, i: int) -> bool:
        """Whether block ``i`` is carried by two hinges (``SimOptions.hinges_per_block``)."""
        return self.options.hinges_per_block == 2

    def hinge_points(self, i: int) -> tuple[float, ...]:
        """Where block ``i``'s hinges sit along x: its middle, or a split block's quarter points."""
        blk = self.blocks[i]
        if self.split(i):
            quarter = 0.25 * (blk.x1 - blk.x0)
            return (blk.x0 + quarter, blk.x1 - quarter)
        return (blk.mid,)

    def hinge(self, body, name: str, i: int, k: float, axis: float) -> None:
        """A hinge of block ``i`` at ``body``'s origin, ``k`` [N m/rad] and its Rayleigh damping."""
        body.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[0, -1, 0],
            pos=[0, 0, axis],
            stiffness=float(k),
            damping=float(self.options.damping_time * k),
            armature=self.options.hinge_armature,
        )
        self.handle.joints.append(name)
        self.handle.joint_blocks.append(i)

    def waypoint(self, body, i: int, origin: float, waypoint: np.ndarray) -> None:
        site = body.add_site(
            name=f"{self.prefix}wp{i}",
            pos=waypoint - [origin, 0, 0],
            size=[0.0008, 0, 0],
            rgba=[0.9, 0.1, 0.1, 1],
            group=3,
        )
        self.handle.waypoint_sites.append(site.name)

    def link(self, parent, i: int, origin_prev: float, k: float, axis: float, waypoint: np.ndarray):
        """Block ``i``'s bodies under ``parent`` (frame at x=origin_prev): hinges, pieces, waypoint site.

        Returns the last body and its frame's x.
        """
        blk = self.blocks[i]
        p = self.prefix
        points = self.hinge_points(i)
        k_hinge = k * len(points)  # hinges in series: the block keeps its compliance 1/k
        if len(points) == 2:  # the middle link of a split block carries the waypoint
            mid = parent.add_body(name=f"{p}block{i}m", pos=[points[0] - origin_prev, 0, 0])
            self.hinge(mid, f"{p}hinge{i}m", i, k_hinge, axis)
            self.piece(mid, i, points[0], points[1], points[0], "m")
            self.waypoint(mid, i, points[0], waypoint)
            self.handle.bodies.append(mid.name)
            parent, origin_prev = mid, points[0]
        body = parent.add_body(name=f"{p}block{i}", pos=[points[-1] - origin_prev, 0, 0])
        self.hinge(body, f"{p}hinge{i}", i, k_hinge, axis)
        self.piece(body, i, points[-1], blk.x1, points[-1], "d")
        if i + 1 < len(self.blocks):
            nxt = self.blocks[i + 1]
            self.piece(body, i + 1, nxt.x0, self.hinge_points(i + 1)[0], points[-1], "p")
        if len(points) == 1:
            self.waypoint(body, i, points[-1], waypoint)
        self.handle.bodies.append(body.name)
        return body, points[-1]

    def tip(self, body) -> None:
        """The tip site on the last block's body."""
        last = self.blocks[-1]
        body.add_site(
            name=self.handle.tip_site,
            pos=[
                last.x1 - self.hinge_points(len(self.blocks) - 1)[-1],
                0,
                0.5 * self.design.flexure_thickness,
            ],
            size=[0.0008, 0, 0],
            group=3,
        )


def add_chain_finger(
    spec: mujoco.MjSpec, parent, design: FingerDesign, young: np.ndarray, prefix: str, options: SimOptions
) -> FingerHandle:
    """Add a chain finger under ``parent`` (whose frame is the finger frame) and return its handle."""
    k = hinge_stiffness(design, young, options.stiffness_model)
    axes = hinge_axes(design, options.stiffness_model)
    wps = design.waypoints()
    handle = FingerHandle(
        prefix=prefix,
        model=FingerModel.CHAIN,
        base_body=parent.name,
        waypoint_sites=[],
        tip_site=f"{prefix}tip",
    )
    builder = _ChainBuilder(spec, design, young, prefix, options, handle)
    blocks = builder.blocks
    builder.piece(parent, 0, 0.0, builder.hinge_points(0)[0], 0.0, "p")
    body = parent
    origin_prev = 0.0
    for i in range(len(blocks)):
        body, origin_prev = builder.link(body, i, origin_prev, k[i], axes[i], wps[i])
    builder.tip(body)
    return handle
