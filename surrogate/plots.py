"""The report's figures: learning curves, success calibration, and the smoothness lines (PNG, matplotlib)."""

from __future__ import annotations

from pathlib import Path

from mjcodesign.outputs import new_figure, save_figure

__all__ = ["plot_calibration", "plot_curves", "plot_lines"]

_DPI = 110
_LINES_SHOWN = 6


def _figure(figsize: tuple[float, float]):
    return new_figure(
        figsize, unavailable="the surrogate's report needs matplotlib (pip install 'mjcodesign[torch]')"
    )


def _save(fig, path: Path) -> Path:
    return save_figure(fig, path, dpi=_DPI)


def plot_curves(runs: dict[str, dict], path: Path) -> Path:
    """Training and validation loss per epoch of each run (``name -> TrainResult.summary()``)."""
    fig = _figure((7, 4.5))
    ax = fig.subplots()
    for name, s in runs.items():
        line = ax.plot(s["train_loss"], ls="--", lw=1, label=f"{name}: train")[0]
        ax.plot(s["val_loss"], color=line.get_color(), lw=1.5, label=f"{name}: validation")
        ax.axvline(s["best_epoch"], color=line.get_color(), ls=":", lw=1)
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss (L1 on z-scored outputs, contact BCE; mean of 10)")
    ax.set_yscale("log")
    ax.legend(fontsize="small")
    return _save(fig, path)


def plot_calibration(models: dict[str, list[dict]], path: Path) -> Path:
    """Reliability diagram of the calibrated success probability on the test rows, one line per model."""
    fig = _figure((5, 5))
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], color="0.6", ls=":", lw=1)
    for name, bins in models.items():
        if bins:
            ax.plot([b["predicted"] for b in bins], [b["observed"] for b in bins], marker="o", label=name)
    ax.set_xlabel("predicted success probability (Platt on validation)")
    ax.set_ylabel("simulator success rate")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(fontsize="small")
    return _save(fig, path)


def plot_lines(result: dict, path: Path) -> Path:
    """L_opt along the smoothness lines: the surrogate beside the simulator."""
    rows = result["lines"][:_LINES_SHOWN]
    fig = _figure((3.2 * max(1, len(rows)), 3.4))
    axes = fig.subplots(1, max(1, len(rows)), squeeze=False)
    for ax, r in zip(axes[0], rows, strict=False):
        ax.plot(r["t"], r["simulator_loss"], marker="o", label="simulator")
        ax.plot(r["t"], r["surrogate_loss"], marker=".", label="surrogate")
        ax.set_yscale("symlog", linthresh=1e-2)
        ax.set_title(f"{r['object']} p{r['pose_row']} line {r['line']}", fontsize="small")
        ax.set_xlabel("t along the line [ln E]")
    axes[0][0].set_ylabel("L_opt")
    axes[0][0].legend(fontsize="small")
    return _save(fig, path)
