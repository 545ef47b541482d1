"""The library's grasp API: a grasp is a :class:`GraspJob`, and :func:`run_jobs` runs many at once.

A job names everything that decides one rollout: the object (loaded, with its convex pieces), the palm
pose, the design (22 ln E), the finger model, the scenario, the object's density and the seed that
produced them. :func:`run_jobs` compiles one grasp scene per object, density, finger model and finger
geometry, and groups the jobs into the simulator's cheapest calls:

* the same scene at one pose with several designs goes to ``run_batch`` (a copy of the model per
  design, no recompile);
* one design at several poses goes to ``run_poses`` (a copy of the model per pose);
* what is left runs alone.

The outcomes come back in job order. On MuJoCo C the batches are bitwise equal to running every job on
its own (``tests/test_jobs.py``): a design and a pose only change numbers in a model of the same
structure, which ``with_stiffness`` and ``scene_at_pose`` write exactly as a recompile would.

:func:`load_grasp_object` and :func:`resolve_pose` are the steps before a job (a mesh or a named
object, made watertight and decomposed into convex pieces; a pose from a rule, the sampler or a file).
"""

from __future__ import annotations

import dataclasses
import json
import threading
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, MeshError, PoseError
from mjcodesign.models.types import FingerModel, GripperPose, SimOptions, grasp_model
from mjcodesign.objects import (
    CoacdSettings,
    GraspObject,
    at_mass,
    convex_decomposition,
    load_object,
    mass_by_rule,
    parse_density,
    parse_mass,
)
from mjcodesign.poses import read_candidates, sample_poses, to_gripper_pose
from mjcodesign.poses.checks import check_candidate_object, check_reach
from mjcodesign.scenarios.grasp import (
    GraspScenario,
    GraspScene,
    auto_pose,
    compile_scene,
    scene_at_pose,
    scene_options,
)
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome
from mjcodesign.scenarios.perturb import Perturbation, perturbed_scene
from mjcodesign.sim.mujoco_c import scene_with_design
from mjcodesign.sim.observe import Observer
from mjcodesign.sim.protocol import Simulator

__all__ = ["GraspJob", "SceneCache", "run_jobs", "load_grasp_object", "resolve_pose", "POSE_RULES"]

POSE_RULES = ("auto", "best")
"""Pose names besides a file: ``auto`` (top-down over the object) and ``best`` (the sampler's best of 10)."""
_BEST_OF = 10  # candidates the sampler draws for the "best" pose


