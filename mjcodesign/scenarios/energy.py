"""The energy bound every grasp rollout is checked against: nothing gains energy that was not put in.

Over a rollout, the mechanical energy MuJoCo accounts for (kinetic energy of every body, gravity,
joint springs) can rise at most by the work the actuators (tendons, lift and opening servos) and the
disturbance impulse did, less what the joint and tendon dampers took:

    E(t) − E(0) ≤ W⁺_act(t) + W_impulse(t) − D(t),   E = E_kin + E_pot − E_pot(gravity-compensated bodies),

with W⁺_act the work of each actuator's positive power only (what it can give; what it absorbs only
tightens the true bound) and D = ∫ Σ b v² dt over the damped joints and tendons (exactly known).
Every other force is passive: friction and a soft contact take energy or store it, and a
store (a penetrating contact, the flex's elasticity, which MuJoCo 4.0 leaves out of its potential)
can give back at most what it took. The palm and carriages are held by gravity compensation, whose
work is their potential energy, so both are left out. A rollout that breaks the bound by more than
:data:`ENERGY_TOL` of what was put in (and :data:`ENERGY_FLOOR`) made energy: a contact found already
deep inside a body pushes it out with no work to pay for it, or the solver blew up. Such a rollout is
:attr:`~mjcodesign.scenarios.outcome.Failure.IMPLAUSIBLE`, never a sample.

The bound cannot see a rollout whose impulse could pay for anything: ``J`` can give a mass ``m`` up to
``J²/2m`` (1.6 kJ on a 0.1 mg cube), so a tiny object driven through the ground and thrown back out
keeps it. :mod:`mjcodesign.scenarios.motion` bounds the object's speed and position for that.

The terms are sensors of the grasp scene (:func:`add_energy_sensors`; ``mujoco.rollout`` returns them
per step), so the check costs no replay.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["ENERGY_TOL", "ENERGY_FLOOR", "EnergyBalance", "add_energy_sensors", "energy_balance"]

ENERGY_TOL = 0.05
"""Allowed excess as a fraction of the work put in: the work is integrated with the trapezoid rule
over 2 ms steps whose forces the integrator applies semi-implicitly (measured excess on the landscape's
ordinary rollouts: docs/benchmarks.md)."""
ENERGY_FLOOR = 1e-4
"""Allowed excess [J] whatever the work: 0.1 mJ, the kinetic energy of a 50 g object at 6 cm/s."""
_PREFIX = "energy_"


@dataclass(frozen=True)
class EnergyBalance:
    """The energy bound of one rollout.

    ``excess``: the largest E(t) − E(0) − W(t) + D(t) over the rollout [J] (≤ 0 when energy was only
    lost), at step ``step``, when the work put in was ``work`` [J] and the object moved at
    ``object_speed`` [m/s]; ``total_work``: the work put in over the whole rollout [J].
    """

    excess: float
    work: float
    step: int
    object_speed: float
    total_work: float = 0.0

    def reason(self, dt: float) -> str:
        """Readable reason for an implausible rollout."""
        return (
            f"implausible: the system gained {1e3 * self.excess:.1f} mJ more than the actuators and the "
            f"impulse put in ({1e3 * self.work:.1f} mJ) by t = {(self.step + 1) * dt:.3f} s "
            f"(object at {self.object_speed:.2f} m/s)"
        )

    @property
    def plausible(self) -> bool:
        """Whether the excess stays within :data:`ENERGY_TOL` of the work (and :data:`ENERGY_FLOOR`)."""
        return self.excess <= ENERGY_TOL * max(self.work, 0.0) + ENERGY_FLOOR


def add_energy_sensors(spec: mujoco.MjSpec, compensated: list[str]) -> None:
    """Sensors for :func:`energy_balance`; call after every actuator is added.

    Every actuator's force and velocity, the total kinetic and potential energy, and the position of
    the gravity-compensated bodies ``compensated``; turns on MuJoCo's energy computation.
    """
    for act in spec.actuators:
        for kind, tag in (
            (mujoco.mjtSensor.mjSENS_ACTUATORFRC, "f"),
            (mujoco.mjtSensor.mjSENS_ACTUATORVEL, "v"),
        ):
            s = spec.add_sensor(name=f"{_PREFIX}{tag}_{act.name}", type=kind, objname=act.name)
            s.objtype = mujoco.mjtObj.mjOBJ_ACTUATOR
    spec.add_sensor(name=f"{_PREFIX}kinetic", type=mujoco.mjtSensor.mjSENS_E_KINETIC)
    spec.add_sensor(name=f"{_PREFIX}potential", type=mujoco.mjtSensor.mjSENS_E_POTENTIAL)
    for body in compensated:
        s = spec.add_sensor(name=f"{_PREFIX}z_{body}", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objname=body)
        s.objtype = mujoco.mjtObj.mjOBJ_BODY
    spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY


def _sensor(m: mujoco.MjModel, name: str) -> int:
    sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, name)
    if sid < 0:
        raise KeyError(f"the grasp scene has no sensor {name!r}")
    return int(m.sensor_adr[sid])


@dataclass(frozen=True)
class _Columns:
    """Where :func:`energy_balance` reads a model's sensors, and which joints and bodies it weighs."""

    force: np.ndarray  # (nu,): each actuator's force sensor
    velocity: np.ndarray  # (nu,): each actuator's velocity sensor
    kinetic: int
    potential: int
    compensated: tuple[tuple[int, int], ...]  # (body, its position sensor) of gravity-compensated bodies
    tendon_actuators: tuple[int, ...]


