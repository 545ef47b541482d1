"""MuJoCo C backend: one rollout stepped from Python, or a batch through ``mujoco.rollout``."""

from __future__ import annotations

import copy
import dataclasses
import functools
import os
import queue
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import SimulationDiverged
from mjcodesign.models.builder import make_data
from mjcodesign.models.chain import contact_solrefs, joint_stiffness
from mjcodesign.models.simulate import captured_warnings, check_state, has_warning, reset_warnings
from mjcodesign.scenarios.grasp import (
    STATE_SPEC,
    GraspScenario,
    GraspScene,
    control_spec,
    drive_scene,
    phase_controls,
)
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome, outcome_from_states
from mjcodesign.sim.batch import SceneBatchSimulator
from mjcodesign.sim.observe import Capture, Observer, Rollout

__all__ = ["MujocoBackend", "initial_state", "scene_with_design", "scene_with_model", "with_stiffness"]

_CLOCK_TOL = 0.5  # [steps]: a rollout's time off by half a step means MuJoCo reset it


@functools.lru_cache(maxsize=8)
def _blocks(design: FingerDesign) -> tuple:
    return tuple(design.blocks())


def with_stiffness(scene: GraspScene, stiffness: Stiffness) -> mujoco.MjModel:
    """A copy of the scene's model with another design's stiffness.

    Chain: hinge stiffness and damping (:func:`mjcodesign.models.chain.joint_stiffness`, the rule the
    model was built with; ~0.1 ms a finger for the FEM calibration) and the blocks' contact solref
    (:func:`mjcodesign.models.chain.contact_solrefs`) are rewritten instead of a recompile; the
    test checks they equal a recompiled model bitwise. Flex: each cell's stiffness record is rescaled to
    the design's cell modulus (:func:`mjcodesign.models.flex.rescale_cell_young`; equal to a recompile
    to round-off, tested).
    """
    return _stiffness_writer(scene)(stiffness)


def _stiffness_writer(scene: GraspScene) -> Callable[[Stiffness], mujoco.MjModel]:
    """:func:`with_stiffness` for many designs of one scene: the ids are looked up once."""
    built = scene.built
    if built.finger_model.is_flex:
        from mjcodesign.models.flex import rescale_cell_young

        def flex(stiffness: Stiffness) -> mujoco.MjModel:
            m = copy.copy(scene.model)
            for h, young in zip(built.fingers, stiffness.young, strict=True):
                rescale_cell_young(m, h, built.design, young, built.options)
            return m

        return flex
    design, opts = built.design, built.options
    ids = _chain_ids(scene)

    def chain(stiffness: Stiffness) -> mujoco.MjModel:
        m = copy.copy(scene.model)
        for (jids, dofs, gids, owner, blocks_of), young in zip(ids, stiffness.young, strict=True):
            k, damping, solref = _finger_numbers(design, opts, tuple(float(e) for e in young))
            m.jnt_stiffness[jids] = k[blocks_of]
            m.dof_damping[dofs] = damping[blocks_of]
            m.geom_solref[gids] = solref[owner]
        return m

    return chain


@functools.lru_cache(maxsize=256)
def _finger_numbers(design: FingerDesign, options, young: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    """One finger's hinge stiffness, damping and block contact solrefs for ``young`` (read-only arrays).

    Cached: an evaluation writes each design into a model copy per (pose, draw), the same numbers each
    time (:func:`~mjcodesign.models.chain.joint_stiffness`, ~0.2 ms a finger).
    """
    e = np.array(young)
    k, damping = joint_stiffness(design, e, options)
    solref = contact_solrefs(list(_blocks(design)), e, design.density, options.timestep)
    for a in (k, damping, solref):
        a.setflags(write=False)
    return k, damping, solref


def _chain_ids(scene: GraspScene) -> list[tuple[np.ndarray, ...]]:
    """Per finger: hinge ids and dofs, solref geoms and their blocks, and each hinge's block.

    A block has one hinge or two (``SimOptions.hinges_per_block``; their stiffness and damping:
    :func:`mjcodesign.models.chain.joint_stiffness`), and one to three geoms (its proximal, middle and
    distal pieces).
    """
    m = scene.model
    n_blocks = scene.built.design.n_blocks
    out = []
    for h in scene.built.fingers:
        jids = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name) for name in h.joints])
        blocks_of = np.array(h.joint_blocks, dtype=int)
        gids, owner = [], []
        for b in range(n_blocks):
            for part in ("p", "m", "d"):
                g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{h.prefix}b{b}_{part}")
                if g >= 0:
                    gids.append(g)
                    owner.append(b)
        out.append((jids, m.jnt_dofadr[jids].copy(), np.array(gids, dtype=int), np.array(owner, dtype=int),
                    blocks_of))  # fmt: skip
    return out


