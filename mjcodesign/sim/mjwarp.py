"""MuJoCo Warp backend: the designs of a batch are worlds of one device model.

Per-world designs and poses (chain): ``jnt_stiffness``, ``dof_damping``, ``geom_solref`` and the mount
and palm ``body_pos``/``body_quat`` are batched (``put_model(batch_sizes=...)``) and filled from
:func:`with_stiffness` and :func:`scene_at_pose`; each world gets its own initial state and controls.
Flex: MJWarp shares ``flex_stiffness`` across worlds, so a flex design is one model batched over poses
(``run_poses``), and ``run_batch`` runs one model per design in turn; a batch of different flex designs
is refused with :class:`UnsupportedError`. MJWarp 4.0 runs the trilinear flex on Warp's CPU device
(28 s for 13 steps of 2 worlds with compiled kernels), but its flex does not track MuJoCo C's: flex
nodes 0.056 mm apart after 6 steps and 0.70 mm after 13 (a strict expected failure in
``tests/test_mjwarp_parity.py``); untested on CUDA. The phase controls are copied into ``ctrl`` and
``xfrc_applied`` before every step. Every step's sensors and velocities (the energy bound's terms and
its dampers' loss, `mjcodesign.scenarios.energy`) and the full states at the steps the outcome reads
are copied back and the outcome (contact wrench included) is evaluated by
:func:`outcome_from_states` with MuJoCo C's ``mj_forward`` on those states, so both backends share one
outcome definition. On the CPU the first step compiles kernels (18–36 s, cached by Warp).
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.optional import import_warp
from mjcodesign.scenarios.grasp import (
    STATE_SPEC,
    GraspScenario,
    GraspScene,
    build_scene,
    drive_scene,
    phase_controls,
)
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome, outcome_from_states, outcome_steps
from mjcodesign.sim.batch import SceneBatchSimulator
from mjcodesign.sim.mujoco_c import initial_state, scene_with_design
from mjcodesign.sim.observe import Observer, Rollout

__all__ = ["MjwarpBackend"]

# Per-world model fields: a design's stiffness (with_stiffness) and a pose's mount and palm (scene_at_pose).
_BATCHED = ("jnt_stiffness", "dof_damping", "geom_solref", "body_pos", "body_quat", "body_ipos")
_SHARED_CHECKED = (
    "body_mass",
    "body_inertia",
    "geom_friction",
    "actuator_gear",
    "actuator_gainprm",
    "actuator_biasprm",
    "actuator_forcerange",
)  # what a perturbation changes besides the batched fields
_NCONMAX_PER_WORLD = 256  # contacts per world (a grasp makes ~20-60)
_NJMAX_PER_WORLD = 1024  # constraint rows per world


class MjwarpBackend(SceneBatchSimulator):
    """MuJoCo Warp on ``device`` (``"cpu"`` for parity tests; built for GPUs): a ``Simulator``.

    A batch of poses (:meth:`~mjcodesign.sim.batch.SceneBatchSimulator.run_poses`) is one world per
    pose (batched ``body_pos``/``body_quat``) through :meth:`run_scenes`.
    """

    name = "mjwarp"

    def __init__(self, device: str | None = "cpu"):
        try:
            import mujoco_warp  # noqa: F401
            import warp as wp
        except ImportError as exc:
            raise DesignError("the mjwarp backend needs mujoco-warp and warp-lang") from exc
        self.device = device
        import_warp()
        if device is not None:
            wp.set_device(device)

    def run(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
        label: str = "grasp",
    ) -> Outcome:
        """One world with the scene's own design; ``observer`` receives it as ``label``."""
        return self.run_scenes([scene], scenario, observer=observer, labels=[label])[0]

    def run_batch(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        stiffnesses: list[Stiffness],
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """One world per design; a world whose state turns non-finite is a failed outcome.

        Flex: MJWarp shares ``flex_stiffness`` across worlds, so every design is a model of its own, run
        one after the other (each one world); batch a flex design over poses with
        :meth:`~mjcodesign.sim.batch.SceneBatchSimulator.run_poses`.
        ``observer`` receives every rollout, labelled ``labels[i]`` (default ``design{i}``).
        """
        labels = labels or [f"design{i}" for i in range(len(stiffnesses))]
        if scene.built.finger_model.is_flex:
            return [
                self.run_scenes([_flex_design(scene, s)], scenario, observer=observer, labels=[lab])[0]
                for s, lab in zip(stiffnesses, labels, strict=True)
            ]
        scenes = [scene_with_design(scene, s) for s in stiffnesses]
        return self.run_scenes(scenes, scenario, observer=observer, labels=labels)

    def run_scenes(
        self,
        scenes: list[GraspScene],
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """Scenes of one model structure as worlds: per-world model fields, initial state and controls.

        Without an observer only the states the outcome reads are copied back from the device; with
        one, every step's state is (a device-to-host copy per step), and world ``w`` is handed over
        as ``labels[w]`` (default ``world{w}``). Flex scenes must share one design (see the module
        docstring).
        """
        import mujoco_warp as mjw
        import warp as wp

        scenes = [drive_scene(sc, scenario) for sc in scenes]
        for f in _SHARED_CHECKED:  # fields mjwarp shares across worlds: scenes may not differ in them
            ref = getattr(scenes[0].model, f)
            if any(not np.array_equal(getattr(sc.model, f), ref) for sc in scenes[1:]):
                raise UnsupportedError(
                    f"mjwarp shares {f} across worlds: scenes that differ in it (perturbed mass, friction "
                    "or tendon drive) need the mujoco backend"
                )
        flex0 = scenes[0].model.flex_stiffness
        if any(not np.array_equal(sc.model.flex_stiffness, flex0) for sc in scenes[1:]):
            raise UnsupportedError(
                "mjwarp shares flex stiffness across worlds: batch one flex design over poses"
            )
        t0 = time.perf_counter()
        n = len(scenes)
        mjm = scenes[0].model
        m = mjw.put_model(mjm, batch_sizes={f: n for f in _BATCHED})
        for f in _BATCHED:
            arr = getattr(m, f)
            like = arr.numpy()
            host = np.stack([getattr(sc.model, f) for sc in scenes]).astype(like.dtype)
            arr.assign(host.reshape(like.shape))
        plans = [phase_controls(sc, scenario) for sc in scenes]
        starts = plans[0][1]
        ctrl = np.stack([c for c, _ in plans])
        x0 = np.stack([initial_state(sc) for sc in scenes])
        nq, nv, na = mjm.nq, mjm.nv, mjm.na
        mjd = mujoco.MjData(mjm)
        mujoco.mj_setState(mjm, mjd, x0[0], STATE_SPEC)
        mujoco.mj_forward(mjm, mjd)
        d = mjw.put_data(mjm, mjd, nworld=n, nconmax=_NCONMAX_PER_WORLD * n, njmax=_NJMAX_PER_WORLD)
        d.qpos.assign(x0[:, 1 : 1 + nq])  # state = (time, qpos, qvel, act, ...)
        d.qvel.assign(x0[:, 1 + nq : 1 + nq + nv])
        keep = set(range(ctrl.shape[1])) if observer is not None else outcome_steps(starts)
        keep |= {
            starts["impulse"] - 1,
            starts["impulse"],
        }  # the impulse's work needs the velocities around it
        nu, nbody = mjm.nu, mjm.nbody
        states = np.zeros((n, ctrl.shape[1], x0.shape[1]))
        sensors = np.zeros((n, ctrl.shape[1], mjm.nsensordata))  # every step: the energy bound sums them
        scratch = mujoco.MjData(mjm)
        for t in range(ctrl.shape[1]):
            d.ctrl.assign(ctrl[:, t, :nu])
            d.xfrc_applied.assign(ctrl[:, t, nu:].reshape(n, nbody, 6))
            mjw.step(m, d)
            sensors[:, t] = d.sensordata.numpy()
            # The energy bound's damper loss sums b v² over every step: a step whose velocities were
            # left at zero drops that loss and loosens the bound (MuJoCo C's rollout has them all).
            states[:, t, 1 + nq : 1 + nq + nv] = d.qvel.numpy()
            if t in keep:
                qpos, qvel = d.qpos.numpy(), d.qvel.numpy()
                act = d.act.numpy() if na else None
                for w in range(n):
                    scratch.time = (t + 1) * mjm.opt.timestep
                    scratch.qpos[:] = qpos[w]
                    scratch.qvel[:] = qvel[w]
                    if act is not None:
                        scratch.act[:] = act[w]
                    mujoco.mj_getState(mjm, scratch, states[w, t], STATE_SPEC)
        wp.synchronize()
        outs = []
        for w, sc in enumerate(scenes):
            if not np.all(np.isfinite(states[w][sorted(keep)])):
                outs.append(failed_outcome(Failure.DIVERGED, "diverged: mjwarp state is not finite"))
                continue
            outs.append(
                outcome_from_states(sc, scenario, x0[w], states[w], ctrl[w], starts, sensordata=sensors[w])
            )
        wall = (time.perf_counter() - t0) / n
        outs = [o.with_wall_time(wall) for o in outs]
        labels = labels or [f"world{w}" for w in range(n)]
        for w, sc in enumerate(scenes if observer is not None else ()):
            finite = np.all(np.isfinite(states[w]), axis=1)
            valid = len(finite) if finite.all() else int(np.argmin(finite))  # up to the first bad state
            observer.rollout(
                Rollout(
                    labels[w],
                    sc,
                    scenario,
                    sc.model,
                    sc.built.stiffness.log_e,
                    x0[w],
                    states[w][:valid],
                    ctrl[w],
                    starts,
                    outs[w],
                )
            )
        return outs


def _flex_design(scene: GraspScene, stiffness: Stiffness) -> GraspScene:
    """The scene rebuilt with a flex design of its own (the flex stiffness is compiled into the model)."""
    b = scene.built
    return build_scene(scene.obj, b.design, stiffness, b.finger_model, scene.pose, options=b.options)
