"""Benchmarks: named cases, one runner, JSON out. Speed goals live here, not in tests."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import mujoco
import numpy as np

from mjcodesign.errors import OutputError
from mjcodesign.finger import FingerDesign
from mjcodesign.mjcf import FingerModel, SimOptions, build_finger
from mjcodesign.simulate import check_state
from mjcodesign.stiffness import Stiffness
from mjcodesign.tendon import TendonDriver

__all__ = ["bench_finger"]

_BENCH_DESIGN = "semi-rigid"
_BENCH_TENSION = 2.0
"""Tendon tension of the free curl [N], ramped over the first 0.2 s."""
_RAMP = 0.2
_MIN_WALL_S = 1.0
_MAX_REPS = 200


def _one_thread() -> None:
    # MuJoCo steps single-threaded; cap BLAS too so numpy glue does not steal the second core.
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def bench_finger(
    models=("chain", "flex", "flex-quadratic"),
    seconds: float = 1.0,
    out: str | None = None,
    progress: bool = True,
    flex_cells: int | None = None,
) -> dict:
    """Steps per second of a free tendon curl (native tendon, gravity on) for each model."""
    _one_thread()
    design = FingerDesign()
    stiffness = Stiffness.preset(_BENCH_DESIGN)
    results: dict[str, dict] = {}
    from rich.progress import Progress

    with Progress(disable=not progress, transient=True) as bar:
        task = bar.add_task("bench finger", total=len(models))
        for name in models:
            model = FingerModel(name)
            built = build_finger(design, stiffness, model, options=SimOptions(flex_cells=flex_cells))
            m = built.model
            n = int(round(seconds / m.opt.timestep))
            rates, reps, wall_total = [], 0, 0.0
            # Repeat the curl until 1 s of wall time has accumulated: one 1-s chain curl takes ~20 ms.
            while reps == 0 or (wall_total < _MIN_WALL_S and reps < _MAX_REPS):
                d = mujoco.MjData(m)
                drv = TendonDriver(built)
                t0 = time.perf_counter()
                for _ in range(n):
                    drv.set_tension(d, _BENCH_TENSION * min(1.0, d.time / _RAMP))
                    mujoco.mj_step(m, d)
                wall = time.perf_counter() - t0
                check_state(d, f"{name}: ")
                rates.append(n / wall)
                wall_total += wall
                reps += 1
            results[name] = {
                "steps_per_s": float(np.median(rates)),
                "steps": n,
                "repeats": reps,
                "wall_s": wall_total,
                "nv": int(m.nv),
                "timestep_s": m.opt.timestep,
                "solver_iterations_cap": int(m.opt.iterations),
                "cells": built.fingers[0].grid[3] if model.is_flex else None,
            }
            bar.advance(task)
    if out:
        try:
            Path(out).write_text(json.dumps(results, indent=2))
        except OSError as exc:
            raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from exc
    return results
