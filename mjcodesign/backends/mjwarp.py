"""MuJoCo Warp backend: the designs of a batch are worlds of one device model.

Per-world stiffness (chain): ``jnt_stiffness``, ``dof_damping`` and ``geom_solref`` are batched
(``put_model(batch_sizes=...)``) and filled from :func:`with_stiffness`. Flex moduli are shared by all
worlds in MJWarp, so flex is refused here. The phase controls are copied into ``ctrl`` and
``xfrc_applied`` before every step. The states at the steps the outcome reads are copied back and
the outcome (contact wrench included) is evaluated by :func:`outcome_from_states` with MuJoCo C's
``mj_forward`` on those states, so both backends share one outcome definition. On the CPU the first
step compiles kernels (18–36 s, cached by Warp).
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from mjcodesign.backends.mujoco_c import _initial_state, with_stiffness
from mjcodesign.errors import DesignError
from mjcodesign.scenario import (
    STATE_SPEC,
    GraspScenario,
    GraspScene,
    Outcome,
    failed_outcome,
    outcome_from_states,
    outcome_steps,
    phase_controls,
)
from mjcodesign.stiffness import Stiffness

__all__ = ["MjwarpBackend"]

_BATCHED = ("jnt_stiffness", "dof_damping", "geom_solref")
_NCONMAX_PER_WORLD = 256  # contacts per world (a grasp makes ~20-60)
_NJMAX_PER_WORLD = 1024  # constraint rows per world


class MjwarpBackend:
    """MuJoCo Warp on ``device`` (``"cpu"`` for parity tests; built for GPUs)."""

    def __init__(self, device: str | None = "cpu"):
        try:
            import mujoco_warp  # noqa: F401
            import warp as wp
        except ImportError as exc:
            raise DesignError("the mjwarp backend needs mujoco-warp and warp-lang") from exc
        self.device = device
        wp.config.quiet = True
        if device is not None:
            wp.set_device(device)

    def run(self, scene: GraspScene, scenario: GraspScenario) -> Outcome:
        """One world with the scene's own design."""
        return self.run_batch(scene, scenario, [scene.built.stiffness])[0]

    def run_batch(
        self, scene: GraspScene, scenario: GraspScenario, stiffnesses: list[Stiffness]
    ) -> list[Outcome]:
        """One world per design; a world whose state turns non-finite is a failed outcome."""
        import mujoco_warp as mjw
        import warp as wp

        if scene.built.finger_model.is_flex:
            raise DesignError("mjwarp shares flex stiffness across worlds: use --backend mujoco for flex")
        t0 = time.perf_counter()
        n = len(stiffnesses)
        mjm = scene.model
        models = [with_stiffness(scene, s) for s in stiffnesses]
        m = mjw.put_model(mjm, batch_sizes={f: n for f in _BATCHED})
        for f in _BATCHED:
            arr = getattr(m, f)
            like = arr.numpy()
            host = np.stack([getattr(mi, f) for mi in models]).astype(like.dtype)
            arr.assign(host.reshape(like.shape))
        ctrl, starts = phase_controls(scene, scenario)
        x0 = _initial_state(scene)
        mjd = mujoco.MjData(mjm)
        mujoco.mj_setState(mjm, mjd, x0, STATE_SPEC)
        mujoco.mj_forward(mjm, mjd)
        d = mjw.put_data(mjm, mjd, nworld=n, nconmax=_NCONMAX_PER_WORLD * n, njmax=_NJMAX_PER_WORLD)
        keep = outcome_steps(starts)
        nu, nbody = mjm.nu, mjm.nbody
        states = np.zeros((n, len(ctrl), x0.size))
        scratch = mujoco.MjData(mjm)
        for t in range(len(ctrl)):
            d.ctrl.assign(np.tile(ctrl[t, :nu], (n, 1)))
            d.xfrc_applied.assign(np.tile(ctrl[t, nu:].reshape(nbody, 6), (n, 1, 1)))
            mjw.step(m, d)
            if t in keep:
                qpos, qvel = d.qpos.numpy(), d.qvel.numpy()
                act = d.act.numpy() if mjm.na else None
                for w in range(n):
                    scratch.time = (t + 1) * mjm.opt.timestep
                    scratch.qpos[:] = qpos[w]
                    scratch.qvel[:] = qvel[w]
                    if act is not None:
                        scratch.act[:] = act[w]
                    mujoco.mj_getState(mjm, scratch, states[w, t], STATE_SPEC)
        wp.synchronize()
        outs = []
        for w, mi in enumerate(models):
            if not np.all(np.isfinite(states[w][sorted(keep)])):
                outs.append(failed_outcome("diverged: mjwarp state is not finite"))
                continue
            scene_w = _with_model(scene, mi)
            outs.append(outcome_from_states(scene_w, scenario, x0, states[w], ctrl, starts))
        wall = (time.perf_counter() - t0) / n
        for o in outs:
            o.wall_time_s = wall
        return outs


def _with_model(scene: GraspScene, m: mujoco.MjModel) -> GraspScene:
    from mjcodesign.backends.mujoco_c import _scene_with

    return _scene_with(scene, m)