def initial_state(scene: GraspScene) -> np.ndarray:
    """The scene's state at t=0 (``mjSTATE_FULLPHYSICS``): fingers at the start openings, object at rest."""
    d = make_data(scene.built)
    x0 = np.empty(mujoco.mj_stateSize(scene.model, STATE_SPEC))
    mujoco.mj_getState(scene.model, d, x0, STATE_SPEC)
    return x0


def _step_all(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    x0: np.ndarray,
    ctrl: np.ndarray,
    states: np.ndarray,
    sensordata: np.ndarray,
    *,
    checked: bool,
    capture: Capture | None = None,
    steps: frozenset[int] = frozenset(),
    captured: dict | None = None,
) -> tuple[int, SimulationDiverged] | None:
    """Run every step from ``x0`` into ``states`` (and each step's sensors into ``sensordata``).

    ``checked`` checks MuJoCo's warnings and the state after every step and stops at the first bad
    one: ``(step, error)``; None when every step passed, or always when unchecked. ``capture`` takes
    state t (of ``steps``, -1 the initial state) into ``captured[t]`` right after step t+1, while the
    data still holds that state's forward quantities (:class:`~mjcodesign.sim.observe.Capture`).
    """
    reset_warnings(d)
    mujoco.mj_setState(m, d, x0, STATE_SPEC)
    spec = control_spec()
    for t in range(len(ctrl)):
        mujoco.mj_setState(m, d, ctrl[t], spec)
        mujoco.mj_step(m, d)
        if t - 1 in steps:
            captured[t - 1] = capture.capture(m, d)
        if checked:
            try:
                check_state(d, f"step {t}: ")
            except SimulationDiverged as exc:
                return t, exc
        mujoco.mj_getState(m, d, states[t], STATE_SPEC)
        sensordata[t] = d.sensordata
    return None