def _columns(m: mujoco.MjModel) -> _Columns:
    """:class:`_Columns` of ``m``, looked up once per model layout (the names and sensor addresses).

    A grasp's design copies (:func:`~mjcodesign.sim.with_stiffness`) share one layout; the values the
    bound weighs (masses, gravity compensation, damping) are read from each model by the caller.
    """
    weighed = (m.body_gravcomp > 0) & (m.body_mass > 0)
    key = (bytes(m.names), m.sensor_adr.tobytes(), m.actuator_trntype.tobytes(), weighed.tobytes())
    cols = _COLUMNS.get(key)
    if cols is None:
        names = [m.actuator(a).name for a in range(m.nu)]
        cols = _Columns(
            force=np.array([_sensor(m, f"{_PREFIX}f_{n}") for n in names], dtype=int),
            velocity=np.array([_sensor(m, f"{_PREFIX}v_{n}") for n in names], dtype=int),
            kinetic=_sensor(m, f"{_PREFIX}kinetic"),
            potential=_sensor(m, f"{_PREFIX}potential"),
            compensated=tuple(
                (b, _sensor(m, f"{_PREFIX}z_{m.body(b).name}")) for b in np.flatnonzero(weighed).tolist()
            ),
            tendon_actuators=tuple(
                a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_TENDON
            ),
        )
        with _COLUMNS_LOCK:  # worker threads share the cache
            while len(_COLUMNS) >= _COLUMNS_KEPT:
                _COLUMNS.pop(next(iter(_COLUMNS)))
            _COLUMNS[key] = cols
    return cols


_COLUMNS: dict[tuple, _Columns] = {}
_COLUMNS_KEPT = 64
_COLUMNS_LOCK = threading.Lock()


def energy_balance(
    m: mujoco.MjModel,
    object_body: int,
    x0: np.ndarray,
    states: np.ndarray,
    ctrl: np.ndarray,
    sensordata: np.ndarray,
) -> EnergyBalance:
    """The energy bound of one rollout (see the module docstring).

    ``sensordata[t]`` are the sensors MuJoCo computed during step t, at the state before it (``x0`` or
    ``states[t − 1]``) under ``ctrl[t]``; ``ctrl`` (nstep, nu + 6 nbody) carries the impulse in its
    ``xfrc_applied`` part. Work is integrated with the trapezoid rule. ``states`` must hold every step's
    joint velocities (the dampers' loss) and the object's velocity around the impulse step; MJWarp,
    which copies back only some full states, copies the joint velocities of every step for this.
    """
    dt = m.opt.timestep
    cols = _columns(m)
    f = sensordata[:, cols.force]
    v = sensordata[:, cols.velocity]
    # MuJoCo evaluates the kinetic-energy sensor before it updates d.energy in the same step, so the
    # sensor of step t holds the kinetic energy of the state before step t - 1 (measured: sensor[t] equals
    # ½ vᵀMv of states[t - 2] to round-off), and at step 0 whatever the data last held (the previous
    # rollout's, on reused data). The potential sensor is current. So the kinetic energy of the state
    # before step t is the sensor of step t + 1, and the last step, whose kinetic energy no sensor
    # holds, is left out of the bound.
    kinetic = sensordata[1:, cols.kinetic]
    energy = kinetic + sensordata[:-1, cols.potential]
    g = -float(m.opt.gravity[2])
    gravcomp, mass = m.body_gravcomp, m.body_mass
    for b, z_adr in cols.compensated:
        z = sensordata[:-1, z_adr + 2]
        energy = energy - gravcomp[b] * mass[b] * g * z
    # Only what each actuator gives counts: a servo's damping is integrated implicitly, so its sensed
    # force (at the step's start) overstates what it absorbs, and absorbed work can only lower the bound.
    power = np.sum(np.maximum(f * v, 0.0), axis=1)
    w_act = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * dt)])
    # What joint and tendon dampers certainly took, b v² at the velocity each step ends with (the
    # implicit integrator applies them there): the lift's 50 N·s/m alone takes ~0.27 J of a 3 cm lift.
    qvel = np.vstack([x0[None, 1 + m.nq : 1 + m.nq + m.nv], states[:, 1 + m.nq : 1 + m.nq + m.nv]])
    loss = qvel[1:] ** 2 @ m.dof_damping
    for a in cols.tendon_actuators:
        loss = loss + m.tendon_damping[m.actuator_trnid[a, 0]] * v[:, a] ** 2
    damped = np.concatenate([[0.0], np.cumsum(loss * dt)])[:-1]
    # The object's COM velocity (free joint: linear velocity in the world) before and after each step.
    qv = 1 + m.nq + int(m.jnt_dofadr[m.body_jntadr[object_body]])
    vel = np.vstack([x0[None, qv : qv + 3], states[:, qv : qv + 3]])
    nu = m.nu
    force = ctrl[:, nu + 6 * object_body : nu + 6 * object_body + 3]
    w_imp = np.concatenate([[0.0], np.cumsum(np.sum(force * 0.5 * (vel[1:] + vel[:-1]), axis=1) * dt)])[:-1]
    excess = energy - energy[0] - w_act[:-1] - w_imp[:-1] + damped[:-1]
    t = int(np.argmax(excess))
    return EnergyBalance(
        excess=float(excess[t]),
        work=float(w_act[t] + w_imp[t]),
        step=t,
        object_speed=float(np.linalg.norm(vel[t])),
        total_work=float(w_act[-1] + w_imp[-1]),
    )
