"""The curl comparison's trajectories as a figure (matplotlib)."""

from __future__ import annotations

import numpy as np

__all__ = ["plot_curves"]


def plot_curves(curves: dict, path: str) -> None:
    """Curl trajectories per model to the PNG ``path``.

    Left: the tip path in the bending plane as the tension rises; right: the bend against the tension.
    ``curves`` maps a model to its ``tension`` [N], ``bend`` [rad] and ``tip`` displacements [m] (3,)
    (the second value of :func:`mjcodesign.crosscheck.crosscheck`). Draws on a bare
    ``matplotlib.figure.Figure`` (Agg), so the process's pyplot backend is left as it is.
    """
    from matplotlib.figure import Figure

    from mjcodesign.errors import DesignError, OutputError

    if not curves:
        raise DesignError("--plot needs the curl scenario (no trajectories to plot)")
    fig = Figure(figsize=(9, 4))
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
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=120)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc}") from exc