@dataclass(frozen=True, kw_only=True, eq=False)
class GraspJob:
    """One grasp rollout to run: what it grasps, where, with which fingers, how.

    Jobs are compared by identity; two jobs on the same :class:`GraspObject` instance share its scene.
    """

    obj: GraspObject
    """The object, with its convex pieces (:func:`load_grasp_object`)."""
    pose: GripperPose
    """Palm pose and the target openings of the close phase."""
    design: Stiffness
    """ln E of the 22 blocks (finger A base to tip, then finger B)."""
    finger_model: FingerModel = FingerModel.CHAIN
    """The chain: the flex models cannot grasp (:func:`~mjcodesign.models.types.grasp_model` refuses them)."""
    scenario: GraspScenario = field(default_factory=GraspScenario)
    density: float | None = None
    """Object density [kg/m³]; None keeps the one ``obj`` was loaded with. Mass and inertia scale with
    it (same shape), so one loaded object serves every density."""
    seed: int = 0
    """The seed that produced the object, pose or design; recorded, it does not change the rollout
    (MuJoCo is deterministic)."""
    geometry: FingerDesign = field(default_factory=FingerDesign)
    """Finger geometry and tendon routing."""
    options: SimOptions | None = None
    """Numerical options of the model; None for the defaults."""
    label: str | None = None
    """Name an observer gets for this rollout (default ``job{i}``)."""
    perturbation: Perturbation | None = None
    """What this execution does differently (:mod:`mjcodesign.scenarios.perturb`); None: nothing."""

    def __post_init__(self) -> None:
        if not isinstance(self.obj, GraspObject):
            raise DesignError(f"a grasp job needs a GraspObject, got {type(self.obj).__name__}")
        if not self.obj.hulls:
            raise DesignError(f"object {self.obj.name} has no convex pieces: use load_grasp_object")
        if not isinstance(self.design, Stiffness):
            raise DesignError(f"a grasp job's design is a Stiffness, got {type(self.design).__name__}")
        object.__setattr__(self, "finger_model", grasp_model(self.finger_model))
        if self.density is not None and not (np.isfinite(self.density) and self.density > 0):
            raise DesignError(f"density must be a finite value > 0 kg/m³, got {self.density}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer) or self.seed < 0:
            raise DesignError(f"seed must be an integer >= 0, got {self.seed!r}")

    @property
    def rho(self) -> float:
        """The object's density in this job [kg/m³]."""
        return float(self.obj.density if self.density is None else self.density)


_KEPT_PERTURBED = 256
"""Perturbed scenes a :class:`SceneCache` keeps for their rollouts (a model copy each, ~1 MB): an
evaluation keeps one object's 10 poses x 8 draws."""


class SceneCache:
    """Compiled scenes kept between :func:`run_jobs` calls, ``size`` at most (least recently used out).

    A scene is compiled once per object, density, finger model, geometry, options and scenario (its
    friction is compiled in: :func:`~mjcodesign.scenarios.grasp.scene_options`); designs and poses
    are written into model copies, so a cached scene gives the same numbers as a fresh compile (chain:
    bitwise; flex: a design's cells are rescaled, equal to a recompile to round-off). Threads may
    share one cache: a scene missing is compiled once, under the cache's lock, and the scenes are
    only read by the runs that use them.
    """

    def __init__(self, size: int = 16):
        if size < 1:
            raise DesignError(f"a scene cache holds at least one scene, got {size}")
        self.size = size
        self._scenes: dict[tuple, tuple[GraspObject, GraspScene]] = {}
        self._perturbed: dict[tuple, tuple[GraspScene, GraspScene]] = {}
        self._lock = threading.RLock()

    def keep_perturbed(
        self, base: GraspScene, scenario: GraspScenario, pose: GripperPose, p: Perturbation, scene: GraspScene
    ) -> None:
        """Keep ``scene``, ``base`` perturbed by ``p`` at ``pose``, for that draw's rollout to take once.

        ``scene`` is :func:`~mjcodesign.scenarios.perturb.perturbed_scene`'s, as a draw's start check
        built it. ``base`` must be a scene of this cache: the rollout looks it up by the scene it runs on.
        """
        with self._lock:
            self._perturbed[_perturbed_key(base, scenario, pose, p)] = (base, scene)  # base held: id stays
            while len(self._perturbed) > _KEPT_PERTURBED:  # oldest first out: a later rollout builds it again
                self._perturbed.pop(next(iter(self._perturbed)))

    def take_perturbed(
        self, base: GraspScene, scenario: GraspScenario, pose: GripperPose, p: Perturbation
    ) -> GraspScene:
        """The kept perturbed scene (removed from the cache), or a new one; :class:`PoseError` if bad."""
        with self._lock:
            kept = self._perturbed.pop(_perturbed_key(base, scenario, pose, p), None)
        if kept is not None and kept[0] is base:
            return kept[1]
        return perturbed_scene(base, scenario, p, pose=pose)

    def scene(self, job: GraspJob) -> GraspScene:
        """The compiled scene (gripper at the reference pose) for ``job``'s object and fingers."""
        key = _scene_key(job)
        with self._lock:
            hit = self._scenes.pop(key, None)
            if hit is None:
                obj = _at_density(job.obj, job.rho)
                hit = (
                    job.obj,
                    compile_scene(
                        obj,
                        job.geometry,
                        job.design,
                        job.finger_model,
                        options=scene_options(job.scenario, job.options),
                    ),
                )
                while len(self._scenes) >= self.size:
                    self._scenes.pop(next(iter(self._scenes)))
            self._scenes[key] = hit  # most recent last; the object is held so that its id stays unique
        return hit[1]


def run_jobs(
    jobs: Sequence[GraspJob],
    backend: Simulator,
    observer: Observer | None = None,
    *,
    strict: bool = False,
    scenes: SceneCache | None = None,
) -> list[Outcome]:
    """Run every job on ``backend``; the outcomes in job order.

    A pose the scene cannot take (gripper below the ground, object too wide for the stroke) gives a
    :attr:`Failure.BAD_POSE` outcome, or raises :class:`PoseError` with ``strict``. ``observer``
    receives every rollout under its job's ``label`` (default ``job{i}``). ``scenes`` keeps compiled
    scenes for later calls (a fresh cache by default).
    """
    scenes = scenes or SceneCache()
    outs: list[Outcome | None] = [None] * len(jobs)
    groups: dict[tuple, list[int]] = defaultdict(list)
    for i, job in enumerate(jobs):
        groups[_scene_key(job)].append(i)
    for idx in groups.values():
        _run_group(jobs, idx, backend, observer, outs, strict, scenes.scene(jobs[idx[0]]), scenes)
    return outs  # type: ignore[return-value]  # every slot is filled by _run_group


def _perturbed_key(base: GraspScene, scenario: GraspScenario, pose: GripperPose, p: Perturbation) -> tuple:
    """What a perturbed scene depends on: its base scene, the scenario's drive and friction, pose, draw."""
    return (id(base), scenario.tendon, scenario.friction, pose, p)


def _scene_key(job: GraspJob) -> tuple:
    """Jobs with equal keys share one compiled scene (numbers change, the structure does not)."""
    return (id(job.obj), job.rho, job.finger_model, job.geometry, job.options, job.scenario)


def _run_group(
    jobs, idx: list[int], backend, observer, outs: list, strict: bool, base: GraspScene, scenes: SceneCache
) -> None:
    """The jobs ``idx`` of one scene key: per pose a design batch, then per design a pose batch.

    Perturbed jobs go together through the backend's ``run_scenes`` (:func:`_run_perturbed`).
    """
    first = jobs[idx[0]]
    perturbed = [i for i in idx if jobs[i].perturbation is not None]
    if perturbed:
        _run_perturbed(jobs, perturbed, backend, observer, outs, strict, base, scenes)
        idx = [i for i in idx if jobs[i].perturbation is None]
        if not idx:
            return
    by_pose: dict[GripperPose, list[int]] = defaultdict(list)
    for i in idx:
        by_pose[jobs[i].pose].append(i)
    singles: list[int] = []
    for pose, members in by_pose.items():
        if len(members) == 1:
            singles.append(members[0])
            continue
        scene = _at_pose(base, pose, members, outs, strict)
        if scene is not None:  # run_batch writes each design into its own model copy
            designs = [jobs[i].design for i in members]
            res = backend.run_batch(
                scene, first.scenario, designs, observer=observer, labels=_labels(jobs, members)
            )
            _place(outs, members, res)
    by_design: dict[tuple, list[int]] = defaultdict(list)
    for i in singles:
        by_design[_design_key(jobs[i].design)].append(i)
    for members in by_design.values():
        _run_poses(jobs, members, base, backend, observer, outs, strict)


_SCENES_PER_CALL = (
    256  # perturbed scenes per rollout call: its states (nstep x nstate doubles each) stay < 0.5 GB
)
_PIPELINE_CHUNK = 64
"""Perturbed scenes per rollout call when the backend pipelines its calls (``run_scene_chunks``): small
enough that building the next chunk and scoring the last one overlap most of the rollouts, large
enough to keep every core busy in each call (``mujoco.rollout`` splits a call into chunks of
``nbatch / (10 nthread)``)."""


def _run_perturbed(
    jobs, idx: list[int], backend, observer, outs: list, strict: bool, base: GraspScene, cache: SceneCache
) -> None:
    """Perturbed jobs of one scene key: a scene per (pose, draw), a model copy per design, batched.

    A (pose, draw) that cannot be simulated marks its jobs :attr:`Failure.BAD_POSE`. Backends with
    ``run_scene_chunks`` (MuJoCo C) take :data:`_PIPELINE_CHUNK` scenes a call, each chunk built while
    the one before rolls out; backends with ``run_scenes`` take up to :data:`_SCENES_PER_CALL` scenes a
    call; others a design batch per scene. The outcomes do not depend on the chunking. A scene that a
    draw's start check kept in ``cache`` (:meth:`SceneCache.keep_perturbed`) is taken, not built again.
    """
    scenario = jobs[idx[0]].scenario
    if hasattr(backend, "run_scene_chunks"):
        placed: list[list[int]] = []
        results = backend.run_scene_chunks(
            _perturbed_chunks(jobs, idx, base, cache, scenario, outs, strict, placed),
            scenario,
            observer=observer,
        )
        for n, res in enumerate(results):  # chunk n is in ``placed`` once it has been pulled
            _place(outs, placed[n], res)
        return
    at: dict[tuple, GraspScene | PoseError] = {}
    by_scene: dict[tuple, list[int]] = defaultdict(list)
    for i in idx:
        key = (jobs[i].pose, jobs[i].perturbation)
        if key not in at:
            at[key] = _perturbed_or_error(base, cache, scenario, jobs[i], strict)
        if isinstance(at[key], PoseError):
            outs[i] = failed_outcome(Failure.BAD_POSE, f"bad pose: {at[key]}")
        else:
            by_scene[key].append(i)
    if hasattr(backend, "run_scenes"):
        order = [i for members in by_scene.values() for i in members]
        for k in range(0, len(order), _SCENES_PER_CALL):
            chunk = order[k : k + _SCENES_PER_CALL]
            scenes = [_with_design(at[(jobs[i].pose, jobs[i].perturbation)], jobs[i].design) for i in chunk]
            _place(
                outs,
                chunk,
                backend.run_scenes(scenes, scenario, observer=observer, labels=_labels(jobs, chunk)),
            )
        return
    for key, members in by_scene.items():
        designs = [jobs[i].design for i in members]
        res = backend.run_batch(at[key], scenario, designs, observer=observer, labels=_labels(jobs, members))
        _place(outs, members, res)


def _perturbed_or_error(base: GraspScene, cache: SceneCache, scenario, job: GraspJob, strict: bool):
    """``base`` under ``job``'s draw at its pose, or the :class:`PoseError` (raised with ``strict``)."""
    try:
        return cache.take_perturbed(base, scenario, job.pose, job.perturbation)
    except PoseError as exc:
        if strict:
            raise
        return exc


def _perturbed_chunks(jobs, idx, base, cache, scenario, outs, strict, placed):
    """Chunks ``(scenes, labels, start_keys)`` of the perturbed jobs ``idx``, built as they are pulled.

    Jobs of one (pose, draw) follow each other, so its scene is built once and kept until the next
    (pose, draw); its design copies share its initial state and controls (``start_keys``). Each chunk's
    job indices are appended to ``placed`` before it is yielded; bad poses are marked in ``outs``.
    """
    by_key: dict[tuple, list[int]] = defaultdict(list)
    for i in idx:  # (pose, draw) groups in order of first appearance, as the batched path runs them
        by_key[(jobs[i].pose, jobs[i].perturbation)].append(i)
    members: list[int] = []
    scenes: list[GraspScene] = []
    keys: list[int] = []
    for n, group in enumerate(by_key.values()):
        at = _perturbed_or_error(base, cache, scenario, jobs[group[0]], strict)
        for i in group:
            if isinstance(at, PoseError):
                outs[i] = failed_outcome(Failure.BAD_POSE, f"bad pose: {at}")
                continue
            members.append(i)
            scenes.append(_with_design(at, jobs[i].design))
            keys.append(n)
            if len(members) == _PIPELINE_CHUNK:
                placed.append(members)
                yield scenes, _labels(jobs, members), keys
                members, scenes, keys = [], [], []
    if members:
        placed.append(members)
        yield scenes, _labels(jobs, members), keys


def _run_poses(jobs, members: list[int], base: GraspScene, backend, observer, outs, strict: bool) -> None:
    """One design at the poses of ``members`` (a single job runs alone)."""
    job = jobs[members[0]]
    scene = _with_design(base, job.design)
    ok = []
    for i in members:  # refuse bad poses one by one, so one does not fail the batch
        if _at_pose(scene, jobs[i].pose, [i], outs, strict) is not None:
            ok.append(i)
    if not ok:
        return
    labels = _labels(jobs, ok)
    if len(ok) == 1:
        res = [
            backend.run(
                scene_at_pose(scene, jobs[ok[0]].pose), job.scenario, observer=observer, label=labels[0]
            )
        ]
    else:
        poses = [jobs[i].pose for i in ok]
        res = backend.run_poses(scene, job.scenario, poses, observer=observer, labels=labels)
    _place(outs, ok, res)


def _at_pose(scene: GraspScene, pose: GripperPose, members: list[int], outs: list, strict: bool):
    """The scene at ``pose``, or None after marking ``members`` as bad poses."""
    try:
        return scene_at_pose(scene, pose)
    except PoseError as exc:
        if strict:
            raise
        for i in members:
            outs[i] = failed_outcome(Failure.BAD_POSE, f"bad pose: {exc}")
        return None


def _with_design(scene: GraspScene, design: Stiffness) -> GraspScene:
    """The scene with ``design`` (a model copy; the scene compiled with it is returned as is)."""
    if _design_key(scene.built.stiffness) == _design_key(design):
        return scene
    return scene_with_design(scene, design)


def _design_key(design: Stiffness) -> bytes:
    return np.asarray(design.log_e, dtype=float).tobytes()


def _labels(jobs, members: list[int]) -> list[str]:
    return [jobs[i].label or f"job{i}" for i in members]


def _place(outs: list, members: list[int], results: list[Outcome]) -> None:
    for i, out in zip(members, results, strict=True):
        outs[i] = out


def _at_density(obj: GraspObject, rho: float) -> GraspObject:
    """``obj`` at density ``rho`` [kg/m³]: the same shape, mass and inertia scaled by rho / density."""
    if rho == obj.density:
        return obj
    r = rho / obj.density
    return dataclasses.replace(obj, density=float(rho), mass=obj.mass * r, inertia=obj.inertia * r)


def load_grasp_object(
    source: str | Path,
    density: str | float = "light",
    *,
    mass: str | float | None = None,
    seed: int = 0,
    allow_open: bool = False,
    cache_dir: Path | None = None,
) -> GraspObject:
    """An object ready for a job, watertight, with its convex pieces (CoACD, cached under ``cache_dir``).

    ``source``: a YCB name, ``egad-like:N`` or a mesh file; ``density``: kg/m³ or a preset name.
    ``mass`` overrides the density: ``"real"`` places a YCB object at its published mass
    (:func:`~mjcodesign.objects.published_mass`; :class:`MeshError` for any other object or a YCB
    object without one), ``"auto"`` the published mass where there is one and ``density`` otherwise,
    a number that mass [kg]. Either way the density becomes mass / volume, uniform, and the inertia is
    the uniformly filled mesh's (:func:`~mjcodesign.objects.at_mass`).
    """
    if Path(source).is_dir():
        raise MeshError(f"{source} is a folder: give one object")
    mass = parse_mass(mass)
    if mass in ("real", "auto"):  # a YCB object without a published mass is refused before any loading
        found = mass_by_rule(str(source), mass)
        target = None if found is None else found.mass
    else:
        target = mass
    obj = load_object(source, parse_density(density), allow_open=allow_open, seed=seed)
    if target is not None:
        obj = at_mass(obj, target)
    convex_decomposition(obj, CoacdSettings(seed=seed), cache_dir=cache_dir)
    return obj


def resolve_pose(
    text: str,
    obj: GraspObject,
    geometry: FingerDesign | None = None,
    *,
    seed: int = 0,
    cache_dir: Path | None = None,
) -> GripperPose:
    """A palm pose from a rule (:data:`POSE_RULES`) or a file.

    A file is a candidate file (``FILE.npz`` for its first row, the best, or ``FILE.npz:ROW`` for row
    ``ROW`` counted from 0) or JSON with ``pose`` (4x4) and ``openings`` (2). ``cache_dir`` keeps the
    sampler's signed-distance grid for ``best``. A file's pose must reach the object, and a candidate
    file must have been made for it (``mjcodesign.poses.checks``): :class:`PoseError` otherwise.
    """
    geometry = geometry or FingerDesign()
    if text == "auto":
        return auto_pose(obj, geometry)
    if text == "best":
        return to_gripper_pose(sample_poses(obj, _BEST_OF, seed=seed, design=geometry, cache_dir=cache_dir))
    path, row = _pose_file(text)
    if path.suffix == ".npz":
        cands = read_candidates(path)
        check_candidate_object(path, obj)
        return check_reach(to_gripper_pose(cands, row), obj, geometry)
    if path.suffix == ".npy":
        raise PoseError(f"{path}: a pose file is an .npz from `mjcodesign poses --out` or JSON, not .npy")
    if not path.is_file():
        raise PoseError(f"pose file not found: {path}")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        return check_reach(GripperPose.from_matrix(raw["pose"], tuple(raw["openings"])), obj, geometry)
    except PoseError as exc:
        raise PoseError(f"{path}: {exc}") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise PoseError(f"{path}: not a pose file ({type(exc).__name__}: {exc})") from exc


def _pose_file(text: str) -> tuple[Path, int]:
    """(path, row) of ``FILE`` or ``FILE.npz:ROW``; :class:`PoseError` for a bad row."""
    head, sep, tail = text.rpartition(":")
    if sep and head.endswith(".npz") and not Path(text).is_file():
        if not tail.isdigit():
            raise PoseError(f"bad pose row {tail!r} in {text!r}: use FILE.npz:ROW with ROW an integer >= 0")
        return Path(head), int(tail)
    return Path(text), 0
