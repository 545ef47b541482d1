"""The MuJoCo grasp scenario's open-loop controls at the FEM's substeps.

`grasp_schedule` reads the controls of `mjcodesign.scenarios.grasp.phase_controls` (one row per MuJoCo
step of ``scene.model.opt.timestep``) and turns them into tables indexed by the FEM substep ``s``
(1-based; substep s runs from (s−1)·dt to s·dt):

* the openings and the lift are position servos in the MuJoCo gripper. The FEM moves each finger's
  base as the servo's own response to the same commands: m ẍ = kp (u − x) − (kv + b) ẋ with kp, kv
  of the compiled actuator, the joint's damping b and the mass the joint carries (``body_subtreemass``),
  solved exactly for the zero-order-hold command. The load of the fingers on the servos is left out:
  a soft finger bent 3 mm pushes back with millinewtons, a servo error of 1 mm with 0.5 N (openings);
* the tendon tension and the disturbance force are held over each MuJoCo step, as MuJoCo applies them.
  In position mode (`mjcodesign.scenarios.drive.TendonPosition`) the tension is the servo's, computed
  by the FEM each substep from its own tendon length: the schedule gives the length the motor has wound
  in (``wound``, the MuJoCo targets' ramp) and the servo's constants (``servo``).

Times that the outcome reads (`mjcodesign.scenarios.outcome.outcome_steps`: the hold samples, the grasp
at the end of tightening, the end) map MuJoCo's state after step t to substep (t + 1)·J, with J the
substeps per MuJoCo step (an integer: the FEM step must divide MuJoCo's).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import scipy.linalg

from mjcodesign.errors import DesignError
from mjcodesign.scenarios.drive import TendonPosition, tendon_targets
from mjcodesign.scenarios.grasp import GraspScenario, GraspScene, drive_scene, phase_controls
from mjcodesign.scenarios.outcome import outcome_steps

__all__ = ["GraspSchedule", "grasp_schedule"]

_RATIO_TOL = 1e-6
"""How far the MuJoCo step over the FEM step may be from an integer (relative)."""


@dataclass(frozen=True, eq=False)
class GraspSchedule:
    """The controls of one grasp at every FEM substep (index s = 0 … ``n_steps``; s = 0 is t = 0)."""

    dt: float
    """FEM substep [s]."""
    per_step: int
    """FEM substeps per MuJoCo step (J)."""
    n_steps: int
    """FEM substeps in the grasp."""
    openings: np.ndarray
    """Carriage positions [m] at the end of every substep, shape (n_steps + 1, 2)."""
    lift: np.ndarray
    """Palm rise [m] at the end of every substep, shape (n_steps + 1,)."""
    tension: np.ndarray
    """Tendon tension of each finger during substep s [N], shape (n_steps + 1, 2) (row 0 unused; in
    position mode NaN, a table the servo kernel fills as the FEM steps)."""
    push: np.ndarray
    """External force on the object's COM during substep s [N], shape (n_steps + 1, 3) (row 0 unused)."""
    starts: dict
    """First MuJoCo step of every phase, and ``end`` (`phase_controls`)."""
    grasp_step: int
    """Substep at the end of tightening: the displacement's reference."""
    hold: tuple[int, int]
    """First and last substep of the body-force average (the MuJoCo hold samples' span)."""
    samples: tuple[int, ...]
    """Substeps of the MuJoCo outcome's states (`outcome_steps`), sorted."""
    wound: np.ndarray | None = None
    """Position mode: tendon length the motor has wound in during substep s [m], shape (n_steps + 1,)
    (the target is ℓ* = ℓ₀ − wound, ℓ₀ the FEM tendon's slack length); None in force mode."""
    servo: tuple[float, float, float] | None = None
    """Position mode: the servo's stiffness k [N/m], tension limit T_max [N] and damping b [N·s/m] on
    the tendon (`TendonPosition`); None in force mode (``tension`` is the ramp)."""

    def offsets(self, axes: np.ndarray) -> np.ndarray:
        """Each finger base's displacement from t = 0 [m], shape (n_steps + 1, 2, 3).

        ``axes`` (2, 3) are the fingers' opening directions in the world; the lift is along world z.
        """
        d = (self.openings - self.openings[0])[:, :, None] * np.asarray(axes, dtype=float)[None]
        d[:, :, 2] += self.lift[:, None]
        return d


