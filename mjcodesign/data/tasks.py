"""The work of a dataset, as tasks any process can run: prepare an object, run a shard.

* :class:`ObjectTask`: load the object (watertight, convex pieces), sample its poses, draw each pose's
  density and partial point cloud: the ``poses`` rows of one object.
* :class:`ShardTask`: one scene (object, pose, density) with its designs, run through one
  :func:`mjcodesign.jobs.run_jobs` call (one ``mujoco.rollout`` batch): its ``samples`` and
  ``rejected`` rows; with K > 1 perturbed rollouts per design, its cells
  (:mod:`mjcodesign.data.cells`) and their ``rollouts`` rows too.

A :class:`Worker` runs them and keeps what is worth keeping between tasks: loaded objects, compiled
scenes (:class:`~mjcodesign.jobs.SceneCache`) and the simulator. Tasks carry everything they need,
so a task gives the same rows in this process, a pool process or on a Ray node.
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from mjcodesign.data.cells import cell_tables, run_cells
from mjcodesign.data.cloud import partial_cloud, to_gripper
from mjcodesign.data.config import DatagenConfig
from mjcodesign.data.sampling import PoseStreams, object_pose_seed, sample_designs
from mjcodesign.data.schema import POSES, REJECTED, SAMPLES, build_table, empty_columns
from mjcodesign.design.stiffness import N_LOG_E, Stiffness
from mjcodesign.errors import MeshError, PoseError, UnsupportedError
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.models.types import GripperPose
from mjcodesign.objects import (
    DENSITY_PRESETS,
    GraspObject,
    mass_by_rule,
    real_density,
)
from mjcodesign.poses import sample_poses, scene_offset
from mjcodesign.scenarios.grasp import scene_at_pose
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome
from mjcodesign.sim import get_backend, scene_with_design

__all__ = [
    "ObjectResult",
    "ObjectTask",
    "ShardResult",
    "ShardTask",
    "Worker",
    "hulls_hash",
    "mesh_hash",
    "shard_key",
]

_LOAD_DENSITY = DENSITY_PRESETS["light"]  # objects load at this; every job sets its pose's density
_OBJECTS_KEPT = 4  # loaded objects a worker keeps (shards arrive grouped by object)


def shard_key(object_index: int, pose_index: int) -> str:
    """The name of shard (object, pose): ``o0003-p017``."""
    return f"o{object_index:04d}-p{pose_index:03d}"


def mesh_hash(obj: GraspObject) -> str:
    """SHA-256 of the object's watertight mesh (COM frame vertices, faces) as simulated."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(obj.mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(obj.mesh.faces, dtype=np.int64).tobytes())
    return h.hexdigest()


