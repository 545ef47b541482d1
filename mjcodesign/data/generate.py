"""Batched data generation: objects prepared, shards run, rows written, all resumable.

:func:`generate` drives a :class:`~mjcodesign.data.store.DatasetDir` with an executor
(:mod:`mjcodesign.data.executors`): each object not yet prepared is an ``ObjectTask``; each pose of a
prepared object not yet finished is a shard (one ``run_jobs`` batch). At most ``slots`` tasks are in
flight, shards before new objects once enough shards wait. Results are written by this process only
(one writer), each file by a rename and then the manifest, so a killed run loses only the tasks in
flight, and the next run into the same folder skips everything the manifest lists.

Determinism: a shard's designs, density and point cloud come from seeds keyed by its (object, pose)
(:mod:`mjcodesign.data.sampling`), and MuJoCo C gives the same bits whatever batch or thread a rollout
runs in, so the rows do not depend on ``workers``, on Ray, or on how often the run was interrupted
(only ``wall_time_s`` does). With K > 1 perturbed rollouts per cell, the draws come from a stream keyed
by (object, pose) too (:mod:`mjcodesign.data.cells`).
"""

from __future__ import annotations

import functools
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mjcodesign.data.config import DatagenConfig
from mjcodesign.data.executors import InlineExecutor, PoolExecutor, RayExecutor, ThreadExecutor, cpu_count
from mjcodesign.data.store import DatasetDir
from mjcodesign.data.tasks import ObjectTask, ShardTask
from mjcodesign.errors import DesignError, MjcodesignError

__all__ = ["MAX_WORLDS", "Event", "generate"]

MAX_WORLDS = 2048
"""Most (pose, design) worlds in one MJWarp call."""


@dataclass(frozen=True)
class Event:
    """Progress of a run, handed to ``on_event``.

    ``kind``: ``start`` (``total``: shards expected, ``done``: already finished, ``objects``: objects
    to prepare), ``submit`` (``keys``: the shards, or the object's source, sent out), ``object`` /
    ``object_failed`` (``keys``: the object's source; ``total``: the shards expected, now that its
    poses are known; ``message``: why it failed, or why it has fewer poses than asked, else empty),
    ``shard`` / ``shard_failed`` (``samples`` and ``rejected`` of
    the shard). ``submit`` comes before the task runs, the others after its rows and the manifest are
    written.
    """

    kind: str
    keys: tuple[str, ...] = ()
    samples: int = 0
    rejected: int = 0
    total: int = 0
    done: int = 0
    message: str = ""
    objects: int = 0