def grasp_schedule(scene: GraspScene, scenario: GraspScenario, dt: float) -> GraspSchedule:
    """The scenario's controls in ``scene`` at FEM substeps of ``dt`` [s] (see the module docstring)."""
    position = isinstance(scenario.tendon, TendonPosition)
    if position:
        scene = drive_scene(scene, scenario)
    m = scene.model
    ratio = m.opt.timestep / dt
    J = int(round(ratio))
    if J < 1 or abs(ratio - J) > _RATIO_TOL * ratio:
        raise DesignError(f"the FEM step {dt:g} s must divide the MuJoCo step {m.opt.timestep:g} s")
    ctrl, starts = phase_controls(scene, scenario)
    K = len(ctrl)
    n = K * J
    zoh = np.r_[0, np.arange(n) // J]  # the MuJoCo step that substep s (1-based) lies in; row 0 unused

    def column(name: str) -> np.ndarray:
        return ctrl[:, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)]

    openings = np.column_stack(
        [
            _servo(m, f"{letter}_opening", column(f"{letter}_opening"), scene.start_openings[i], J)
            for i, letter in enumerate("AB")
        ]
    )
    lift = _servo(m, "lift", column("lift"), 0.0, J)
    tension = np.column_stack([sum(column(a) for a in h.actuators) for h in scene.built.fingers])[zoh]
    xfrc = ctrl[:, m.nu + 6 * scene.object_body : m.nu + 6 * scene.object_body + 6]
    if np.any(xfrc[:, 3:]):
        raise DesignError("the FEM grasp applies forces at the object's COM only, not torques")
    push = xfrc[zoh, :3]
    push[0] = 0.0
    wound = servo = None
    if position:
        drive = scenario.tendon
        wound_mj = -tendon_targets(drive, np.zeros(1), starts["tighten"] * m.opt.timestep, m.opt.timestep, K)
        wound = wound_mj[zoh, 0]
        wound[0] = 0.0
        tension = np.full_like(tension, np.nan)  # the FEM's servo writes it, substep by substep
        servo = (drive.stiffness, drive.max_tension, drive.damping)
    tension[0] = 0.0
    mj_steps = sorted(outcome_steps(starts))
    hold = [t for t in mj_steps if starts["hold"] <= t < starts["impulse"]]
    first, last = hold[0], hold[-1]
    window = ((first + 1) * J + 1, (last + 1) * J) if last > first else (last * J + 1, (last + 1) * J)
    samples = tuple((t + 1) * J for t in mj_steps)
    # fields in order: dt, per_step, n_steps, openings, lift, tension, push, starts, grasp_step, hold, samples
    return GraspSchedule(
        float(dt), J, n, openings, lift, tension, push, dict(starts), starts["lift"] * J, window, samples,
        wound, servo,
    )  # fmt: skip


def _servo(m: mujoco.MjModel, actuator: str, command: np.ndarray, x0: float, J: int) -> np.ndarray:
    """Position [m] of the joint of position servo ``actuator`` at every substep, shape (K J + 1,).

    m ẍ = kp (u − x) − (kv + b) ẋ from rest at ``x0`` under the command ``command`` (K,), held over
    each MuJoCo step and solved exactly (matrix exponential) at J substeps per step.
    """
    aid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, actuator)
    joint = int(m.actuator_trnid[aid, 0])
    kp = float(m.actuator_gainprm[aid, 0])
    kv = -float(m.actuator_biasprm[aid, 2])
    b = float(m.dof_damping[m.jnt_dofadr[joint]])
    mass = float(m.body_subtreemass[m.jnt_bodyid[joint]])
    A = np.array([[0.0, 1.0, 0.0], [-kp / mass, -(kv + b) / mass, kp / mass], [0.0, 0.0, 0.0]])
    h = m.opt.timestep / J
    E = np.stack([scipy.linalg.expm(A * h * j) for j in range(1, J + 1)])  # (J, 3, 3)
    out = np.empty(len(command) * J + 1)
    out[0] = x0
    state = np.array([x0, 0.0])
    for k, u in enumerate(command):
        sub = E[:, :2, :2] @ state + E[:, :2, 2] * u  # (J, 2)
        out[k * J + 1 : (k + 1) * J + 1] = sub[:, 0]
        state = sub[-1]
    return out
