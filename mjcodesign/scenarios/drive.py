"""How the grasp drives the tendons: a fixed tension (the paper's simulator) or the motor's position servo.

* :class:`TendonForce` pulls each finger's tendon with a tension that ramps to ``tension`` [N] over the
  tighten phase: an ideal force source, as in the authors' simulator (``sim_gen.py``: force 100 in
  their scaled units).
* :class:`TendonPosition` (:mod:`mjcodesign.design.servo`, where the motor's datasheet facts and the
  horn are cited) is the hardware's drive, shared by the simulator and the robot: an XL330-M288-T per
  finger in current-based position mode winding the tendon on the authors' 8 mm motor horn. Here it is
  modelled as a tendon length target ``ℓ* = ℓ₀ − r·2π·ticks/4096`` ramped at the no-load speed (the
  goal is written once, and the motor runs without a velocity profile), tracked by a pull-only servo
  spring ``T = clip(k (ℓ − ℓ*), 0, T_max)`` with ``T_max = τ(I_limit) / r``, and the motor's back-EMF
  as a damper ``b ℓ̇`` on the tendon.

:func:`parse_tendon` reads the CLI's ``force:N`` and ``position:TICKS``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from mjcodesign.design.servo import PAPER_TICKS, TendonPosition
from mjcodesign.errors import DesignError
from mjcodesign.models.types import SimOptions

__all__ = [
    "TendonForce",
    "TendonPosition",
    "TendonDrive",
    "TendonSpecError",
    "parse_tendon",
    "tendon_targets",
    "apply_drive",
    "PAPER_TICKS",
]


class TendonSpecError(DesignError):
    """A ``--tendon`` text is not ``force:N`` or ``position:TICKS`` with a valid number."""


@dataclass(frozen=True, kw_only=True)
class TendonForce:
    """A fixed tendon tension per finger [N], ramped in over the tighten phase (the paper's simulator)."""

    tension: float = 10.0
    """Tension per finger at the end of the ramp [N]."""

    def __post_init__(self) -> None:
        t, top = self.tension, SimOptions().max_tension  # the tension motors' control range
        if isinstance(t, bool) or not isinstance(t, int | float) or not (math.isfinite(t) and 0 < t <= top):
            raise DesignError(f"tension must be in (0, {top:g}] N, got {t!r}")
        object.__setattr__(self, "tension", float(t))

    @property
    def mode(self) -> str:
        """``force``."""
        return "force"

    def text(self) -> str:
        """The ``--tendon`` text of this drive."""
        return f"force:{self.tension:g}"


TendonDrive = TendonForce | TendonPosition
"""Either tendon drive."""


def parse_tendon(text: str) -> TendonForce | TendonPosition:
    """``force:N`` (tension per finger [N]) or ``position:TICKS`` (XL330 goal [ticks of 4096]).

    Raises :class:`TendonSpecError` (a :class:`DesignError`) on anything else.
    """
    if not isinstance(text, str):
        raise TendonSpecError(f"--tendon needs text like force:10 or position:1000, got {text!r}")
    mode, sep, value = text.strip().partition(":")
    if not sep or mode not in ("force", "position"):
        raise TendonSpecError(f"--tendon {text!r}: write force:N (tension per finger [N]) or position:TICKS")
    try:
        number = float(value)
    except ValueError:
        raise TendonSpecError(f"--tendon {text!r}: {value!r} is not a number") from None
    try:
        return TendonForce(tension=number) if mode == "force" else TendonPosition(ticks=number)
    except DesignError as exc:
        raise TendonSpecError(f"--tendon {text!r}: {exc}") from None


def tendon_targets(
    drive: TendonPosition, length0: np.ndarray, t_start: float, dt: float, nstep: int
) -> np.ndarray:
    """Tendon length targets [m] of a position-mode drive, shape (nstep, n_tendons).

    ``length0`` [m] (n_tendons,): the tendons' slack lengths (straight fingers). Each target holds
    ``length0`` until ``t_start`` [s] and then shortens at :attr:`TendonPosition.pull_speed` until it has
    wound in :attr:`TendonPosition.pull`; step ``t`` applies the target at time ``(t + 1) dt``.
    """
    t = (np.arange(nstep) + 1) * dt
    wound = np.clip((t - t_start) * drive.pull_speed, 0.0, drive.pull)
    return np.asarray(length0, dtype=float)[None, :] - wound[:, None]


def apply_drive(m: mujoco.MjModel, actuators: list[list[int]], tendon: TendonForce | TendonPosition) -> None:
    """Write the tendon actuators' parameters for ``tendon`` into ``m`` (a model copy).

    ``actuators``: per finger, its tendon actuators (the finger's drive is split equally among them).
    They are compiled as force motors (gear −1: a control is a tension that shortens the tendon), which
    the force mode uses as they are. Position mode makes each a pull-only servo spring on its tendon,
    ``T = clip(k (ℓ − ℓ*), 0, T_max) / n`` with the control ``−ℓ*`` (the actuator's length is ``−ℓ``:
    affine bias ``(0, −k, 0)``, gain ``k``, the tension limit as force range), and gives the tendon
    itself the motor's damping ``b`` as a passive damper. MuJoCo drops an actuator's velocity derivative
    from the implicit integrator while its force is clamped, so a servo damper went explicit at every
    slack step and its 53 kN/m spring blew up (BADQACC within 0.1 s on four of five designs); the
    passive damper stays implicit, and b / k = 9 ms > dt / 2 keeps the spring stable.
    """
    if isinstance(tendon, TendonForce):
        return
    for ids in actuators:
        n = len(ids)
        for a in ids:
            m.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
            m.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
            m.actuator_gainprm[a, :] = 0.0
            m.actuator_biasprm[a, :] = 0.0
            m.actuator_gainprm[a, 0] = tendon.stiffness / n
            m.actuator_biasprm[a, 1] = -tendon.stiffness / n
            m.actuator_ctrllimited[a] = 0
            m.actuator_forcelimited[a] = 1
            m.actuator_forcerange[a] = (0.0, tendon.max_tension / n)
            m.tendon_damping[m.actuator_trnid[a, 0]] = tendon.damping / n
