"""Cost of recording a grasp rollout with an observer (``mjcodesign bench viz``).

Cases are data (:data:`CASES`); one runner times, per case and decimation, the same rollout three ways,
in turn so that a busy machine slows all alike: without an observer; into a recording of its own (the
observer created, fed and closed inside the timed span, as ``grasp --rrd`` with one design); and into
one recording that all repeats share (as ``grasp --design a,b,c --rrd``), whose close is timed once and
shared out. It reports medians of wall and CPU time (CPU time counts the observer's own threads too);
an overhead is the median over repeats of (recorded - plain), each pair timed back to back, over the
median plain rollout.
The difference between the two recorded figures is the recording's fixed cost (stream, file, footer).
"""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["VizCase", "CASES", "bench_viz", "OVERHEAD_BUDGET"]

OVERHEAD_BUDGET = 0.2
"""The budget: at the default decimation, recording may add at most 20% to the rollout time."""
_BOX = 0.04  # box side [m]: the paper-optimized chain misses it (auto pose), the cheapest rollout
_BOX_HELD = 0.05  # box side [m]: 50 g at the heavy density, held through lift and disturbance
_RHO = 400.0  # heavy preset [kg/m³]


@dataclass(frozen=True)
class VizCase:
    """A grasp to record: finger model, design preset and object (``box``, of side ``box_m``, or a YCB name)."""

    name: str
    model: str = "chain"
    design: str = "paper-optimized"
    object: str = "box"
    box_m: float = _BOX


CASES = (
    VizCase("chain-box"),  # the cheapest rollout, so the largest relative overhead
    VizCase("chain-held", box_m=_BOX_HELD),  # a grasp that holds: contacts in every logged state
    VizCase("chain-ycb", object="010_potted_meat_can"),  # 4 CoACD hulls, a 16k-face mesh to log
    VizCase("flex-box", model="flex"),
)


def _time(fn) -> tuple[float, float]:
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def _measure(sim, job, scenes, observer: str, path: Path, dec, repeats: int) -> dict:
    """Medians [s] of (wall, CPU) of the rollout three ways, alternated; and the files' sizes [B].

    Plain; into a recording of its own; into one recording shared by the repeats (its close shared out).
    """
    import dataclasses

    from mjcodesign.jobs import run_jobs
    from mjcodesign.sim.observe import observer_class

    cls = observer_class(observer)  # finding the entry point (~20 ms) is start-up, not per rollout

    def plain():
        run_jobs([job], sim, scenes=scenes)

    files = [path.with_name(f"{path.stem}_{i}{path.suffix}") for i in range(repeats)]
    paths = iter(files)

    def own():
        # A new file each time, as a run writes (the recorder replaces an older file, see its close).
        rec = cls(path=next(paths), decimation=dec)
        run_jobs([job], sim, rec, scenes=scenes)
        rec.close()

    shared_path = path.with_name(f"{path.stem}_shared{path.suffix}")
    shared = cls(path=shared_path, decimation=dec)
    labelled = iter(dataclasses.replace(job, label=f"run{i}") for i in range(repeats))

    def into_shared():
        run_jobs([next(labelled)], sim, shared, scenes=scenes)

    times = np.array([(_time(plain), _time(own), _time(into_shared)) for _ in range(repeats)])
    close = np.array(_time(shared.close))
    for f in files[:-1]:
        f.unlink()
    files[-1].replace(path)  # the size reported is the last recording's
    med = np.median(times, axis=0)  # (3, 2): plain, own, shared x wall, CPU
    # The recording's cost from each repeat's pair (recorded minus the plain run just before it): the
    # machine's speed drifts within seconds, and a pair ~0.1 s apart shares its state.
    extra = np.median(times[:, 1:] - times[:, :1], axis=0)  # (2, 2): own, shared x wall, CPU
    return {
        "plain": med[0],
        "own": med[1],
        "shared": med[2] + close / repeats,
        "own_extra": extra[0],
        "shared_extra": extra[1] + close / repeats,
        "close": close,
        "own_bytes": path.stat().st_size,
        "shared_bytes": shared_path.stat().st_size,
    }


def _case_row(case: VizCase, object_name: str, dec, m: dict, repeats: int) -> dict:
    """The JSON row of one case and decimation from :func:`_measure`'s medians."""
    p, r, sh = m["plain"], m["own"], m["shared"]
    ex, sx = m["own_extra"], m["shared_extra"]
    return {
        "case": case.name,
        "model": case.model,
        "object": object_name,
        "decimation": "default" if dec is None else dec,
        "rollout_wall_s": float(p[0]),
        "recorded_wall_s": float(r[0]),
        "overhead_wall": float(ex[0] / p[0]),
        "rollout_cpu_s": float(p[1]),
        "recorded_cpu_s": float(r[1]),
        "overhead_cpu": float(ex[1] / p[1]),
        "rrd_bytes": m["own_bytes"],
        "shared_recording": {
            "rollouts": repeats,
            "recorded_wall_s": float(sh[0]),
            "overhead_wall": float(sx[0] / p[0]),
            "recorded_cpu_s": float(sh[1]),
            "overhead_cpu": float(sx[1] / p[1]),
            "close_cpu_s": float(m["close"][1]),
            "rrd_bytes": m["shared_bytes"],
        },
    }


def bench_viz(
    *,
    cases: tuple[VizCase, ...] = CASES,
    names: list[str] | None = None,
    decimations: tuple[int | None, ...] = (None, 1),
    repeats: int = 5,
    observer: str = "rerun",
    cache_dir: Path | None = None,
) -> dict:
    """Rollout and recorded times [s], relative overheads and recording size [B] per case and decimation.

    The top-level figures record each rollout into a file of its own; ``shared_recording`` logs the
    ``repeats`` rollouts into one file, its close shared out. ``names`` picks cases by name (default:
    all of ``cases``).
    """
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError
    from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
    from mjcodesign.objects import box_object
    from mjcodesign.scenarios.grasp import GraspScenario, auto_pose
    from mjcodesign.sim import MujocoBackend
    from mjcodesign.sim.observe import load_observer

    if repeats < 1:
        raise DesignError(f"repeats must be >= 1, got {repeats}")
    if any(d is not None and d < 1 for d in decimations):
        raise DesignError(f"decimations must be None (default) or steps >= 1, got {decimations}")
    sim = MujocoBackend(nthread=1)
    scenario = GraspScenario()
    out: dict = {
        "overhead_budget": OVERHEAD_BUDGET,
        "repeats": repeats,
        "cpus": len(os.sched_getaffinity(0)),
        "load_average_1min": os.getloadavg()[0],
        "cases": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.rrd"
        load_observer(observer, path=path).close()  # import and start-up once, outside the timings
        for case in cases:
            if names is not None and case.name not in names:
                continue
            if case.object == "box":
                obj = box_object((case.box_m,) * 3, _RHO)
            else:
                obj = load_grasp_object(case.object, _RHO, cache_dir=cache_dir)
            design = Stiffness.parse(case.design)
            job = GraspJob(
                obj=obj,
                pose=auto_pose(obj),
                design=design,
                finger_model=case.model,
                scenario=scenario,
                label=case.design,
            )
            scenes = SceneCache()
            run_jobs([job], sim, scenes=scenes)  # warm up; the scene is compiled once, outside the timings
            for dec in decimations:
                m = _measure(sim, job, scenes, observer, path, dec, repeats)
                out["cases"].append(_case_row(case, obj.name, dec, m, repeats))
    return out
