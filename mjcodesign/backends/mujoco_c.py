"""MuJoCo C backend: one rollout stepped from Python, or a batch through ``mujoco.rollout``."""

from __future__ import annotations

import copy
import functools
import os
import time
from typing import NamedTuple, Protocol

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjcodesign.beam import block_bending_compliance
from mjcodesign.chain import contact_solref
from mjcodesign.errors import SimulationDiverged
from mjcodesign.finger import FingerDesign
from mjcodesign.mjcf import make_data
from mjcodesign.observe import Observer, Rollout
from mjcodesign.scenario import (
    STATE_SPEC,
    GraspScenario,
    GraspScene,
    Outcome,
    build_scene,
    control_spec,
    failed_outcome,
    outcome_from_states,
    phase_controls,
)
from mjcodesign.simulate import check_state, reset_warnings
from mjcodesign.stiffness import Stiffness

__all__ = ["GraspBackend", "MujocoBackend", "with_stiffness"]


class GraspBackend(Protocol):
    """What every grasp simulator offers."""

    def run(self, scene: GraspScene, scenario: GraspScenario) -> Outcome:
        """One rollout of the scenario; a divergence is a failed outcome, never an exception."""
        ...

    def run_batch(
        self, scene: GraspScene, scenario: GraspScenario, stiffnesses: list[Stiffness]
    ) -> list[Outcome]:
        """One rollout per design on the same object and pose."""
        ...


class _BlockFacts(NamedTuple):
    """What the chain's stiffness and contact formulas read from a block (computed once per design)."""

    length: float
    width: float
    volume: float
    compliance: float
    """∫ dx / I(x) over the block [m^-3]."""


@functools.lru_cache(maxsize=8)
def _block_facts(design: FingerDesign) -> tuple[_BlockFacts, ...]:
    return tuple(
        _BlockFacts(b.length, b.width, b.volume, block_bending_compliance(b)) for b in design.blocks()
    )


def with_stiffness(scene: GraspScene, stiffness: Stiffness) -> mujoco.MjModel:
    """A copy of the scene's model with another design's stiffness.

    Chain: hinge stiffness k = E I / l (the arithmetic of :func:`mjcodesign.chain.hinge_stiffness`),
    damping ``damping_time`` k and the blocks' contact solref (:func:`mjcodesign.chain.contact_solref`)
    are rewritten instead of a recompile; the test checks they equal a recompiled model bitwise. Flex:
    the scene is rebuilt (its cell moduli are compiled into the flex).
    """
    built = scene.built
    if built.finger_model.is_flex:
        return build_scene(
            scene.obj, built.design, stiffness, built.finger_model, scene.pose, options=built.options
        ).model
    m = copy.copy(scene.model)
    design, opts = built.design, built.options
    facts = _block_facts(design)
    ids = _chain_ids(scene)
    for i, young in enumerate(stiffness.young):
        for j, (f, e) in enumerate(zip(facts, young, strict=True)):
            k = float(e) * f.length / f.compliance / f.length  # == block_effective_ei(b, e) / b.length
            jid, gids = ids[i][j]
            m.jnt_stiffness[jid] = k
            m.dof_damping[m.jnt_dofadr[jid]] = opts.damping_time * k
            solref = contact_solref(f, float(e), design.density, opts.timestep)
            for gid in gids:
                m.geom_solref[gid] = solref
    return m


def _chain_ids(scene: GraspScene) -> list[list[tuple[int, list[int]]]]:
    """Per finger, per block: (hinge joint id, ids of the geoms carrying the block's contact solref)."""
    m = scene.model
    out = []
    for h in scene.built.fingers:
        rows = []
        for j, name in enumerate(h.joints):
            gids = [
                mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{h.prefix}b{j}_{part}")
                for part in ("p", "d")
            ]
            rows.append((mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name), [g for g in gids if g >= 0]))
        out.append(rows)
    return out


