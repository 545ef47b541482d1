"""Draw the documentation's picture: the finger's side profile in three designs, blocks coloured by ln E.

Writes ``docs/_static/fingers.png`` (or ``--out``). The profile is the default :class:`FingerDesign`'s
blocks (segment heights, flexure spine, the trapezoid cuts facing the flexures) and its tendon
waypoints; colours run from red (ln E 13.5, soft) through yellow to green (17.0, stiff), as in the Rerun
recordings.

    python3 scripts/finger_figure.py
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mjcodesign.design import LOG_E_MAX, LOG_E_MIN, FingerDesign, Stiffness
from mjcodesign.pipeline import block_outline

DESIGNS = ("soft", "semi-rigid", "paper-optimized")
_MM = 1e3  # the figure's unit: millimetres


def main() -> None:
    """Draw and save the figure."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs/_static/fingers.png"))
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")  # a script of its own: no display
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap
    from matplotlib.patches import Polygon

    design = FingerDesign()
    cmap = LinearSegmentedColormap.from_list("stiffness", ["#d62728", "#f2d12f", "#2ca02c"])
    fig, axes = plt.subplots(len(DESIGNS), 1, figsize=(7.0, 3.6), sharex=True)
    way = np.asarray(design.waypoints()) * _MM
    for ax, name in zip(axes, DESIGNS, strict=True):
        log_e = np.asarray(Stiffness.preset(name).log_e)[0]
        for b in design.blocks():
            c = cmap((log_e[b.index] - LOG_E_MIN) / (LOG_E_MAX - LOG_E_MIN))
            ax.add_patch(Polygon(block_outline(b), closed=True, facecolor=c, edgecolor="0.25", lw=0.6))
        ax.plot(way[:, 0], way[:, 2], "-o", color="0.1", ms=2.0, lw=0.8)
        ax.set_ylim(-1.0, 16.0)
        ax.set_aspect("equal")
        ax.set_yticks([])
        ax.set_ylabel(name, rotation=0, ha="right", va="center")
        for side in ("top", "right", "left"):
            ax.spines[side].set_visible(False)
    axes[-1].set_xlim(-2.0, design.length * _MM + 2.0)
    axes[-1].set_xlabel("along the finger, base to tip [mm]; line: the tendon's waypoints")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(LOG_E_MIN, LOG_E_MAX))
    fig.colorbar(sm, ax=axes, fraction=0.03, pad=0.02, label="ln(E / Pa)")
    fig.savefig(args.out, dpi=110, bbox_inches="tight")
    print(args.out)


if __name__ == "__main__":
    main()