class MujocoBackend(SceneBatchSimulator):
    """MuJoCo C, a ``Simulator``; ``nthread`` defaults to every core the process may use.

    A batch of poses (:meth:`~mjcodesign.sim.batch.SceneBatchSimulator.run_poses`) is one
    ``mujoco.rollout`` call through :meth:`run_scenes`.
    """

    name = "mujoco"

    def __init__(self, nthread: int | None = None):
        self.nthread = nthread or len(os.sched_getaffinity(0))

    def run(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
        label: str = "grasp",
    ) -> Outcome:
        """Step the scenario one ``mj_step`` at a time; MuJoCo's warnings are failures.

        The steps run unchecked, and the warnings and the states are checked once at the end; if
        either is bad, the same (deterministic) steps run again with a check after every one, which
        names the first bad step. ``observer`` receives the full rollout (its states up to a
        divergence) under ``label``.
        """
        t0 = time.perf_counter()
        scene = drive_scene(scene, scenario)
        m = scene.model
        ctrl, starts = phase_controls(scene, scenario)
        x0 = initial_state(scene)
        d = mujoco.MjData(m)
        states = np.empty((len(ctrl), x0.size))
        sensors = np.empty((len(ctrl), m.nsensordata))
        captured: dict = {}
        capture = observer if isinstance(observer, Capture) else None
        steps = (
            frozenset(capture.capture_steps(len(ctrl), m.opt.timestep, starts)) if capture else frozenset()
        )
        with captured_warnings() as printed:
            bad = _step_all(
                m,
                d,
                x0,
                ctrl,
                states,
                sensors,
                checked=False,
                capture=capture,
                steps=steps,
                captured=captured,
            )
            reset = _diverged(states[None], x0[None], m.opt.timestep)[0]
            if has_warning(d) or reset or printed:  # again, step by step, to name the step
                bad = _step_all(m, d, x0, ctrl, states, sensors, checked=True)
                if bad is None:
                    bad = len(ctrl), SimulationDiverged(f"MuJoCo warned: {printed[0]}")
        if bad is not None:
            t, exc = bad
            out = failed_outcome(Failure.DIVERGED, _diverged_reason(exc, printed), time.perf_counter() - t0)
            captured = {k: v for k, v in captured.items() if k < t}
            _observe(
                observer, label, scene, scenario, m, x0, states[:t], ctrl, starts, out, captured=captured
            )
            return out
        out = outcome_from_states(scene, scenario, x0, states, ctrl, starts, sensordata=sensors)
        out = out.with_wall_time(time.perf_counter() - t0)
        _observe(
            observer, label, scene, scenario, m, x0, states, ctrl, starts, out, scratch=d, captured=captured
        )
        return out

    def run_batch(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        stiffnesses: list[Stiffness],
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """All designs at the scene's pose through one ``mujoco.rollout`` call on ``nthread`` threads.

        ``wall_time_s`` is the batch's wall time shared evenly (see :meth:`run_scenes`). ``observer``
        receives every rollout, labelled ``labels[i]`` (default ``design{i}``).
        """
        labels = labels or [f"design{i}" for i in range(len(stiffnesses))]
        write = _stiffness_writer(scene)
        scenes = [_scene_with(scene, write(s), s) for s in stiffnesses]
        return self._run_scenes(scenes, scenario, observer, labels, same_start=True)

    def run_scenes(
        self,
        scenes: list[GraspScene],
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """Scenes of one model structure (other designs or poses), batched through ``mujoco.rollout``.

        A rollout diverged if its recorded time is not the step count times dt (MuJoCo resets the data
        after a bad acceleration) or its state is not finite; MuJoCo warnings left in a thread's data
        are checked too. Diverged rollouts, or all when a warning is left, are re-run one step at a
        time by :meth:`run`, which names the warning. The outcomes (contact-force replays) are then
        evaluated on ``nthread`` threads; MuJoCo releases the GIL in ``mj_forward``. ``observer``
        receives every rollout, labelled ``labels[i]`` (default ``scene{i}``).
        """
        return self._run_scenes(
            scenes, scenario, observer, labels or [f"scene{i}" for i in range(len(scenes))]
        )

    def run_scene_chunks(
        self,
        chunks: Iterable[tuple[list[GraspScene], list[str], list | None]],
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
    ) -> Iterator[list[Outcome]]:
        """:meth:`run_scenes` over a stream of chunks, each chunk's outcomes yielded in order.

        A chunk is ``(scenes, labels, start_keys)``: scenes with equal ``start_keys`` (not None) differ
        only in stiffness and share one initial state and control sequence. The rollout of chunk k runs
        on a thread of its own (``mujoco.rollout`` releases the GIL) while this thread pulls chunk k+1
        from ``chunks`` (the caller may build it then) and evaluates the outcomes of chunk k-1, so the
        Python work of a chunk overlaps the rollouts of its neighbours. A chunk that needs step-by-step
        reruns (:meth:`run`) runs them only once the next chunk's rollout has ended, so that no other
        rollout's warning can reach theirs. The outcomes equal :meth:`run_scenes`' chunk by chunk: the
        same rollouts and the same checks, in another order. ``wall_time_s`` is a chunk's time from its
        rollout's start to its outcomes, shared evenly.
        """
        with ThreadPoolExecutor(max_workers=1) as rollouts:
            pending = None
            for scenes, labels, keys in chunks:
                started = self._start(scenes, scenario, labels, start_keys=keys, pool=rollouts)
                if pending is not None:  # its step-by-step reruns, if any, wait for this rollout to end
                    yield self._finish(pending, observer, settle=started.future.result)
                pending = started
            if pending is not None:
                yield self._finish(pending, observer)

    def _run_scenes(self, scenes, scenario, observer, labels, *, same_start: bool = False) -> list[Outcome]:
        """:meth:`run_scenes`, with ``same_start`` when the scenes differ only in stiffness.

        Then (:meth:`run_batch`) they share one initial state and one control sequence (neither
        depends on stiffness), made once and broadcast by ``mujoco.rollout``.
        """
        return self._finish(self._start(scenes, scenario, labels, same_start=same_start), observer)

    def _start(
        self, scenes, scenario, labels, *, same_start: bool = False, start_keys=None, pool=None
    ) -> _Started:
        """Drive the scenes, make their initial states and controls, and start their rollout.

        The rollout runs in ``pool`` (a future) or here (a finished future) when ``pool`` is None.
        """
        t0 = time.perf_counter()
        scenes = [drive_scene(sc, scenario) for sc in scenes]
        n = len(scenes)
        if same_start:  # one control sequence and initial state, which mujoco.rollout broadcasts
            c0, starts = phase_controls(scenes[0], scenario)
            ctrl_in, x0_in = c0[None], initial_state(scenes[0])[None]
            ctrl, x0 = np.broadcast_to(ctrl_in, (n, *c0.shape)), np.broadcast_to(x0_in, (n, x0_in.shape[1]))
        else:
            if start_keys is None:  # scenes share a start only when they are the same scene and pose
                start_keys = [(id(sc.built), sc.pose) for sc in scenes]
            plans: dict = {}
            for sc, key in zip(scenes, start_keys, strict=True):
                if key not in plans:
                    plans[key] = (*phase_controls(sc, scenario), initial_state(sc))
            rows = [plans[key] for key in start_keys]
            starts = rows[0][1]
            ctrl_in = ctrl = np.stack([c for c, _, _ in rows])
            x0_in = x0 = np.stack([x for _, _, x in rows])
        models = [sc.model for sc in scenes]
        datas = [mujoco.MjData(models[0]) for _ in range(min(self.nthread, n))]
        for d in datas:
            reset_warnings(d)

        def roll():
            if pool is not None:  # pipelined: the chunk's time starts with its rollout
                started.t0 = time.perf_counter()
            with captured_warnings() as printed:
                states, sensors = mj_rollout.rollout(
                    models, datas, x0_in, ctrl_in, control_spec=control_spec()
                )
            return states, sensors, printed

        started = _Started(scenes, scenario, labels, models, datas, x0, ctrl, starts, None, t0)
        started.future = pool.submit(roll) if pool is not None else _done(roll())
        return started

    def _finish(
        self, started: _Started, observer, *, settle: Callable[[], object] | None = None
    ) -> list[Outcome]:
        """Wait for a started rollout, check it, and evaluate its outcomes (see :meth:`run_scenes`).

        ``settle`` is called before any step-by-step rerun (it waits for a rollout still in flight).
        """
        scenes, scenario, labels, models = started.scenes, started.scenario, started.labels, started.models
        x0, ctrl, starts = started.x0, started.ctrl, started.starts
        states, sensors, printed = started.future.result()
        bad = _diverged(states, x0, models[0].opt.timestep)
        warned = bool(printed)
        for d in started.datas:
            try:
                check_state(d)
            except SimulationDiverged:
                warned = True
        if warned:
            bad[:] = True
        outs: list[Outcome | None] = [None] * len(scenes)
        if settle is not None and bad.any():
            settle()
        for i in np.flatnonzero(bad):  # run() hands these to the observer itself
            outs[i] = self.run(scenes[i], scenario, observer=observer, label=labels[i])
        good = np.flatnonzero(~bad)
        # The rollout's data (one per thread) are scratch for the replays now: _Replay clears the warm
        # start, so the forces equal those of fresh data.
        scratch = queue.SimpleQueue()
        for d in started.datas:
            scratch.put(d)

        def evaluate(i: int) -> Outcome:
            d = scratch.get()
            try:
                return outcome_from_states(
                    scenes[i], scenario, x0[i], states[i], ctrl[i], starts, d, sensordata=sensors[i]
                )
            finally:
                scratch.put(d)

        if len(started.datas) > 1 and len(good) > 1:
            with ThreadPoolExecutor(max_workers=len(started.datas)) as pool:
                done = list(pool.map(evaluate, good))
        else:  # one thread (datagen's worker threads): no pool to start per batch
            done = [evaluate(i) for i in good]
        for i, out in zip(good, done, strict=True):
            outs[i] = out
        wall = (time.perf_counter() - started.t0) / len(scenes)
        outs = [o.with_wall_time(wall) for o in outs]
        for i in good if observer is not None else ():
            sc = scenes[i]
            observer.rollout(
                Rollout(
                    labels[i],
                    sc,
                    scenario,
                    sc.model,
                    sc.built.stiffness.log_e,
                    x0[i],
                    states[i],
                    ctrl[i],
                    starts,
                    outs[i],
                )
            )
        return outs


@dataclasses.dataclass
class _Started:
    """A batch whose rollout has started (:meth:`MujocoBackend._start`): what finishing it needs."""

    scenes: list[GraspScene]
    scenario: GraspScenario
    labels: list[str]
    models: list[mujoco.MjModel]
    datas: list[mujoco.MjData]
    x0: np.ndarray
    ctrl: np.ndarray
    starts: dict[str, int]
    future: Future | None
    t0: float
    """When the batch started (its rollout's start, once that has begun)."""


def _done(value) -> Future:
    """A future that already holds ``value``."""
    f: Future = Future()
    f.set_result(value)
    return f


def _observe(
    observer, label, scene, scenario, m, x0, states, ctrl, starts, out, scratch=None, captured=None
) -> None:
    if observer is not None:
        sc = scene_with_model(scene, m)
        observer.rollout(
            Rollout(
                label,
                sc,
                scenario,
                m,
                sc.built.stiffness.log_e,
                x0,
                states,
                ctrl,
                starts,
                out,
                scratch=scratch,
                captured=captured or {},
            )
        )


def _diverged_reason(exc: SimulationDiverged, printed: list[str]) -> str:
    """``diverged: ...`` with the first bad step's error and how many warnings MuJoCo raised."""
    extra = f"; MuJoCo raised {len(printed)} warning(s), the first: {printed[0]}" if printed else ""
    return f"diverged: {exc}{extra}"


def _diverged(states: np.ndarray, x0: np.ndarray, dt: float) -> np.ndarray:
    """Per rollout: True if its state is not finite or its clock was reset (MuJoCo's auto-reset)."""
    nstep = states.shape[1]
    expected = x0[:, :1] + dt * np.arange(1, nstep + 1)[None, :]
    finite = np.all(np.isfinite(states), axis=(1, 2))
    clock = np.all(np.abs(states[:, :, 0] - expected) < _CLOCK_TOL * dt, axis=1)
    return ~(finite & clock)


def scene_with_model(scene: GraspScene, m: mujoco.MjModel) -> GraspScene:
    """The scene with another model of the same structure (ids unchanged), under the scene's design.

    ``built`` (its design, ``built.stiffness``) is kept: a rollout of the result is handed to an observer
    as that design. For another design use :func:`scene_with_design`.
    """
    if m is scene.model:
        return scene
    other = copy.copy(scene)
    other.model = m
    return other


def scene_with_design(scene: GraspScene, stiffness: Stiffness) -> GraspScene:
    """The scene with another design: a model copy (:func:`with_stiffness`) and a ``built`` naming it.

    The ``built`` names that model and design, so an observer colours the rollout by the design that ran.
    """
    return _scene_with(scene, with_stiffness(scene, stiffness), stiffness)


def _scene_with(scene: GraspScene, m: mujoco.MjModel, stiffness: Stiffness) -> GraspScene:
    other = copy.copy(scene)
    other.built = dataclasses.replace(scene.built, model=m, stiffness=stiffness)
    other.model = m
    return other
