"""Hinge-chain (pseudo-rigid-body) finger.

Each block's bending compliance is lumped into one hinge at the block's midpoint (hinges at block
boundaries overshoot by 12–25%), or into n hinges in series, each n times as stiff
(:attr:`SimOptions.hinges_per_block`: every block's two, or the printed routing's flexures' n). Its
stiffness and axis come from :attr:`SimOptions.stiffness_model`:

* ``fem`` (default): ``k_i = 1 / c_i`` with ``c_i`` block i's rotation per unit moment in the calibrated
  FEM (:func:`mjcodesign.design.calibration.block_compliance`, per design in ~0.1 ms), about an axis at
  the block's fitted bending height (a segment bends at its flexure roots, ~1.4 mm up);
* ``beam``: Euler–Bernoulli, ``k_i = E_i I_i / l_i`` with ``I_i = l_i / ∫ dx / I(x)`` the block's
  series-equivalent section, about the section's mid-height (exact for uniform designs only).

Rigid piece ``k`` spans from block ``k``'s midpoint to block ``k+1``'s midpoint; piece 0's proximal
half belongs to the base. Adjacent pieces are parent and child, so MuJoCo never collides them; the
finger's geoms share one contact bit and never collide with each other. What the printed segments'
contact does is modelled instead by stops: each flexure's hinge, and its gap (its hinge plus its
neighbouring segments' root rotation), end where the flexure's two segments meet (:func:`flexure_stops`).

The tendon (:attr:`SimOptions.tendon_lever`) acts on the hinges with the levers it has on the straight
finger (:attr:`FingerHandle.joint_levers`), as the FEM's tendon does through each block's middle section,
or through the waypoint sites as a spatial tendon. Under the printed routing a flexure's several hinges
may be tied to one angle by joint equalities (:attr:`SimOptions.tied_flexures`, the routing's default).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mjcodesign.design.beam import block_effective_ei
from mjcodesign.design.calibration import block_compliance, calibration_for
from mjcodesign.design.finger import Block, BlockKind, FingerDesign
from mjcodesign.models.types import (
    CONTYPE_FINGER,
    CONTYPE_WORLD,
    FingerHandle,
    FingerModel,
    SimOptions,
    tendon_exit_site,
)

__all__ = [
    "add_chain_finger",
    "hinge_stiffness",
    "hinge_counts",
    "joint_stiffness",
    "hinge_axes",
    "contact_solrefs",
    "flexure_stops",
    "tie_solref",
    "TIE_SOLIMP",
]

# Contact stiffness of a block face: a flat punch of the block's width, k_c = E w (N/m), and a
# time constant from the block's mass, tau = 2 pi sqrt(m / k_c), floored at MuJoCo's stable 2 dt.
_CONTACT_DAMPRATIO = 1.0


TIE_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
"""Solimp of the joint equalities that tie a printed flexure's hinges (:attr:`SimOptions.tied_flexures`).

