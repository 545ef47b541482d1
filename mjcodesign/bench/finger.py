"""`bench finger`: steps/s of a free tendon curl per finger model. Speed goals live here, not in tests."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import mujoco
import numpy as np
from mujoco import rollout

from mjcodesign.design import FingerDesign, Stiffness
from mjcodesign.errors import DesignError, SimulationDiverged
from mjcodesign.models import FingerModel, SimOptions, build_finger, check_state

__all__ = ["bench_finger"]

_BENCH_DESIGN = "semi-rigid"
_BENCH_TENSION = 2.0
"""Tendon tension of the free curl [N], ramped over the first 0.2 s."""
_RAMP = 0.2
_MIN_WALL_S = 1.0
_MAX_REPS = 200


def bench_finger(
    models=("chain", "flex", "flex-quadratic"),
    seconds: float = 1.0,
    progress: Callable[[str, int], None] | None = None,
    flex_cells: int | None = None,
) -> dict:
    """Steps per second of a free tendon curl (native tendon, gravity on) for each model.

    One thread: ``mujoco.rollout`` with one ``MjData`` steps in C on the calling thread. Write the
    result with :func:`mjcodesign.bench.run_benchmark` (``out=``). ``seconds``: simulated time of one
    curl [s]; ``progress(model, done)`` is called before each model (``done`` models finished).
    ``steps_per_s`` is the median over repeats of steps over wall time, ``steps_per_cpu_s`` over the
    process's CPU time (on a shared machine, the stabler of the two). Raises :class:`DesignError` for
    an unknown model, a non-positive ``seconds`` or ``flex_cells``.
    """
    known = {m.value for m in FingerModel}
    unknown = [m for m in models if m not in known]
    if unknown or not models:
        raise DesignError(f"unknown finger model(s) {unknown}: choose from {', '.join(sorted(known))}")
    if not (math.isfinite(seconds) and seconds > 0):
        raise DesignError(f"seconds must be finite and > 0, got {seconds}")
    if flex_cells is not None and flex_cells < 1:
        raise DesignError(f"flex_cells must be >= 1, got {flex_cells}")
    design = FingerDesign()
    stiffness = Stiffness.preset(_BENCH_DESIGN)
    results: dict[str, dict] = {}
    for done, name in enumerate(models):
        if progress is not None:
            progress(name, done)
        model = FingerModel(name)
        built = build_finger(design, stiffness, model, options=SimOptions(flex_cells=flex_cells))
        results[name] = _curl_rate(built, name, seconds)
        results[name]["cells"] = built.fingers[0].grid[3] if model.is_flex else None
    return results


def _curl_rate(built, name: str, seconds: float) -> dict:
    """Median steps/s of ``seconds`` of the free curl of ``built``, repeated for >= 1 s of wall time."""
    m = built.model
    n = max(1, int(round(seconds / m.opt.timestep)))
    # Native tendon, controls precomputed: mujoco.rollout steps in C on one thread, so the
    # figure is the simulator's, not Python's per-step overhead.
    ctrl = np.zeros((n, m.nu))
    ramp = _BENCH_TENSION * np.minimum(1.0, np.arange(n) * m.opt.timestep / _RAMP)
    for act in built.fingers[0].actuators:
        aid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, act)
        ctrl[:, aid] = ramp / len(built.fingers[0].actuators)
    d = mujoco.MjData(m)
    spec_full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.zeros(mujoco.mj_stateSize(m, spec_full))
    mujoco.mj_getState(m, d, x0, spec_full)
    rates, cpu_rates, reps, wall_total, cpu_total = [], [], 0, 0.0, 0.0
    # Repeat until 1 s of wall time has accumulated: one 1-s chain curl takes ~20 ms.
    while reps == 0 or (wall_total < _MIN_WALL_S and reps < _MAX_REPS):
        t0, c0 = time.perf_counter(), time.process_time()
        state, _ = rollout.rollout(m, d, x0, ctrl[None])
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        check_state(d, f"{name}: ")
        if not np.all(np.isfinite(state)):
            raise SimulationDiverged(f"{name}: state is not finite")
        rates.append(n / wall)
        cpu_rates.append(n / max(cpu, 1e-9))
        wall_total += wall
        cpu_total += cpu
        reps += 1
    return {
        "steps_per_s": float(np.median(rates)),
        # CPU time of the one stepping thread: what the model costs, whatever else the machine runs.
        "steps_per_cpu_s": float(np.median(cpu_rates)),
        "steps": n,
        "repeats": reps,
        "wall_s": wall_total,
        "cpu_s": cpu_total,
        "nv": int(m.nv),
        "timestep_s": m.opt.timestep,
        "solver_iterations_cap": int(m.opt.iterations),
    }
