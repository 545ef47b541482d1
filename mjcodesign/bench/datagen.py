"""Benchmark of data generation: raw ``mujoco.rollout`` against the pipeline, on the same scenes.

Three figures from one run:

* ``pose_time_s`` / ``cloud_time_s`` per object: the sampler's poses and the partial point clouds;
* ``raw_rollouts_per_s``: ``mujoco.rollout`` alone over every shard (per shard one call over its
  designs on all cores; models, controls and initial states prepared beforehand, not timed);
* ``pipeline_samples_per_s``: :func:`mjcodesign.data.generate` running the same shards (scene
  compile, jobs, model copies, the rollout, divergence checks, outcomes, Parquet writes and manifest
  updates), the objects being prepared already.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjcodesign.data import (
    DatagenConfig,
    DatasetDir,
    ObjectTask,
    ShardTask,
    Worker,
    generate,
    parse_density_spec,
)
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import MjcodesignError, PoseError
from mjcodesign.jobs import GraspJob
from mjcodesign.models.simulate import reset_warnings
from mjcodesign.models.types import GripperPose
from mjcodesign.scenarios.grasp import GraspScenario, control_spec, phase_controls, scene_at_pose
from mjcodesign.sim import initial_state, with_stiffness

__all__ = ["bench_datagen"]

_PAPER_POSES = 46 * 50  # objects x poses per object of the paper's dataset
_PAPER_DESIGNS = 35  # designs per pose (paper: 50 draws, about 80k valid samples)


def bench_datagen(
    objects: list[str] | tuple[str, ...] = ("012_strawberry", "013_apple", "010_potted_meat_can"),
    poses_per_object: int = 4,
    designs_per_pose: int = 35,
    *,
    backend: str = "mujoco",
    device: str = "cpu",
    density: str = "light",
    scenario: GraspScenario | None = None,
    workers: int = 1,
    seed: int = 0,
    cache_dir: str | Path | None = None,
    repeats: int = 2,
) -> dict:
    """Pose, point-cloud, raw-rollout and pipeline throughput of one small dataset (module docstring).

    ``workers`` is the pipeline's (1: in this process, MuJoCo on every core, as the raw calls). Raw
    and pipeline passes alternate ``repeats`` times (each pipeline pass into a fresh copy of the
    prepared folder) and the fastest of each is kept, since the machine is shared; ``*_cpu_s`` are
    this process's CPU seconds (all its threads; pool workers' are not counted), which other users of
    the machine disturb less than wall time.
    """
    config = DatagenConfig(
        objects=tuple(objects),
        poses_per_object=poses_per_object,
        designs_per_pose=designs_per_pose,
        density=parse_density_spec(density),
        backend=backend,
        seed=seed,
        **({} if scenario is None else {"scenario": scenario, "tension": scenario.tension}),
    )
    cache = str(cache_dir) if cache_dir else None
    worker = Worker(nthread=None, device=device)
    per_object: dict[str, dict] = {}
    failed: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="bench-datagen-") as tmp:
        out = Path(tmp) / "dataset"
        ds = DatasetDir.open(out, config, {"command": ["bench datagen"]})
        try:
            for i, source in enumerate(config.objects):
                t0 = time.perf_counter()
                try:
                    worker.grasp_object(config, i, cache)
                    load = time.perf_counter() - t0
                    res = worker.prepare(ObjectTask(i, config, cache))
                except MjcodesignError as exc:  # as in a dataset: the object is left out, with why
                    ds.object_failed(i, f"{type(exc).__name__}: {exc}")
                    failed[source] = str(exc)
                    continue
                ds.object_ready(res)
                f = res.facts
                per_object[f["name"]] = {
                    "load_s": load,
                    "pose_time_s": f["pose_time_s"],
                    "cloud_time_s": f["cloud_time_s"],
                    "poses": f["poses"],
                    "hulls": f["hulls"],
                }
            shards = _shards(ds, config, cache)
        finally:
            ds.close()
        if not shards:
            raise PoseError(f"bench datagen: no object could be posed ({failed})")
        raw_wall, raw_cpu, pipe_wall, pipe_cpu = [], [], [], []
        for r in range(repeats):
            w, c, steps, bad = _raw(worker, shards)
            raw_wall.append(w)
            raw_cpu.append(c)
            copy = Path(tmp) / f"run{r}"
            shutil.copytree(out, copy)
            t0, c0 = time.perf_counter(), time.process_time()
            res = generate(config, copy, workers=workers, device=device, cache_dir=cache)
            pipe_wall.append(time.perf_counter() - t0)
            pipe_cpu.append(time.process_time() - c0)
    n = (len(shards) - bad) * designs_per_pose  # rollouts both sides run (bad poses run none)
    pose_s = sum(v["pose_time_s"] + v["cloud_time_s"] for v in per_object.values()) / max(len(shards), 1)
    return {
        "objects": list(per_object),
        "backend": backend,
        "workers": workers,
        "threads": worker.backend("mujoco").nthread,
        "poses": len(shards),
        "designs_per_pose": designs_per_pose,
        "rollouts": n,
        "bad_pose_shards": bad,
        "steps_per_rollout": steps,
        "repeats": repeats,
        "raw_rollouts_per_s": n / min(raw_wall),
        "pipeline_samples_per_s": n / min(pipe_wall),
        "pipeline_vs_raw": min(raw_wall) / min(pipe_wall),
        "pipeline_vs_raw_cpu": min(raw_cpu) / min(pipe_cpu) if workers == 1 else None,
        "raw_wall_s": raw_wall,
        "raw_cpu_s": raw_cpu,
        "pipeline_wall_s": pipe_wall,
        "pipeline_cpu_s": pipe_cpu,
        "samples": res["samples"],
        "rejected": res["rejected"],
        "success_rate": res["success_rate"],
        "pose_time_s_per_object": {k: v["pose_time_s"] for k, v in per_object.items()},
        "cloud_time_s_per_object": {k: v["cloud_time_s"] for k, v in per_object.items()},
        "per_object": per_object,
        "objects_failed": failed,
        "pose_and_cloud_s_per_pose": pose_s,
        # The paper's 46 objects x 50 poses x 35 designs at these rates, poses on one core, then the
        # shards: an extrapolation, not a measurement.
        "paper_scale_estimate_s": _PAPER_POSES * pose_s + _PAPER_POSES * _PAPER_DESIGNS * min(pipe_wall) / n,
    }


def _shards(ds: DatasetDir, config: DatagenConfig, cache) -> list[ShardTask]:
    ready = [i for i in range(len(config.objects)) if ds.object_entry(i)["status"] == "ready"]
    return [t for i in ready for t in ds.shard_tasks(i, config, cache)]


def _raw(worker: Worker, shards: list[ShardTask]) -> tuple[float, float, int, int]:
    """(wall [s], CPU [s], steps per rollout, bad poses) of bare ``mujoco.rollout`` calls, one per shard.

    A shard whose pose the scene refuses (a bad pose: rejected rows, no rollout) is skipped.
    """
    backend = worker.backend("mujoco")
    wall = cpu = 0.0
    steps = bad = 0
    for t in shards:
        c = t.config
        obj = worker.grasp_object(c, t.object_index, t.cache_dir)
        pose = GripperPose.from_matrix(np.reshape(t.matrix, (4, 4)), tuple(t.openings))
        designs = [Stiffness(d) for d in t.designs()]
        job = GraspJob(obj=obj, pose=pose, design=designs[0], scenario=c.scenario, density=t.density)
        try:
            scene = scene_at_pose(worker.scenes.scene(job), pose)
        except PoseError:
            bad += 1
            continue
        ctrl, _ = phase_controls(scene, c.scenario)
        x0 = initial_state(scene)
        models = [with_stiffness(scene, s) for s in designs]
        datas = [mujoco.MjData(scene.model) for _ in range(min(backend.nthread, len(models)))]
        for d in datas:
            reset_warnings(d)
        t0, c0 = time.perf_counter(), time.process_time()
        mj_rollout.rollout(models, datas, x0[None], ctrl[None], control_spec=control_spec())
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        steps = len(ctrl)
    return wall, cpu, steps, bad
