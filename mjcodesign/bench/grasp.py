"""Benchmark of grasp rollouts: raw ``mujoco.rollout`` throughput against the whole pipeline."""

from __future__ import annotations

import os
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.models.simulate import check_state, reset_warnings
from mjcodesign.models.types import FingerModel
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene, control_spec, phase_controls
from mjcodesign.sim import MujocoBackend, initial_state, with_stiffness

__all__ = ["bench_grasp"]

_DEFAULT_ROLLOUTS = {"chain": 32, "flex": 2}
_DEFAULT_REPEATS = {"chain": 3, "flex": 1}
_BENCH_DENSITY = 100.0  # light preset [kg/m³]


def bench_grasp(
    model: str = "chain",
    source: str = "010_potted_meat_can",
    rollouts: int | None = None,
    seed: int = 0,
    cache_dir: str | Path | None = None,
    repeats: int | None = None,
) -> dict:
    """Rollouts/s of the default scenario over random designs on one object and auto pose, all cores.

    ``raw_rollouts_per_s`` times one ``mujoco.rollout`` call alone (models, controls and the initial
    state prepared beforehand). ``rollouts_per_s`` times :func:`mjcodesign.jobs.run_jobs` on one job
    per design (one ``run_batch``): per-design models, controls, the rollout, the divergence checks and
    the outcomes (contact-force replays); its compiled scene is cached, as in data generation.
    The two alternate ``repeats`` times and the fastest of each is kept, since the machine is shared;
    ``pipeline_overhead_cpu`` compares the process CPU time of the two, which other users of the
    machine disturb less than wall time; ``*_per_cpu_s`` are rollouts per CPU second (one free core).
    Loading, decomposing the object and building the scene happen once and are not timed.
    """
    if model not in _DEFAULT_ROLLOUTS:
        raise DesignError(f"unknown finger model {model!r}: choose from {', '.join(_DEFAULT_ROLLOUTS)}")
    for name, value in (("rollouts", rollouts), ("repeats", repeats)):
        if value is not None and value < 1:
            raise DesignError(f"{name} must be >= 1, got {value}")
    n = _DEFAULT_ROLLOUTS[model] if rollouts is None else rollouts
    repeats = _DEFAULT_REPEATS[model] if repeats is None else repeats
    obj = load_grasp_object(source, _BENCH_DENSITY, seed=seed, cache_dir=cache_dir)
    rng = np.random.default_rng(seed)
    designs = [Stiffness(rng.uniform(LOG_E_MIN, LOG_E_MAX, 22)) for _ in range(n)]
    design = FingerDesign()
    pose = auto_pose(obj, design)
    scene = build_scene(obj, design, designs[0], FingerModel(model), pose)
    scenario = GraspScenario()
    jobs = [GraspJob(obj=obj, pose=pose, design=s, finger_model=model, scenario=scenario) for s in designs]
    scenes = SceneCache()
    scenes.scene(jobs[0])  # compiled once, outside the timings (as a long data-generation run)
    nthread = len(os.sched_getaffinity(0))
    ctrl, _ = phase_controls(scene, scenario)
    x0 = initial_state(scene)
    models = [with_stiffness(scene, s) for s in designs]
    datas = [mujoco.MjData(scene.model) for _ in range(min(nthread, n))]
    backend = MujocoBackend(nthread=nthread)
    raw_walls, pipe_walls, raw_cpu, pipe_cpu = [], [], [], []
    for _ in range(repeats):
        for d in datas:
            reset_warnings(d)
        t0, c0 = time.perf_counter(), time.process_time()
        mj_rollout.rollout(models, datas, x0[None], ctrl[None], control_spec=control_spec())
        raw_walls.append(time.perf_counter() - t0)
        raw_cpu.append(time.process_time() - c0)
        for d in datas:
            check_state(d, "bench raw rollout: ")
        t0, c0 = time.perf_counter(), time.process_time()
        outs = run_jobs(jobs, backend, scenes=scenes)
        pipe_walls.append(time.perf_counter() - t0)
        pipe_cpu.append(time.process_time() - c0)
    raw = n / min(raw_walls)
    pipe = n / min(pipe_walls)
    m = scene.model
    return {
        "model": model,
        "object": obj.name,
        "mass_kg": obj.mass,
        "hulls": len(obj.hulls),
        "hull_vertices": int(sum(len(v) for v, _ in obj.hulls)),
        "rollouts": n,
        "repeats": repeats,
        "steps_per_rollout": int(len(ctrl)),
        "timestep_s": float(m.opt.timestep),
        "cone": mujoco.mjtCone(m.opt.cone).name,
        "threads": nthread,
        "raw_rollouts_per_s": raw,
        "rollouts_per_s": pipe,
        "pipeline_overhead": raw / pipe - 1.0,
        "pipeline_overhead_cpu": min(pipe_cpu) / min(raw_cpu) - 1.0,
        "raw_steps_per_s": raw * len(ctrl),
        "raw_rollouts_per_cpu_s": n / min(raw_cpu),
        "rollouts_per_cpu_s": n / min(pipe_cpu),
        "raw_wall_s": raw_walls,
        "pipeline_wall_s": pipe_walls,
        "raw_cpu_s": raw_cpu,
        "pipeline_cpu_s": pipe_cpu,
        "successes": int(sum(o.success for o in outs)),
        "failed_reasons": sorted({o.reason for o in outs if not o.success})[:5],
    }
