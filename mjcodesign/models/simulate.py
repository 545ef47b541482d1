"""Stepping with solver-warning checks: a warning is a failure, never ignored."""

from __future__ import annotations

import mujoco
import numpy as np

from mjcodesign.errors import SimulationDiverged

__all__ = ["check_state", "has_warning", "reset_warnings"]

_FATAL_WARNINGS = (
    mujoco.mjtWarning.mjWARN_INERTIA,  # also raised when the flex M+K solve under-converges
    mujoco.mjtWarning.mjWARN_CONTACTFULL,
    mujoco.mjtWarning.mjWARN_CNSTRFULL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADCTRL,
)


def reset_warnings(d: mujoco.MjData) -> None:
    """Clear the warning counters of ``d``."""
    for w in _FATAL_WARNINGS:
        d.warning[w].number = 0


def _first_warning(d: mujoco.MjData):
    """The first of the warnings that fail a rollout that ``d`` holds, or None."""
    return next((w for w in _FATAL_WARNINGS if d.warning[w].number > 0), None)


def has_warning(d: mujoco.MjData) -> bool:
    """Whether ``d`` holds any of the warnings that fail a rollout."""
    return _first_warning(d) is not None


def check_state(d: mujoco.MjData, context: str = "") -> None:
    """Raise :class:`SimulationDiverged` if MuJoCo warned or the state is not finite."""
    w = _first_warning(d)
    if w is not None:
        name = mujoco.mjtWarning(w).name.removeprefix("mjWARN_")
        hint = {
            "INERTIA": "under-converged M+K solve or singular inertia: raise iterations or lower the timestep",
            "BADQACC": "acceleration blew up: lower the timestep",
        }.get(name, "")
        raise SimulationDiverged(
            f"{context}MuJoCo warning {name} at t={d.time:.4f} s" + (f" ({hint})" if hint else "")
        )
    if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
        raise SimulationDiverged(f"{context}state is not finite at t={d.time:.4f} s")
