"""What a co-design run writes: the design file, each object's pose file, the loss curves (PNG).

The design file holds the 22 ln E as one comma-separated line, the text every ``--design`` takes
(:meth:`~mjcodesign.design.stiffness.Stiffness.parse`). A pose file is the JSON that ``grasp --pose``
reads: ``{"pose": 4x4 palm pose [m], "openings": [s1, s2] [m]}``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mjcodesign.codesign.optimize import OptimizeResult
from mjcodesign.codesign.problem import PoseSet
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import OutputError
from mjcodesign.outputs import new_figure, save_figure

__all__ = ["design_text", "plot_curves", "pose_record", "write_design", "write_json", "write_pose"]

_DPI = 110
_LEGEND_MAX = 12  # objects named in the legend; more would hide the curves


def design_text(log_e) -> str:
    """22 ln E as the comma-separated line ``--design`` parses (6 decimals: 1e-6 of ln E is 1 ppm of E)."""
    Stiffness(log_e)  # refuses a value outside the printable range
    return ",".join(f"{v:.6f}" for v in np.asarray(log_e, dtype=float).ravel())


def _write(path: Path, text: str) -> Path:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path


def write_json(path: Path, record: dict) -> Path:
    """``record`` as indented JSON."""
    return _write(Path(path), json.dumps(record, indent=1) + "\n")


def write_design(path: Path, log_e) -> Path:
    """The design file (module docstring)."""
    return _write(Path(path), design_text(log_e) + "\n")


def pose_record(poses: PoseSet, row: int) -> dict:
    """Pose ``row`` as ``grasp --pose`` JSON reads it."""
    return {"pose": poses.palms[row].tolist(), "openings": poses.openings[row].tolist()}


def write_pose(path: Path, poses: PoseSet, row: int) -> Path:
    """A pose file (module docstring)."""
    return _write(Path(path), json.dumps(pose_record(poses, row)) + "\n")


def plot_curves(result: OptimizeResult, path: Path) -> Path:
    """Counted L_opt per object and in total against the iteration (log scale), as a PNG."""
    fig = new_figure((11, 4), unavailable="the loss curves need matplotlib (pip install 'mjcodesign[torch]')")
    a, b = fig.subplots(1, 2)
    it = np.arange(1, result.iterations + 1)
    for k, name in enumerate(result.objects):
        a.plot(it, np.maximum(result.curves[:, k], 1e-12), lw=0.8, label=name if k < _LEGEND_MAX else None)
    a.set(yscale="log", xlabel="iteration", ylabel="counted L_opt", title="per object")
    if len(result.objects) <= _LEGEND_MAX:
        a.legend(fontsize=6)
    b.plot(it, np.maximum(result.total_curve, 1e-12), color="k")
    b.set(yscale="log", xlabel="iteration", ylabel="Σ counted L_opt", title=f"total ({result.mode.value})")
    return save_figure(fig, path, dpi=_DPI)
