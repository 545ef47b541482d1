"""Stepping with solver-warning checks: a warning is a failure, never ignored, and never printed.

MuJoCo prints the first warning of each kind per ``MjData`` to stdout and appends it to
``MUJOCO_LOG.TXT`` in the working directory, and ``mujoco.rollout`` clears the counters of its data
before every rollout, so a batch printed one line per thread. :func:`captured_warnings` routes MuJoCo's
warning callback into a list while a rollout runs (the one process-wide hook the library sets: it is
installed on entry and the previous handler restored on exit, under a lock, nested uses sharing it), so
the backends count the warnings into a ``DIVERGED`` outcome instead. A capture takes the warnings of its
own thread and of threads Python did not start (``mujoco.rollout``'s pool), never those of another Python
thread: one rollout's warning is not another's, whatever else the process runs beside it.
"""

from __future__ import annotations

import contextlib
import sys
import threading
from collections.abc import Iterator

import mujoco
import numpy as np

from mjcodesign.errors import SimulationDiverged

__all__ = ["check_state", "has_warning", "reset_warnings", "captured_warnings", "warning_counts"]

_CAPTURE_LOCK = threading.Lock()
_CAPTURES: list[tuple[int, list[str]]] = []  # (the capturing thread's ident, its log)
_SAVED_HANDLER: list = []


def _python_thread(ident: int) -> bool:
    """Whether ``ident`` is a thread Python started (a callback from a native thread has none)."""
    # A native thread only appears in threading's registry as a _DummyThread, and only once it asks
    # for current_thread(); _on_warning never does.
    return any(t.ident == ident and not isinstance(t, threading._DummyThread) for t in threading.enumerate())


def _on_warning(message: str) -> None:
    me = threading.get_ident()
    python = _python_thread(me)
    with _CAPTURE_LOCK:
        takers = [log for owner, log in _CAPTURES if owner == me or not python]
        for log in takers:
            log.append(message)
        saved = None if takers else (_SAVED_HANDLER[0] if _SAVED_HANDLER else None)
    if takers:
        return
    if saved is not None:
        saved(message)
    else:  # a Python thread outside any capture (a scene being built, an outcome replay): say so
        print(f"MuJoCo warning outside a checked rollout: {message}", file=sys.stderr)


@contextlib.contextmanager
def captured_warnings() -> Iterator[list[str]]:
    """A list that collects MuJoCo's warnings while the block runs; none print.

    It takes the warnings of this thread and of MuJoCo's own threads, not those of other Python threads.
    """
    log: list[str] = []
    with _CAPTURE_LOCK:
        if not _CAPTURES:
            _SAVED_HANDLER[:] = [mujoco.get_mju_user_warning()]
            mujoco.set_mju_user_warning(_on_warning)
        _CAPTURES.append((threading.get_ident(), log))
    try:
        yield log
    finally:
        with _CAPTURE_LOCK:
            del _CAPTURES[next(i for i, (_, x) in enumerate(_CAPTURES) if x is log)]  # by identity
            if not _CAPTURES:
                mujoco.set_mju_user_warning(_SAVED_HANDLER[0])
                _SAVED_HANDLER.clear()


def warning_counts(d: mujoco.MjData) -> dict[str, int]:
    """The failing warnings ``d`` counted, by name (``BADQACC``...), nonzero ones only."""
    return {
        mujoco.mjtWarning(w).name.removeprefix("mjWARN_"): int(d.warning[w].number)
        for w in _FATAL_WARNINGS
        if d.warning[w].number > 0
    }


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
        count = int(d.warning[w].number)
        raise SimulationDiverged(
            f"{context}MuJoCo warning {name}"
            + (f" (x{count})" if count > 1 else "")
            + f" at t={d.time:.4f} s"
            + (f" ({hint})" if hint else "")
        )
    if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
        raise SimulationDiverged(f"{context}state is not finite at t={d.time:.4f} s")
