"""The printed finger's tendon channels: where its tendon runs through each segment.

The authors' printed finger (``hardware/sim_finger.stl`` of their codesign-soft-gripper repository,
20 × 14 × 136.35 mm) has a straight 1.2 × 1.2 mm channel through each of its six segments and nothing
above its flexures: every flexure is the bare 2 mm spine, so the tendon crosses each gap in air,
straight from one segment's channel exit to the next one's entry. Sliced every 0.05 mm along its
length, each channel's centre lies on a line (largest residual 0.08 mm); :data:`PRINTED_CHANNELS` keeps
each line as its height above the finger's back at the default design's segment middle and its slope.

:func:`channel_points` places those lines on a design: a channel enters where its line meets the
segment's proximal face (the base face for the first segment, the trapezoid cut otherwise) and leaves
where it meets the distal one (the tip face for the last). On the default design these ends lie within 0.53 mm of
where the STL's channels open (its segment ends are rounded, the design's cuts straight).

:func:`flexure_guides` places the chain's guides across each flexure: its one hinge buckles under the
tendon as the flexure does bending along its length.
"""

from __future__ import annotations

import functools

import numpy as np

from mjcodesign.design.finger import Block, BlockKind, FingerDesign
from mjcodesign.errors import DesignError

__all__ = ["PRINTED_CHANNELS", "channel_points", "flexure_guides"]

PRINTED_CHANNELS = np.array(
    [
        (12.13e-3, -0.1548),
        (8.77e-3, -0.1255),
        (6.10e-3, -0.0962),
        (4.14e-3, -0.0672),
        (2.88e-3, -0.0387),
        (2.31e-3, -0.0105),
    ]
)
"""Channel centre of each segment, base to tip: (height above the finger's back at the default design's
segment middle [m], slope dz/dx along the finger [-]); the channels enter 13.37, 9.59, 6.79, 4.65, 3.19
and 2.39 mm up and leave 11.16, 7.92, 5.42, 3.65, 2.59 and 2.23 mm up. Measured on ``sim_finger.stl``."""

_BISECT = 1e-9  # channel-face crossing found to 1 nm along x [m]


def _crossing(block: Block, line, lo: float, hi: float) -> float:
    """Where [m] in [lo, hi] the block's top meets the channel ``line`` (lo may lie past hi)."""
    below = float(block.height(lo)) < line(lo)  # the cut face's foot lies under the channel
    if below == (float(block.height(hi)) < line(hi)):
        raise DesignError(f"the printed tendon channel misses segment {block.index}'s cut face")
    while abs(hi - lo) > _BISECT:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if (float(block.height(mid)) < line(mid)) == below else (lo, mid)
    return 0.5 * (lo + hi)


def channel_points(design: FingerDesign) -> np.ndarray:
    """Entry, middle and exit of every segment's channel in the finger frame [m], shape (n_segments, 3, 3).

    Only the printed finger's six segments have measured channels: :class:`DesignError` for another
    count, or where a channel would leave its segment (above its top, or into the spine).
    """
    segments = [b for b in design.blocks() if b.kind is BlockKind.SEGMENT]
    if len(segments) != len(PRINTED_CHANNELS):
        raise DesignError(
            f"the printed routing is measured on the {len(PRINTED_CHANNELS)}-segment printed finger; "
            f"this design has {len(segments)} segments"
        )
    ref_mids = [b.mid for b in FingerDesign().blocks() if b.kind is BlockKind.SEGMENT]
    out = np.zeros((len(segments), 3, 3))
    for k, (blk, (h, slope), ref) in enumerate(zip(segments, PRINTED_CHANNELS, ref_mids, strict=True)):

        def line(x, h=h, slope=slope, ref=ref):
            return h + slope * (x - ref)

        if not (blk.spine < line(blk.mid) < float(blk.height(blk.mid))):
            raise DesignError(f"the printed tendon channel lies outside segment {blk.index}")
        x_in = blk.x0 if blk.cut0 == 0 else _crossing(blk, line, blk.x0, blk.x0 + blk.cut0)
        x_out = blk.x1 if blk.cut1 == 0 else _crossing(blk, line, blk.x1, blk.x1 - blk.cut1)
        for j, x in enumerate((x_in, blk.mid, x_out)):
            out[k, j] = (x, 0.0, line(x))
    return out


def flexure_guides(design: FingerDesign, axes: np.ndarray) -> np.ndarray:
    """The tendon's two guides across each flexure in the finger frame [m], shape (n_segments − 1, 2, 3).

    The tendon runs straight from one segment's channel exit A to the next one's entry B. Along that chord
    (unit vector t), the flexure's hinge (block middle, height ``axes[i]`` above the back) has the foot of
    its perpendicular α from A and β from B, so a hinge there buckles at k (α+β)/(αβ)
    (:mod:`mjcodesign.models.stability`); the flexure bending along its length, its ends' feet on the
    chord, at :func:`~mjcodesign.models.stability.beam_string_buckling_tension`, r times that (geometry
    alone: k cancels). The guides lie on the chord α/r before the foot and β/r after it,
        P = A + α (1 − 1/r) t,   Q = B − β (1 − 1/r) t,
    so the one hinge between them buckles at the flexure's tension; on the straight finger the tendon's
    path, length and every hinge's lever are the chord's. r is 1.74, 1.86, 2.01, 2.18 and 2.33 on the
    default finger's flexures, base to tip; :class:`DesignError` where a flexure's feet leave the chord.
    """
    return _guides(design, tuple(float(h) for h in axes)).copy()


@functools.lru_cache(maxsize=32)
def _guides(design: FingerDesign, axes: tuple[float, ...]) -> np.ndarray:
    """:func:`flexure_guides` with the axes as a tuple, cached per design (builds of a batch share it)."""
    from mjcodesign.models.stability import beam_string_buckling_tension

    points = channel_points(design)
    flexures = [b for b in design.blocks() if b.kind is BlockKind.FLEXURE]  # one between two segments
    out = np.zeros((len(flexures), 2, 3))
    for j, blk in enumerate(flexures):
        a, b = points[j, 2], points[j + 1, 0]
        span = float(np.linalg.norm(b - a))
        t = (b - a) / span

        def foot(x: float, blk=blk, a=a, t=t) -> float:
            """Distance [m] along the chord from A to the foot of the flexure's axis point at ``x``."""
            return float((np.array([x, 0.0, axes[blk.index]]) - a) @ t)

        alpha = foot(blk.mid)
        beta = span - alpha
        ratio = beam_string_buckling_tension(1.0, foot(blk.x0), foot(blk.x1), 0.0, span) * (
            alpha * beta / span
        )
        shrink = 1.0 - 1.0 / ratio
        out[j] = (a + alpha * shrink * t, b - beta * shrink * t)
    return out
