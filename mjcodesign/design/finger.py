"""Flexure-finger geometry and tendon routing.

A finger is a chain of blocks, base to tip: segment, flexure, segment, ..., segment. The paper's finger
has 6 segments and 5 flexures (11 blocks). Frame of one finger (the *finger frame*):

* ``x`` runs along the finger, base face at ``x = 0``, tip face at ``x = L``;
* ``y`` runs across the width, centred (``-w/2 .. w/2``);
* ``z`` is the bending direction. The continuous spine (the flexures) lies at ``0 <= z <= t``; segment
  blocks rise to their height ``h(x)``. ``+z`` is the inner (grasping) side: pulling the tendon closes
  the trapezoidal gaps between segments and curls the finger towards ``+z``.

Segment blocks are trapezoids in side view: their top face is shorter than their bottom by ``cut`` at
every end that faces a flexure, which opens the V-shaped gaps that let the finger curl. Heights taper
linearly from ``height_base`` at the base to ``height_tip`` at the tip, as on the printed finger.

All lengths are metres.
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass

import numpy as np

from mjcodesign.errors import DesignError

__all__ = ["BlockKind", "Block", "Routing", "FingerDesign"]

# Envelope of the authors' printed finger, hardware/sim_finger.stl: 20 x 14 x 136.35 mm
# (width x height x length). The default design matches it.
_PAPER_LENGTH = 0.13635
_PAPER_WIDTH = 0.020
_PAPER_HEIGHT = 0.014
# Measured on the STL: segment tops fall from 14 mm at the base to about 6 mm at the tip.
_PAPER_HEIGHT_TIP = 0.006
# Thin flexures, 2 mm (paper, NOTES); the gap between segments widens from 8 mm at the spine to about
# 13 mm at the top, i.e. a 2.5 mm trapezoid cut per segment end.
_PAPER_FLEXURE_THICKNESS = 0.002
_PAPER_CUT = 0.0025
# Tendon height scale H of the uniform-pressure law, measured from the flexures' neutral plane.
# 12 mm keeps the first waypoint 1 mm inside the base segment.
_PAPER_TENDON_HEIGHT = 0.012
# Uniform-height routing, for comparison: 4 mm fits inside the 6 mm tip segment.
_UNIFORM_HEIGHT = 0.004
# TPU 95A density [kg/m^3].
_TPU_DENSITY = 1210.0
# Waypoints must stay this far below a segment's top face [m].
_WAYPOINT_MARGIN = 5e-4


class BlockKind(enum.Enum):
    """Kind of block in the finger chain."""

    SEGMENT = "segment"
    FLEXURE = "flexure"


class Routing(enum.Enum):
    """Tendon routing law."""

    UNIFORM_PRESSURE = "uniform-pressure"
    """h_i = H (1 - l_i / L)^2: the tendon moment grows like the moment of a uniform pressure."""
    UNIFORM_HEIGHT = "uniform-height"
    """h_i = const: a constant moment along the finger (the tip curls first in contact)."""


@dataclass(frozen=True)
class Block:
    """One block of the finger, in the finger frame [m]."""

    index: int
    kind: BlockKind
    x0: float
    """Proximal face position along the finger [m]."""
    x1: float
    """Distal face position along the finger [m]."""
    height0: float
    """Height of the block's top face at its proximal end, before the trapezoid cut [m]."""
    height1: float
    """Height at its distal end, before the trapezoid cut [m]."""
    cut0: float
    """Trapezoid cut at the proximal end, along x [m] (0 at the base face)."""
    cut1: float
    """Trapezoid cut at the distal end, along x [m] (0 at the tip face)."""
    width: float
    """Block width [m]."""
    spine: float = 0.002
    """Flexure (spine) thickness that the trapezoid cuts run down to [m]."""

    @property
    def length(self) -> float:
        """Length along the finger [m]."""
        return self.x1 - self.x0

    @property
    def mid(self) -> float:
        """Midpoint along the finger [m]."""
        return 0.5 * (self.x0 + self.x1)

    def height(self, x: np.ndarray | float) -> np.ndarray:
        """Section height [m] at positions ``x`` inside the block, with the trapezoid cut applied."""
        x = np.asarray(x, dtype=float)
        s = np.clip((x - self.x0) / self.length, 0.0, 1.0)
        h = self.height0 + (self.height1 - self.height0) * s
        if self.kind is BlockKind.FLEXURE:
            return h
        t = self.spine
        # Inside a cut, the top falls linearly from the full height to the spine thickness.
        if self.cut0 > 0:
            f0 = np.clip((x - self.x0) / self.cut0, 0.0, 1.0)
            h = np.minimum(h, t + (h - t) * f0)
        if self.cut1 > 0:
            f1 = np.clip((self.x1 - x) / self.cut1, 0.0, 1.0)
            h = np.minimum(h, t + (h - t) * f1)
        return h

    def side_profile(self) -> np.ndarray:
        """Convex side-view polygon (x, z) of the block, counter-clockwise, shape (n, 2) [m]."""
        if self.kind is BlockKind.FLEXURE:
            return np.array(
                [[self.x0, 0.0], [self.x1, 0.0], [self.x1, self.height1], [self.x0, self.height0]]
            )
        t = self.spine
        pts = [[self.x0, 0.0], [self.x1, 0.0]]
        if self.cut1 > 0:
            pts.append([self.x1, t])
            pts.append([self.x1 - self.cut1, float(self.height(self.x1 - self.cut1))])
        else:
            pts.append([self.x1, self.height1])
        if self.cut0 > 0:
            pts.append([self.x0 + self.cut0, float(self.height(self.x0 + self.cut0))])
            pts.append([self.x0, t])
        else:
            pts.append([self.x0, self.height0])
        return np.array(pts, dtype=float)

    def vertices(self) -> np.ndarray:
        """Vertices of the block's convex prism in the finger frame, shape (2n, 3) [m]."""
        p = self.side_profile()
        half = 0.5 * self.width
        lo = np.c_[p[:, 0], np.full(len(p), -half), p[:, 1]]
        hi = np.c_[p[:, 0], np.full(len(p), half), p[:, 1]]
        return np.vstack([lo, hi])

    @functools.cached_property  # a frozen block: computed once (model copies read it per design)
    def volume(self) -> float:
        """Volume [m^3] (side-profile area times width)."""
        p = self.side_profile()
        x, z = p[:, 0], p[:, 1]
        area = 0.5 * abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)))
        return float(area * self.width)