def generate(
    config: DatagenConfig,
    out: str | Path,
    *,
    workers: int = 1,
    ray: str | None = None,
    device: str = "cpu",
    cache_dir: str | Path | None = None,
    slots: int | None = None,
    worker_setup: Callable[[], None] | None = None,
    command: list[str] | None = None,
    on_event: Callable[[Event], None] | None = None,
) -> dict:
    """Generate (or continue) the dataset ``config`` in ``out``; a summary of the folder and this run.

    ``workers``: 1 runs in this process (MuJoCo C: a worker thread per core); more runs a spawned
    process pool. ``ray``: ``"local"`` or a
    cluster address, instead of the pool. ``device``: MJWarp's Warp device. ``cache_dir``: CoACD's cache.
    ``slots``: tasks in flight (default twice the workers or CPUs). ``worker_setup``: a picklable
    function every worker process runs first (e.g. quieting Warp's log). ``command``: recorded in the
    manifest. Files of ``out`` found damaged (:mod:`~mjcodesign.data.integrity`) are listed in
    ``damaged_redone`` and their objects and shards computed again. Raises :class:`OutputError` for an
    unusable ``out`` (see :meth:`DatasetDir.open`).
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise DesignError(f"--workers must be an integer >= 1, got {workers!r}")
    if ray is not None and not ray.strip():
        raise DesignError("--ray needs 'local' or a cluster address")
    emit = on_event or (lambda e: None)
    run_info = {"command": command, "workers": workers, "ray": ray, "device": device}
    t0 = time.perf_counter()
    make = functools.partial(_executor, workers, ray, device, worker_setup, slots, config.backend)
    # A cluster is joined before the folder is touched: one Ray cannot join leaves the folder as it was.
    joined = make() if ray not in (None, "local") else None
    try:
        ds = DatasetDir.open(out, config, run_info)
    except BaseException:
        if joined is not None:
            joined.close()
        raise
    try:
        executor = joined or make()
        try:
            computed = _Scheduler(ds, config, executor, str(cache_dir) if cache_dir else None, emit).run()
        finally:
            executor.close()
    finally:
        ds.close()
    wall = time.perf_counter() - t0
    counts = ds.manifest["counts"]
    # K > 1: every perturbed rollout; else one rollout per sample or rejected row.
    rollouts = computed.get("rollouts", computed["samples"] + computed["rejected"])
    return {
        "out": str(out),
        "complete": ds.manifest["complete"],
        **counts,
        "success_rate": _success_rate(ds),
        "short_poses": {
            o.get("name", o["source"]): note
            for o in ds.manifest["objects"]
            if (note := _short_poses(o, config.poses_per_object))
        },
        "computed": computed,
        "damaged_redone": ds.damaged,
        "wall_s": wall,
        "samples_per_s": computed["samples"] / wall if wall > 0 else 0.0,
        "rollouts_per_s": rollouts / wall if wall > 0 else 0.0,
        "workers": workers,
        "ray": ray,
        "backend": config.backend,
    }


def _executor(workers, ray, device, setup, slots, backend):
    if ray is not None:
        return RayExecutor(ray, num_cpus=cpu_count(), device=device, setup=setup, slots=slots)
    if workers == 1:
        cores = cpu_count()
        return (
            ThreadExecutor(cores, device, slots)
            if backend == "mujoco" and cores > 1
            else InlineExecutor(device)
        )
    return PoolExecutor(workers, device=device, setup=setup, slots=slots)


def _short_poses(entry: dict, asked: int) -> str | None:
    """Why a prepared object (its manifest entry) has fewer than ``asked`` poses, or None if it has them.

    One line: the count, then the sampler's shortfall with its most frequent rejections and the poses
    dropped for want of a point cloud.
    """
    got = int(entry.get("poses", 0))
    if entry.get("status") != "ready" or got >= asked:
        return None
    parts = []
    accepted = int(entry.get("candidates", got))
    if accepted < asked:
        top = sorted(entry.get("sampler_rejected", {}).items(), key=lambda kv: (-kv[1], kv[0]))[:3]
        why = ", ".join(f"{k} {v}" for k, v in top) or "none recorded"
        parts.append(f"the sampler accepted {accepted} of the candidates it tried (most rejections: {why})")
    dropped = entry.get("dropped_poses", {})
    if dropped:
        parts.append(f"{len(dropped)} dropped without a point cloud ({next(iter(dropped.values()))})")
    return f"{got} of {asked} poses: " + "; ".join(parts)


def _success_rate(ds: DatasetDir) -> float:
    c = ds.manifest["counts"]
    return c["successes"] / c["samples"] if c["samples"] else 0.0


class _Scheduler:
    """One run over a dataset folder: what is left, in flight, and written."""

    def __init__(self, ds: DatasetDir, config: DatagenConfig, executor, cache_dir, emit):
        self.ds, self.config, self.executor, self.cache_dir, self.emit = ds, config, executor, cache_dir, emit
        self.pending = deque(
            i for i in range(len(config.objects)) if ds.object_entry(i)["status"] == "pending"
        )
        self.queue: deque[list[ShardTask]] = deque()
        self.in_flight: dict = {}
        self.computed = {"objects": 0, "shards": 0, "samples": 0, "rejected": 0}
        if config.perturbed:
            self.computed["rollouts"] = 0

    def run(self) -> dict:
        done = self.ds.done_shards()
        for i in range(len(self.config.objects)):
            if self.ds.object_entry(i)["status"] == "ready":
                self._enqueue(i, done)
        self.emit(Event("start", total=self._total(), done=len(done), objects=len(self.pending)))
        while self.pending or self.queue or self.in_flight:
            self._fill()
            for handle, result, error in self.executor.wait(list(self.in_flight)):
                kind, what = self.in_flight.pop(handle)
                if kind == "prepare":
                    self._object_done(what, result, error)
                else:
                    self._shards_done(what, result, error)
        return self.computed

    def _fill(self) -> None:
        slots = self.executor.slots
        while len(self.in_flight) < slots and (self.queue or self.pending):
            # Shards first once enough wait to keep the workers busy; else prepare the next object.
            if self.queue and (len(self.queue) >= slots or not self.pending):
                group = self.queue.popleft()
                handle = self.executor.submit("run", group)
                self.in_flight[handle] = ("run", group)
                self.emit(Event("submit", keys=tuple(t.key for t in group)))
            else:
                i = self.pending.popleft()
                handle = self.executor.submit("prepare", ObjectTask(i, self.config, self.cache_dir))
                self.in_flight[handle] = ("prepare", i)
                self.emit(Event("submit", keys=(self.config.objects[i],)))

    def _total(self) -> int:
        """Shards expected: the poses of ready objects, the requested count for pending ones."""
        objs = self.ds.manifest["objects"]
        return sum(
            o["poses"] if o["status"] == "ready" else self.config.poses_per_object
            for o in objs
            if o["status"] != "failed"
        )

    def _object_done(self, index: int, result, error) -> None:
        name = self.config.objects[index]
        if error is not None:
            if not isinstance(error, MjcodesignError):
                raise error
            self.ds.object_failed(index, f"{type(error).__name__}: {error}")
            self.emit(Event("object_failed", keys=(name,), message=str(error), total=self._total()))
            return
        self.ds.object_ready(result)
        self.computed["objects"] += 1
        self._enqueue(index, self.ds.done_shards())
        note = _short_poses(self.ds.object_entry(index), self.config.poses_per_object) or ""
        self.emit(Event("object", keys=(name,), total=self._total(), message=note))

    def _enqueue(self, index: int, done: set[str]) -> None:
        """Queue the unfinished shards of a ready object (MJWarp: grouped by density into worlds)."""
        tasks = self.ds.shard_tasks(index, self.config, self.cache_dir)
        tasks = [t for t in tasks if t.key not in done]
        if self.config.backend != "mjwarp":
            self.queue.extend([t] for t in tasks)
            return
        per_call = max(1, MAX_WORLDS // self.config.designs_per_pose)
        by_density: dict[float, list[ShardTask]] = {}
        for t in tasks:
            by_density.setdefault(t.density, []).append(t)
        for group in by_density.values():
            for s in range(0, len(group), per_call):
                self.queue.append(group[s : s + per_call])

    def _shards_done(self, group: list[ShardTask], results, error) -> None:
        if error is not None:
            if not isinstance(error, MjcodesignError):
                raise error
            for t in group:
                self.ds.shard_failed(t.key, t.object_index, t.pose_index, f"{type(error).__name__}: {error}")
                self.emit(Event("shard_failed", keys=(t.key,), message=str(error)))
            return
        for t, r in zip(group, results, strict=True):
            self.ds.shard_done(r, t.object_index, t.pose_index)
            n, k = r.samples.num_rows, r.rejected.num_rows
            self.computed["shards"] += 1
            self.computed["samples"] += n
            self.computed["rejected"] += k
            if r.rollouts is not None:
                self.computed["rollouts"] += r.rollouts.num_rows
            self.emit(Event("shard", keys=(t.key,), samples=n, rejected=k))