A constant impedance at MuJoCo's ceiling, 0.9999: a soft constraint held at rest gives way in proportion
to (1 − d)/d, so random:21 curled at 10 N rests with its pairs 5e-6 rad apart (0.99: 6e-4 rad, MuJoCo's
default 0.95: 3e-3 rad). While the finger moves the pairs part by up to ~0.1 rad whatever d is (the
implicit hinge damping acts after the constraint solve; docs/concepts/models.md)."""


def tie_solref(timestep: float) -> list[float]:
    """Solref of the ties of a flexure's hinges: (2 ``timestep`` [s], critical).

    MuJoCo's stiffest stable time constant (it clamps shorter ones to two steps), so the hinges of one
    flexure stay as equal as the step allows.
    """
    return [2.0 * timestep, _CONTACT_DAMPRATIO]


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


_STOP_SCAN = np.radians(5.0)  # first pass over the angle; contact is then bisected to 1e-6 rad


def _first_touch(fixed, moving, origin: tuple[float, float], sign: float) -> float:
    """Smallest rotation [rad] of ``moving`` about ``origin`` that makes it overlap ``fixed``.

    Shapely polygons in side view; towards +z if ``sign`` > 0; π if none does before π.
    """
    from shapely import affinity

    def touches(theta: float) -> bool:
        turned = affinity.rotate(moving, sign * theta, origin=origin, use_radians=True)
        return fixed.intersection(turned).area > 0.0

    lo = 0.0
    for hi in np.arange(_STOP_SCAN, np.pi + 1e-12, _STOP_SCAN):
        if touches(hi):
            break
        lo = hi
    else:
        return float(np.pi)
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if touches(mid) else (mid, hi)
    return float(lo)


@functools.lru_cache(maxsize=32)
def _stops(design: FingerDesign, axes: tuple[float, ...]) -> np.ndarray:
    from shapely.geometry import Polygon

    blocks = design.blocks()
    out = np.full((len(blocks), 2), np.nan)
    for i, blk in enumerate(blocks):
        if blk.kind is not BlockKind.FLEXURE or not 0 < i < len(blocks) - 1:
            continue
        fixed, moving = Polygon(blocks[i - 1].side_profile()), Polygon(blocks[i + 1].side_profile())
        origin = (blk.mid, axes[i])
        out[i] = (-_first_touch(fixed, moving, origin, -1.0), _first_touch(fixed, moving, origin, 1.0))
    return out


def flexure_stops(design: FingerDesign, axes: np.ndarray) -> np.ndarray:
    """Joint range [rad] of every flexure's hinge where its two segments meet, shape (n_blocks, 2).

    A flexure's hinge turns its distal segment about (block middle, ``axes[i]``); the range is where the
    side profile of that segment first overlaps the proximal one's: inwards (positive, the tendon side)
    when the trapezoid cuts close, 1.0-1.6 rad on the default finger; outwards at about 2.7 rad.
    The printed finger's segments stop each other there; the chain's finger geoms never collide with
    one another, so without the stop a tendon with a constant lever folds one flexure round on itself.
    NaN rows: segments (their hinges are the block's own elasticity) and end blocks.
    """
    return _stops(design, tuple(float(a) for a in axes)).copy()


def hinge_counts(design: FingerDesign, options: SimOptions) -> np.ndarray:
    """How many chain hinges carry every block, shape (n_blocks,).

    ``options.hinges_per_block`` each, or under the printed routing each flexure's (the segments, which
    carry its channels, keep one).
    """
    if options.routing != "printed":
        return np.full(design.n_blocks, options.hinges_per_block, dtype=int)
    flexure = np.array([b.kind is BlockKind.FLEXURE for b in design.blocks()])
    return np.where(flexure, options.hinges_per_block, 1)


def joint_stiffness(
    design: FingerDesign, young: np.ndarray, options: SimOptions
) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness [N m / rad] and damping [N m s / rad] of each hinge of every block, shape (n_blocks,) each.

    A block carried by n hinges in series (:func:`hinge_counts`) has each at n k
    (:func:`hinge_stiffness` k), so the block keeps its compliance 1 / k; the damping is Rayleigh,
    ``options.damping_time`` times the hinge's stiffness. The one rule for a model built
    (:func:`add_chain_finger`) and for another design written into a copy of it
    (``mjcodesign.sim.mujoco_c.with_stiffness``).
    """
    k = hinge_stiffness(design, young, options.stiffness_model) * hinge_counts(design, options).astype(float)
    return k, options.damping_time * k


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
    k: np.ndarray = field(init=False)
    """Each hinge's stiffness per block [N m / rad] (:func:`joint_stiffness`)."""
    damping: np.ndarray = field(init=False)
    """Each hinge's damping per block [N m s / rad]."""
    stops: np.ndarray = field(init=False)
    waypoints: np.ndarray = field(init=False)
    counts: np.ndarray = field(init=False)
    """Hinges of every block (:func:`hinge_counts`)."""

    def __post_init__(self) -> None:
        self.blocks = self.design.blocks()
        self.counts = hinge_counts(self.design, self.options)
        self.waypoints = np.asarray(self.design.waypoints(), dtype=float)
        self.stops = flexure_stops(self.design, hinge_axes(self.design, self.options.stiffness_model))
        rows = contact_solrefs(self.blocks, self.young, self.design.density, self.options.timestep)
        self.solrefs = [(float(tau), float(ratio)) for tau, ratio in rows]
        self.k, self.damping = joint_stiffness(self.design, self.young, self.options)

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
        """Whether block ``i`` is carried by two free hinges (the guided ``SimOptions.hinges_per_block=2``)."""
        return self.options.routing != "printed" and self.options.hinges_per_block == 2

    def distributed(self, i: int) -> bool:
        """Whether block ``i`` is a printed chain's flexure carried by several hinges."""
        return self.options.routing == "printed" and self.counts[i] > 1

    def hinge_points(self, i: int) -> tuple[float, ...]:
        """Where block ``i``'s hinges sit along x.

        Its middle, a split block's quarter points, or a distributed flexure's n equal parts' middles.
        """
        blk = self.blocks[i]
        if self.split(i):
            quarter = 0.25 * (blk.x1 - blk.x0)
            return (blk.x0 + quarter, blk.x1 - quarter)
        if self.distributed(i):
            n = int(self.counts[i])
            return tuple(blk.x0 + (blk.x1 - blk.x0) * (j + 0.5) / n for j in range(n))
        return (blk.mid,)

    def hinge(self, body, name: str, i: int, x: float, axis: float) -> None:
        """A hinge of block ``i`` at ``body``'s origin (finger x), with its stiffness and damping."""
        joint = body.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[0, -1, 0],
            pos=[0, 0, axis],
            stiffness=float(self.k[i]),
            damping=float(self.damping[i]),
            armature=self.options.hinge_armature,
        )
        stop = self.hinge_range(i)
        if stop is not None:
            joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
            joint.range = (np.degrees(stop) if self.spec.compiler.degree else stop).tolist()
            joint.solref_limit = self.stop_solref()
        self.handle.joints.append(name)
        self.handle.joint_blocks.append(i)
        self.handle.joint_levers.append(self.lever(x, axis))

    def lever(self, x: float, axis: float) -> float:
        """d(tendon length)/d(angle) [m/rad] of a hinge at (x, axis) about -y on the straight finger.

        Bodies are added base to tip, so the next waypoint is the first one distal to this hinge; only
        the tendon's span into it crosses the hinge: ``dl/dθ = u · (ω × r)``, with ``u`` the span's
        direction, ``ω = -y`` and ``r`` from the hinge to that waypoint. Past the last waypoint (a split
        tip block's distal hinge) the tendon crosses nothing: 0.
        """
        wps = self.waypoints
        n = len(self.handle.waypoint_sites)
        if n == len(wps):
            return 0.0
        distal = wps[n]
        proximal = wps[n - 1] if n else tendon_exit_site(self.design)
        u = (distal - proximal) / np.linalg.norm(distal - proximal)
        r = distal - np.array([x, 0.0, axis])
        return float(u @ np.cross([0.0, -1.0, 0.0], r))

    def waypoint(self, body, i: int, origin: float, waypoint: np.ndarray) -> None:
        site = body.add_site(
            name=f"{self.prefix}wp{i}",
            pos=waypoint - [origin, 0, 0],
            size=[0.0008, 0, 0],
            rgba=[0.9, 0.1, 0.1, 1],
            group=3,
        )
        self.handle.waypoint_sites.append(site.name)

    def link(self, parent, i: int, origin_prev: float, axis: float, waypoint: np.ndarray):
        """Block ``i``'s bodies under ``parent`` (frame at x=origin_prev): hinges, pieces, waypoint site.

        Returns the last body and its frame's x.
        """
        blk = self.blocks[i]
        p = self.prefix
        points = self.hinge_points(i)
        # Middle links between a block's hinges, named m, m1, m2, ...; the one distal to the block's
        # middle carries its waypoint: a split block's only one, link (n-1)//2 of n hinges.
        carrier = (len(points) - 1) // 2
        for j, (x, x_next) in enumerate(zip(points[:-1], points[1:], strict=True)):
            tag = "m" if j == 0 else f"m{j}"
            mid = parent.add_body(name=f"{p}block{i}{tag}", pos=[x - origin_prev, 0, 0])
            self.hinge(mid, f"{p}hinge{i}{tag}", i, x, axis)
            self.piece(mid, i, x, x_next, x, tag)
            if j == carrier:
                self.waypoint(mid, i, x, waypoint)
            self.handle.bodies.append(mid.name)
            parent, origin_prev = mid, x
        body = parent.add_body(name=f"{p}block{i}", pos=[points[-1] - origin_prev, 0, 0])
        self.hinge(body, f"{p}hinge{i}", i, points[-1], axis)
        self.piece(body, i, points[-1], blk.x1, points[-1], "d")
        if i + 1 < len(self.blocks):
            nxt = self.blocks[i + 1]
            self.piece(body, i + 1, nxt.x0, self.hinge_points(i + 1)[0], points[-1], "p")
        if len(points) == 1:
            self.waypoint(body, i, points[-1], waypoint)
        self.handle.bodies.append(body.name)
        return body, points[-1]

    def hinge_range(self, i: int) -> np.ndarray | None:
        """Range [rad] of block ``i``'s single hinge, or None.

        None for a split chain's hinges (free) and a distributed flexure's (held together,
        :meth:`distributed_stops`). A flexure's: where its two segments meet (:func:`flexure_stops`). A segment's hinge is its
        roots' compliance, fitted on small bends; its roots can turn no further than a gap beside them
        can close, so it is held to ± the smaller inward stop of its flexures. Without that bound a
        soft finger pulled at the servo's 52 N turned a segment hinge to 5.3 rad while its flexure
        turned 2.2 rad outwards, each gap within its stop (docs/benchmarks.md, large-bend curl).
        """
        if self.split(i) or self.distributed(i):
            return None
        if self.blocks[i].kind is BlockKind.FLEXURE:
            stop = self.stops[i]
            return stop if np.all(np.isfinite(stop)) else None
        near = [self.stops[j, 1] for j in (i - 1, i + 1) if 0 <= j < len(self.blocks)]
        near = [v for v in near if np.isfinite(v)]
        if not near:
            return None
        return np.array([-min(near), min(near)])

    def stop_solref(self) -> list[float]:
        """Solref of the stops: (2 dt, critical).

        Segments meeting make a contact whose time constant (the blocks' ``contact_solrefs`` rule,
        0.4-3.6 ms over log E 13.5-17) is at or under MuJoCo's stable floor of two steps at the default
        2 ms, so the stops take the floor; design-independent, they need no rewrite when a batch swaps
        designs (``sim.mujoco_c.with_stiffness``).
        """
        return [2.0 * self.options.timestep, _CONTACT_DAMPRATIO]

    def gap_share(self, j: int) -> float:
        """How much of hinge ``j``'s angle closes the gap of a flexure next to it.

        A flexure's all of it; a middle segment's half (it has two flexure roots); an end segment's all
        (its one root).
        """
        if self.blocks[j].kind is BlockKind.FLEXURE or j in (0, len(self.blocks) - 1):
            return 1.0
        return 0.5

    def block_joints(self, i: int) -> list[str]:
        """Block ``i``'s hinge names, base to tip."""
        return [n for n, b in zip(self.handle.joints, self.handle.joint_blocks, strict=True) if b == i]

    def stop_tendon(self, name: str, shares: list[tuple[int, float]], stop: np.ndarray) -> None:
        """A fixed tendon over every hinge of the blocks in ``shares`` (block, weight), held to ``stop``."""
        ten = self.spec.add_tendon(name=f"{self.prefix}{name}")
        for j, share in shares:
            for joint in self.block_joints(j):
                ten.wrap_joint(joint, share)
        ten.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        ten.range = stop.tolist()
        ten.solref_limit = self.stop_solref()

    def distributed_stops(self) -> None:
        """Every distributed flexure's stop: the sum of its hinges held to :func:`flexure_stops`.

        As a single hinge's range holds its angle.
        """
        for i in range(1, len(self.blocks) - 1):
            if self.distributed(i) and np.all(np.isfinite(self.stops[i])):
                self.stop_tendon(f"flex{i}", [(i, 1.0)], self.stops[i])

    def tie_flexures(self) -> None:
        """Every distributed flexure's hinges tied to one angle (:attr:`SimOptions.tied_flexures`).

        A joint equality per consecutive pair, ``θ_j − θ_{j+1} = 0`` (polynomial 0 + 1·θ_{j+1}), as stiff as
        :func:`tie_solref` and :data:`TIE_SOLIMP` make it.
        """
        if not self.options.tied_flexures:
            return
        for i in range(len(self.blocks)):
            if not self.distributed(i):
                continue
            joints = self.block_joints(i)
            for j, (a, b) in enumerate(zip(joints[:-1], joints[1:], strict=True)):
                eq = self.spec.add_equality(name=f"{self.prefix}tie{i}_{j}")
                eq.type = mujoco.mjtEq.mjEQ_JOINT
                eq.name1, eq.name2 = a, b
                eq.data[:5] = [0.0, 1.0, 0.0, 0.0, 0.0]
                eq.solref = tie_solref(self.options.timestep)
                eq.solimp = list(TIE_SOLIMP)

    def gap_stops(self) -> None:
        """Limited fixed tendons that stop every flexure's gap where its segments meet.

        A segment's hinge lumps the rotation at its two flexure roots (the calibrated bending axis
        sits 1.4 mm up, at the roots' height), so the gap across flexure ``i`` closes by
        ``θ_i + w (θ_{i-1} + θ_{i+1})`` (:meth:`gap_share`: w = 1/2, or 1 for an end segment's one root;
        θ_i the sum of a distributed flexure's hinges); that sum is held to :func:`flexure_stops`
        (:meth:`stop_solref`). Without it, the segments beside a flexure held at its stop bend on,
        3-14 rad for a soft finger at 10 N in free space. A split chain is left free.
        """
        for i in range(1, len(self.blocks) - 1):
            stop = self.stops[i]
            if not np.all(np.isfinite(stop)) or any(self.split(j) for j in (i - 1, i, i + 1)):
                continue
            self.stop_tendon(f"gap{i}", [(j, self.gap_share(j)) for j in (i - 1, i, i + 1)], stop)

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