def _initial_state(scene: GraspScene) -> np.ndarray:
    d = make_data(scene.built)
    x0 = np.empty(mujoco.mj_stateSize(scene.model, STATE_SPEC))
    mujoco.mj_getState(scene.model, d, x0, STATE_SPEC)
    return x0


class MujocoBackend:
    """MuJoCo C. ``nthread`` defaults to every core the process may use."""

    def __init__(self, nthread: int | None = None):
        self.nthread = nthread or len(os.sched_getaffinity(0))

    def run(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        model: mujoco.MjModel | None = None,
        *,
        observer: Observer | None = None,
        label: str = "grasp",
    ) -> Outcome:
        """Step the scenario one ``mj_step`` at a time, checking MuJoCo's warnings after every step.

        ``observer`` receives the full rollout (its states up to a divergence) under ``label``.
        """
        t0 = time.perf_counter()
        m = model or scene.model
        ctrl, starts = phase_controls(scene, scenario)
        x0 = _initial_state(scene)
        d = mujoco.MjData(m)
        mujoco.mj_setState(m, d, x0, STATE_SPEC)
        states = np.empty((len(ctrl), x0.size))
        spec = control_spec()
        try:
            for t in range(len(ctrl)):
                mujoco.mj_setState(m, d, ctrl[t], spec)
                mujoco.mj_step(m, d)
                check_state(d, f"step {t}: ")
                mujoco.mj_getState(m, d, states[t], STATE_SPEC)
        except SimulationDiverged as exc:
            out = failed_outcome(f"diverged: {exc}", time.perf_counter() - t0)
            _observe(observer, label, scene, scenario, m, x0, states[:t], ctrl, starts, out)
            return out
        out = outcome_from_states(_scene_with(scene, m), scenario, x0, states, ctrl, starts)
        out.wall_time_s = time.perf_counter() - t0
        _observe(observer, label, scene, scenario, m, x0, states, ctrl, starts, out)
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
        """All designs through one ``mujoco.rollout`` call on ``nthread`` threads.

        Every thread's MjData warnings are checked afterwards; if any warned, the batch is re-run one
        rollout at a time to find which diverged. ``wall_time_s`` is the batch's wall time shared evenly.
        ``observer`` receives every rollout, labelled ``labels[i]`` (default ``design{i}``).
        """
        labels = labels or [f"design{i}" for i in range(len(stiffnesses))]
        t0 = time.perf_counter()
        models = [with_stiffness(scene, s) for s in stiffnesses]
        ctrl, starts = phase_controls(scene, scenario)
        x0 = _initial_state(scene)
        datas = [mujoco.MjData(models[0]) for _ in range(min(self.nthread, len(models)))]
        for d in datas:
            reset_warnings(d)
        states, _ = mj_rollout.rollout(models, datas, x0[None], ctrl[None], control_spec=control_spec())
        warned = False
        for d in datas:
            try:
                check_state(d)
            except SimulationDiverged:
                warned = True
        if warned or not np.all(np.isfinite(states)):
            outs = [
                self.run(scene, scenario, model=mi, observer=observer, label=lb)
                for mi, lb in zip(models, labels, strict=True)
            ]
            observer = None  # run() handed them over
        else:
            outs = [
                outcome_from_states(_scene_with(scene, mi), scenario, x0, states[i], ctrl, starts)
                for i, mi in enumerate(models)
            ]
        wall = (time.perf_counter() - t0) / len(models)
        for o in outs:
            o.wall_time_s = wall
        for i, o in enumerate(outs if observer is not None else []):
            _observe(observer, labels[i], scene, scenario, models[i], x0, states[i], ctrl, starts, o)
        return outs


def _observe(observer, label, scene, scenario, m, x0, states, ctrl, starts, out) -> None:
    if observer is not None:
        observer.rollout(Rollout(label, _scene_with(scene, m), scenario, m, x0, states, ctrl, starts, out))


def _scene_with(scene: GraspScene, m: mujoco.MjModel) -> GraspScene:
    """The scene with another model of the same structure (ids unchanged)."""
    if m is scene.model:
        return scene
    other = copy.copy(scene)
    other.model = m
    return other