def hulls_hash(obj: GraspObject) -> str:
    """SHA-256 of the object's convex pieces (its collision geometry)."""
    h = hashlib.sha256()
    for v, f in obj.hulls:
        h.update(np.ascontiguousarray(v, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(f, dtype=np.int64).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class ObjectTask:
    """Prepare object ``index`` of ``config``: its poses, densities and point clouds."""

    index: int
    config: DatagenConfig
    cache_dir: str | None = None
    """CoACD's cache folder (None: no cache)."""


@dataclass(frozen=True)
class ObjectResult:
    """The ``poses`` rows of one object, and its facts for the manifest."""

    index: int
    facts: dict
    """name, mesh_sha256, hulls_sha256, hulls, repaired, repair, fallback, volume_m3, poses,
    candidates, dropped_poses, sampler_rejected, pose_time_s, cloud_time_s."""
    poses: pa.Table


@dataclass(frozen=True)
class ShardTask:
    """Run pose ``pose_index`` of object ``object_index`` at ``density`` with its designs."""

    object_index: int
    pose_index: int
    matrix: tuple[float, ...]
    """Palm pose, 4x4 row-major [m]."""
    openings: tuple[float, float]
    density: float
    """[kg/m³]."""
    hulls_sha256: str
    """The object's collision geometry as prepared; a worker that loads other hulls refuses the shard."""
    config: DatagenConfig
    cache_dir: str | None = None
    log_e: tuple[tuple[float, ...], ...] | None = None
    """Designs to run instead of the seeded draw, ln(E / Pa), 22 each (e.g. presets); None: the draw."""
    replicate: int = 0
    """Perturbed shards: 0 runs the dataset's draws; r >= 1 the pose's r-th independent replicate of
    them (:func:`~mjcodesign.data.cells.run_cells`), a test-retest of the shard's labels."""

    @property
    def key(self) -> str:
        """:func:`shard_key` of this shard."""
        return shard_key(self.object_index, self.pose_index)

    def designs(self) -> np.ndarray:
        """The shard's designs, ln(E / Pa), shape (n, 22): :attr:`log_e`, or ``designs_per_pose`` drawn."""
        if self.log_e is not None:
            return np.array(self.log_e, dtype=float).reshape(len(self.log_e), N_LOG_E)
        c = self.config
        rng = PoseStreams(c.seed, self.object_index, self.pose_index).designs
        return sample_designs(rng, c.designs_per_pose, c.sampler)


@dataclass(frozen=True)
class ShardResult:
    """The rows of one shard."""

    key: str
    samples: pa.Table
    rejected: pa.Table
    wall_time_s: float
    rollouts: pa.Table | None = None
    """Every perturbed rollout of the shard's cells (K > 1), else None."""


class Worker:
    """Runs tasks, keeping loaded objects, compiled scenes and the simulator between them.

    ``nthread``: MuJoCo C's threads per batch; ``device``: MJWarp's Warp device (``cpu``, ``cuda``).
    Threads may share one worker (MuJoCo C shards; :class:`~mjcodesign.data.executors.ThreadExecutor`):
    an object is loaded, and a scene compiled, once for all of them.
    """

    def __init__(self, nthread: int | None = None, device: str = "cpu"):
        self.nthread = nthread
        self.device = device
        self.scenes = SceneCache()
        self._objects: OrderedDict[tuple, GraspObject] = OrderedDict()
        self._backends: dict[str, object] = {}
        self._lock = threading.RLock()

    def backend(self, name: str):
        """The simulator ``name``, built once."""
        with self._lock:
            if name not in self._backends:
                kwargs = {"nthread": self.nthread} if name == "mujoco" else {"device": self.device}
                self._backends[name] = get_backend(name, **kwargs)
            return self._backends[name]

    def grasp_object(self, config: DatagenConfig, index: int, cache_dir: str | None) -> GraspObject:
        """Object ``index`` of ``config``, loaded and decomposed once per worker."""
        key = (config.objects[index], config.object_seed, cache_dir)
        with self._lock:
            obj = self._objects.pop(key, None)
            if obj is None:
                obj = load_grasp_object(
                    config.objects[index], _LOAD_DENSITY, seed=config.object_seed, cache_dir=cache_dir
                )
                while len(self._objects) >= _OBJECTS_KEPT:
                    self._objects.popitem(last=False)
            self._objects[key] = obj
        return obj

    def prepare(self, task: ObjectTask) -> ObjectResult:
        """Load, pose and crop the point clouds of one object.

        Raises :class:`MeshError` or :class:`PoseError` when the object cannot be loaded or posed.
        """
        c = task.config
        obj = self.grasp_object(c, task.index, task.cache_dir)
        t0 = time.perf_counter()
        cands = sample_poses(
            obj, c.poses_per_object, seed=object_pose_seed(c.seed, task.index), design=c.geometry
        )
        t_pose = time.perf_counter() - t0
        # sample_poses raises PoseError (every reason counted) when it accepts no candidate.
        real = _real_density(obj, c.objects[task.index], c.mass)
        cols = empty_columns(POSES)
        dropped: dict[str, str] = {}
        t0 = time.perf_counter()
        for p in range(len(cands)):
            T = cands.matrices[p]
            streams = PoseStreams(c.seed, task.index, p)
            rho = real if real is not None else c.density.draw(streams.density)
            try:
                cloud = partial_cloud(
                    obj, T, cands.openings[p], streams.cloud, n=c.cloud_points, geometry=c.geometry
                )
            except PoseError as exc:
                dropped[str(p)] = str(exc)
                continue
            row = {
                "object_index": task.index,
                "object": obj.name,
                "pose_index": p,
                "source": "sampler",
                "candidate_index": p,
                "candidate_score": float(cands.scores[p]),
                "palm_pose": T.reshape(16),
                "openings": cands.openings[p],
                "density": rho,
                "mass": obj.mass * rho / obj.density,
                "com_gripper": to_gripper(T, scene_offset(obj)[None])[0],
                "point_cloud": cloud.points,
                "cloud_inside": cloud.inside,
                "seed": c.seed,
            }
            for k, v in row.items():
                cols[k].append(v)
        t_cloud = time.perf_counter() - t0
        if not cols["pose_index"]:
            raise PoseError(f"no pose has a point cloud: {next(iter(dropped.values()))}")
        for k in ("palm_pose", "openings", "com_gripper", "point_cloud"):
            cols[k] = np.stack(cols[k])
        facts = {
            "name": obj.name,
            "mesh_sha256": mesh_hash(obj),
            "hulls_sha256": hulls_hash(obj),
            "hulls": len(obj.hulls),
            "repaired": bool(obj.repaired),
            # The repair method, where the objects package records it (GraspObject.repair).
            "repair": getattr(obj, "repair", None),
            "fallback": obj.fallback,
            "volume_m3": float(obj.mass / obj.density),
            "poses": len(cols["pose_index"]),
            "candidates": len(cands),
            "dropped_poses": dropped,
            "sampler_rejected": {k: int(v) for k, v in cands.rejected.items()},
            "pose_time_s": t_pose,
            "cloud_time_s": t_cloud,
        }
        return ObjectResult(task.index, facts, build_table(cols, POSES))

    def run(self, tasks: list[ShardTask]) -> list[ShardResult]:
        """Run shards of one object: each as one ``run_jobs`` batch, or (MJWarp) all as worlds of one call.

        The MJWarp shards must share one density.
        """
        if not tasks:
            return []
        c = tasks[0].config
        obj = self.grasp_object(c, tasks[0].object_index, tasks[0].cache_dir)
        for t in tasks:
            if t.object_index != tasks[0].object_index or t.config != c:
                raise ValueError("the shards of one call share their object and config")
            if hulls_hash(obj) != t.hulls_sha256:
                raise MeshError(
                    f"{obj.name}: this worker's convex pieces differ from the prepared ones "
                    "(another CoACD version or cache?)"
                )
        if c.backend == "mjwarp":
            return self._run_worlds(obj, tasks)
        out = []
        for t in tasks:
            t0 = time.perf_counter()
            if c.perturbed:
                out.append(self._run_cells(obj, t))
                continue
            jobs = _jobs(obj, t)
            outs = run_jobs(jobs, self.backend(c.backend), scenes=self.scenes)
            out.append(_result(t, obj.name, outs, time.perf_counter() - t0))
        return out

    def _run_cells(self, obj: GraspObject, t: ShardTask) -> ShardResult:
        """One shard of K > 1 perturbed rollouts per design (:mod:`mjcodesign.data.cells`)."""
        t0 = time.perf_counter()
        where = {"object_index": t.object_index, "pose_index": t.pose_index}
        cells = run_cells(
            _jobs(obj, t),
            config=t.config,
            backend=self.backend("mujoco"),
            scenes=self.scenes,
            replicate=t.replicate,
            **where,
        )
        tables = cell_tables(cells, t.designs(), name=obj.name, config=t.config, density=t.density, **where)
        wall = time.perf_counter() - t0
        return ShardResult(t.key, tables.samples, tables.rejected, wall, tables.rollouts)

    def _run_worlds(self, obj: GraspObject, tasks: list[ShardTask]) -> list[ShardResult]:
        """(pose, design) pairs of one object and density as the worlds of one MJWarp batch."""
        c = tasks[0].config
        if len({t.density for t in tasks}) != 1:
            raise UnsupportedError("one MJWarp batch holds one density (the object's mass is shared)")
        if c.model.is_flex:
            raise UnsupportedError(
                "MJWarp shares flex stiffness across worlds: use --backend mujoco for flex"
            )
        t0 = time.perf_counter()
        jobs = [_jobs(obj, t) for t in tasks]
        base = self.scenes.scene(jobs[0][0])
        outs: list[list[Outcome | None]] = [[None] * len(j) for j in jobs]
        scenes, where = [], []
        for i, group in enumerate(jobs):
            try:
                posed = scene_at_pose(base, group[0].pose)
            except PoseError as exc:
                outs[i] = [failed_outcome(Failure.BAD_POSE, f"bad pose: {exc}")] * len(group)
                continue
            for k, job in enumerate(group):
                scenes.append(scene_with_design(posed, job.design))
                where.append((i, k))
        if scenes:
            res = self.backend("mjwarp").run_scenes(scenes, c.scenario)
            for (i, k), o in zip(where, res, strict=True):
                outs[i][k] = o
        share = (time.perf_counter() - t0) / len(tasks)
        return [_result(t, obj.name, o, share) for t, o in zip(tasks, outs, strict=True)]


def _jobs(obj: GraspObject, t: ShardTask) -> list[GraspJob]:
    c = t.config
    pose = GripperPose.from_matrix(np.reshape(t.matrix, (4, 4)), tuple(t.openings))
    return [
        GraspJob(
            obj=obj,
            pose=pose,
            design=Stiffness(d),
            finger_model=c.model,
            scenario=c.scenario,
            density=t.density,
            seed=c.seed,
            geometry=c.geometry,
            options=c.options,
        )
        for d in t.designs()
    ]


def _result(t: ShardTask, name: str, outs: list[Outcome], wall: float) -> ShardResult:
    """Split a shard's outcomes into training rows and sample errors."""
    c = t.config
    designs = t.designs()
    tables = {}
    for table, schema, keep in (("samples", SAMPLES, False), ("rejected", REJECTED, True)):
        rows = [i for i, o in enumerate(outs) if any(f.is_sample_error for f in o.failures) == keep]
        cols = {
            "object_index": [t.object_index] * len(rows),
            "object": [name] * len(rows),
            "pose_index": [t.pose_index] * len(rows),
            "design_index": rows,
            "density": [t.density] * len(rows),
            "log_e": designs[rows].reshape(len(rows), N_LOG_E),
            "body_force": np.array([outs[i].body_force for i in rows]).reshape(len(rows), 6),
            "displacement": np.array([outs[i].displacement for i in rows]).reshape(len(rows), 3),
            "ground_contact": [bool(outs[i].ground_contact) for i in rows],
            "finger_contact": [bool(outs[i].finger_contact) for i in rows],
            "lift_height": [float(outs[i].lift_height) for i in rows],
            "success": [bool(outs[i].success) for i in rows],
            "failure": [outs[i].failure.value if outs[i].failure else "none" for i in rows],
            "failures": [[f.value for f in outs[i].failures] for i in rows],
            "reason": [outs[i].reason for i in rows],
            "backend": [c.backend] * len(rows),
            "wall_time_s": [float(outs[i].wall_time_s) for i in rows],
            "seed": [c.seed] * len(rows),
        }
        tables[table] = build_table(cols, schema)
    return ShardResult(t.key, tables["samples"], tables["rejected"], wall)


def _real_density(obj: GraspObject, source: str, mode: str) -> float | None:
    """The density [kg/m³] at which ``obj`` weighs its published mass under the mass rule ``mode``.

    None when its poses draw one from the config's density (``density``; ``auto`` without a mass).
    """
    found = mass_by_rule(source, mode)
    return None if found is None else real_density(obj, found.mass)