def _add_channels(builder: _ChainBuilder, bodies: list, origins: list[float], axes: np.ndarray) -> None:
    """The printed routing's sites in the handle's chain: channel entries, middles and exits, flexure guides.

    ``bodies[i]`` carries block i's proximal half (the finger's parent for block 0, frame at x = 0) and
    ``bodies[i + 1]`` its middle and distal half (frame at x = ``origins[i + 1]``, its last hinge: a
    segment's middle): the entry rides on the body before the segment's hinge, the middle (just past the
    hinge, as the channel guides the tendon through the segment) and the exit on the one after it.
    Between one segment's exit and the next one's entry the tendon crosses its flexure's hinges alone: a
    flexure of one hinge through its guides on the chord (:func:`~mjcodesign.models.channels.flexure_guides`,
    on the bodies before and after the hinge), so that the hinge buckles as the flexure bending along its
    length; a flexure of several hinges bends along its length itself and is crossed from exit to entry.
    """
    from mjcodesign.models.channels import channel_points, flexure_guides

    segments = [b.index for b in builder.blocks if b.kind is BlockKind.SEGMENT]
    guides = flexure_guides(builder.design, axes)
    sites = []

    def add(k: int, name: str, point: np.ndarray) -> None:
        site = bodies[k].add_site(
            name=f"{builder.prefix}{name}",
            pos=point - [origins[k], 0.0, 0.0],
            size=[0.0006, 0, 0],
            rgba=[0.9, 0.6, 0.1, 1],
            group=3,
        )
        sites.append(site.name)

    for j, (i, points) in enumerate(zip(segments, channel_points(builder.design), strict=True)):
        for end, point, k in zip(("in", "mid", "out"), points, (i, i + 1, i + 1), strict=True):
            add(k, f"ch{i}_{end}", point)
        f = i + 1  # the flexure after this segment
        if j < len(guides) and builder.counts[f] == 1:
            add(f, f"guide{f}_p", guides[j, 0])
            add(f + 1, f"guide{f}_d", guides[j, 1])
    builder.handle.site_chains = [sites]


def add_chain_finger(
    spec: mujoco.MjSpec, parent, design: FingerDesign, young: np.ndarray, prefix: str, options: SimOptions
) -> FingerHandle:
    """Add a chain finger under ``parent`` (whose frame is the finger frame) and return its handle.

    With :attr:`SimOptions.routing` ``printed`` the handle's ``site_chains`` hold the channel sites the
    native tendon runs through; its ``waypoint_sites`` stay the design's waypoints.
    """
    axes = hinge_axes(design, options.stiffness_model)
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
    bodies = [parent]
    origin_prev = 0.0
    origins = [origin_prev]
    for i in range(len(blocks)):
        body, origin_prev = builder.link(body, i, origin_prev, axes[i], builder.waypoints[i])
        bodies.append(body)
        origins.append(origin_prev)
    if options.routing == "printed":
        _add_channels(builder, bodies, origins, axes)
    builder.distributed_stops()
    builder.tie_flexures()
    builder.gap_stops()
    builder.tip(body)
    return handle