@dataclass(frozen=True)
class FingerDesign:
    """Geometry of one flexure finger; both fingers of the gripper share it.

    The default is the paper's printed finger: 6 segments and 5 flexures, 136.35 mm long, 20 mm wide and
    14 mm high at the base. With ``flexure_length=None`` the flexures take ``L / (2 n_s + n_f)`` and
    segments twice that, which puts every block boundary on a uniform grid of ``2 n_s + n_f`` cells
    (the flex model's interpolation grid).
    """

    n_segments: int = 6
    length: float = _PAPER_LENGTH
    width: float = _PAPER_WIDTH
    height_base: float = _PAPER_HEIGHT
    height_tip: float = _PAPER_HEIGHT_TIP
    flexure_thickness: float = _PAPER_FLEXURE_THICKNESS
    flexure_length: float | None = None
    cut: float = _PAPER_CUT
    tendon_height: float = _PAPER_TENDON_HEIGHT
    uniform_height: float = _UNIFORM_HEIGHT
    routing: Routing = Routing.UNIFORM_PRESSURE
    density: float = _TPU_DENSITY

    def __post_init__(self) -> None:
        if isinstance(self.routing, str):
            try:
                object.__setattr__(self, "routing", Routing(self.routing))
            except ValueError as exc:
                raise DesignError(f"unknown routing {self.routing!r}") from exc
        if int(self.n_segments) != self.n_segments or self.n_segments < 2:
            raise DesignError(f"n_segments must be an integer >= 2, got {self.n_segments}")
        for name in (
            "length",
            "width",
            "height_base",
            "height_tip",
            "flexure_thickness",
            "density",
        ):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise DesignError(f"{name} must be positive and finite, got {v}")
        for name in ("cut", "tendon_height", "uniform_height"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise DesignError(f"{name} must be non-negative and finite, got {v}")
        if self.height_tip > self.height_base:
            raise DesignError("height_tip must not exceed height_base")
        if self.flexure_thickness >= self.height_tip:
            raise DesignError("flexure_thickness must be below height_tip")
        lf = self.flexure_len
        ls = self.segment_length
        if not (lf > 0 and ls > 0):
            raise DesignError(f"blocks do not fit: flexure {lf * 1e3:.2f} mm, segment {ls * 1e3:.2f} mm")
        if 2 * self.cut >= ls:
            raise DesignError("trapezoid cut must be shorter than half a segment")
        tops = self.waypoints()[:, 2]
        for b, z in zip(self.blocks(), tops, strict=True):
            if b.kind is BlockKind.SEGMENT and z > float(b.height(b.mid)) - _WAYPOINT_MARGIN:
                raise DesignError(
                    f"tendon waypoint {b.index} at {z * 1e3:.2f} mm lies outside its segment "
                    f"({float(b.height(b.mid)) * 1e3:.2f} mm high); lower tendon_height"
                )

    # -- blocks ---------------------------------------------------------------------------------
    @property
    def n_flexures(self) -> int:
        """Number of flexures (one between each pair of segments)."""
        return self.n_segments - 1

    @property
    def n_blocks(self) -> int:
        """Blocks per finger (segments plus flexures)."""
        return 2 * self.n_segments - 1

    @property
    def flexure_len(self) -> float:
        """Flexure length along the finger [m]."""
        if self.flexure_length is not None:
            return float(self.flexure_length)
        return self.length / (2 * self.n_segments + self.n_flexures)

    @property
    def segment_length(self) -> float:
        """Segment length along the finger [m], equal for all segments."""
        return (self.length - self.n_flexures * self.flexure_len) / self.n_segments

    def height_at(self, x: np.ndarray | float) -> np.ndarray:
        """Untruncated segment height [m] of the linear taper at ``x``."""
        x = np.asarray(x, dtype=float)
        return self.height_base + (self.height_tip - self.height_base) * x / self.length

    def blocks(self) -> list[Block]:
        """The finger's blocks, base to tip."""
        out: list[Block] = []
        x = 0.0
        t = self.flexure_thickness
        for i in range(self.n_blocks):
            seg = i % 2 == 0
            ln = self.segment_length if seg else self.flexure_len
            x1 = self.length if i == self.n_blocks - 1 else x + ln
            if seg:
                h0, h1 = float(self.height_at(x)), float(self.height_at(x1))
                c0 = self.cut if i > 0 else 0.0
                c1 = self.cut if i < self.n_blocks - 1 else 0.0
                kind = BlockKind.SEGMENT
            else:
                h0 = h1 = t
                c0 = c1 = 0.0
                kind = BlockKind.FLEXURE
            out.append(Block(i, kind, x, x1, h0, h1, c0, c1, self.width, spine=t))
            x = x1
        return out

    # -- tendon ---------------------------------------------------------------------------------
    def waypoint_heights(self) -> np.ndarray:
        """Tendon height above the flexures' neutral plane at each block midpoint [m], (n_blocks,)."""
        mids = np.array([b.mid for b in self.blocks()])
        if self.routing is Routing.UNIFORM_PRESSURE:
            return self.tendon_height * (1.0 - mids / self.length) ** 2
        return np.full(mids.shape, self.uniform_height)

    def waypoints(self) -> np.ndarray:
        """Tendon waypoints in the finger frame, one per block midpoint, shape (n_blocks, 3) [m]."""
        mids = np.array([b.mid for b in self.blocks()])
        z = 0.5 * self.flexure_thickness + self.waypoint_heights()
        return np.c_[mids, np.zeros_like(mids), z]

    def tendon_exit(self) -> np.ndarray:
        """Where the tendon leaves the finger at the base face, towards the motor [m], shape (3,)."""
        return np.array([0.0, 0.0, float(self.waypoints()[0, 2])])

    # -- mass -----------------------------------------------------------------------------------
    @property
    def mass(self) -> float:
        """Mass of one finger [kg]."""
        return float(sum(b.volume for b in self.blocks()) * self.density)

    @property
    def envelope(self) -> tuple[float, float, float]:
        """(width, height, length) of the bounding box [m]."""
        return (self.width, self.height_base, self.length)

    def replace(self, **changes) -> FingerDesign:
        """A copy with some fields changed (validated)."""
        from dataclasses import replace

        return replace(self, **changes)
