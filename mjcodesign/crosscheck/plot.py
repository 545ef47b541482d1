"""The curl comparison's trajectories as a figure (matplotlib)."""

from __future__ import annotations

import numpy as np

from mjcodesign.errors import DesignError
from mjcodesign.outputs import new_figure, save_figure

__all__ = ["plot_curves"]

_DPI = 120


def plot_curves(curves: dict, path: str) -> None:
    """Curl trajectories per model to the PNG ``path``.

    Left: the tip path in the bending plane as the tension rises; right: the bend against the tension.
    ``curves`` maps a model to its ``tension`` [N], ``bend`` [rad] and ``tip`` displacements [m] (3,)
    (the second value of :func:`mjcodesign.crosscheck.crosscheck`), on a bare figure
    (:func:`mjcodesign.outputs.new_figure`: no pyplot state).
    """
    if not curves:
        raise DesignError("--plot needs the curl scenario (no trajectories to plot)")
    fig = new_figure((9, 4), unavailable="--plot needs matplotlib (pip install matplotlib)")
    ax_tip, ax_bend = fig.subplots(1, 2)
    for name, c in curves.items():
        tip = 1e3 * np.array([[0.0, 0.0, 0.0]] + [list(v) for v in c["tip"]])
        ax_tip.plot(tip[:, 0], tip[:, 2], "o-", label=name)
        ax_bend.plot(c["tension"], np.degrees(c["bend"]), "o-", label=name)
    ax_tip.set_xlabel("tip Δx [mm]")
    ax_tip.set_ylabel("tip Δz [mm]")
    ax_tip.set_title("tip path, tension rising from 0")
    ax_tip.set_aspect("equal", adjustable="datalim")
    ax_bend.set_xlabel("tendon tension [N]")
    ax_bend.set_ylabel("total bend [deg]")
    ax_bend.legend()
    save_figure(fig, path, dpi=_DPI)
