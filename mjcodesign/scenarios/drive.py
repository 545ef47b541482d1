"""How the grasp drives the tendons: a fixed tension (the paper's simulator) or the motor's position servo.

* :class:`TendonForce` pulls each finger's tendon with a tension that ramps to ``tension`` [N] over the
  tighten phase: an ideal force source, as in the authors' simulator (``sim_gen.py``: force 100 in
  their scaled units).
* :class:`TendonPosition` is the hardware's drive: a Dynamixel XL330-M288-T per finger in
  current-based position mode (operating mode 5) winding the tendon on a spool. The goal position is
  ``ticks`` of 4096 from the slack position; the motor moves towards it at most at its no-load speed and
  pulls with at most the torque its current allows. Modelled as a tendon length target
  ``ℓ* = ℓ₀ − r·2π·ticks/4096`` ramped at the no-load speed, tracked by a pull-only servo spring
  ``T = clip(k (ℓ − ℓ*), 0, T_max)`` with ``T_max = τ(I_limit) / r``, and the motor's back-EMF as a
  damper ``b ℓ̇`` on the tendon.

Hardware facts (ROBOTIS e-manual, XL330-M288-T): stall torque 0.52 N·m at 1.47 A and
5.0 V, no-load speed 103 rpm at 5 V, 4096 ticks per turn, Current Limit (register 38) factory default
1750 mA, which current-based position mode uses as its limit. At 5 V the supply caps the current at the
stall current, so the tension limit is 0.52 N·m / r: 52 N on a 10 mm spool. The paper's hardware pulls
1000 ticks (``hardware/tendon.py: PAPER_PULL_TICKS``). The spool radius is not published; 10 mm is an
assumption (the NOTES' own example), and a documented parameter.

:func:`parse_tendon` reads the CLI's ``force:N`` and ``position:TICKS``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

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
    "TICKS_PER_TURN",
    "XL330_STALL_TORQUE",
    "XL330_STALL_CURRENT",
    "XL330_NO_LOAD_SPEED",
    "XL330_CURRENT_LIMIT",
    "PAPER_TICKS",
]

TICKS_PER_TURN = 4096
"""Encoder ticks per motor output turn (XL330)."""
XL330_STALL_TORQUE = 0.52
"""Stall torque [N·m] at 5.0 V (ROBOTIS e-manual, XL330-M288-T)."""
XL330_STALL_CURRENT = 1.47
"""Stall current [A] at 5.0 V (ROBOTIS e-manual); torque is taken proportional to current below it."""
XL330_NO_LOAD_SPEED = 103.0 / 60.0 * 2.0 * math.pi
"""No-load speed [rad/s] at 5 V: 103 rpm (ROBOTIS e-manual)."""
XL330_CURRENT_LIMIT = 1.75
"""Current Limit, register 38, factory default [A] (1750 mA; the hardware code does not change it)."""
PAPER_TICKS = 1000
"""The paper's hardware tendon pull [ticks of 4096] (``hardware/tendon.py: PAPER_PULL_TICKS``)."""
_SPOOL_RADIUS = 0.010
"""Spool radius [m]: not published; 10 mm is an assumption."""
_SATURATION_TICKS = 64
"""Tendon error [ticks] at which the servo reaches its tension limit: sets the servo stiffness
k = T_max / (64 ticks of tendon), 52 N over 0.98 mm on a 10 mm spool. The XL330's position gain in
current units is not published; the grasp outcomes change little when this is halved or doubled
(docs/benchmarks.md, position-mode servo stiffness), because a closed grasp saturates the current."""
_MAX_TENSION = 200.0
"""Largest tension [N] either mode accepts: far above any hobby servo on a spool of a few mm."""


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


@dataclass(frozen=True, kw_only=True)
class TendonPosition:
    """The XL330 in current-based position mode winding the tendon on a spool (the hardware's drive).

    The goal is ``ticks`` from the slack position; the length target moves towards it at the motor's
    no-load speed from the start of the tighten phase, and a pull-only servo tracks it with at most
    :attr:`max_tension`.
    """

    ticks: float = float(PAPER_TICKS)
    """Goal position from the slack position [ticks of 4096] (paper's hardware: 1000)."""
    spool_radius: float = _SPOOL_RADIUS
    """Spool radius [m] (assumed 10 mm; not published)."""
    current_limit: float = XL330_CURRENT_LIMIT
    """Current limit [A] (register 38; factory default 1.75 A)."""
    speed: float = XL330_NO_LOAD_SPEED
    """Largest motor speed [rad/s] the goal is approached with (no-load speed at 5 V)."""
    saturation_ticks: float = float(_SATURATION_TICKS)
    """Tendon error [ticks] at which the servo reaches :attr:`max_tension` (sets its stiffness)."""

    def __post_init__(self) -> None:
        for name, lo, hi in (
            ("ticks", 0.0, 4.0 * TICKS_PER_TURN),
            ("spool_radius", 1e-3, 0.05),
            ("current_limit", 1e-3, 10.0),
            ("speed", 1e-3, 1e3),
            ("saturation_ticks", 1.0, 1e4),
        ):
            v = getattr(self, name)
            if (
                isinstance(v, bool)
                or not isinstance(v, int | float)
                or not (math.isfinite(v) and lo <= v <= hi)
            ):
                raise DesignError(f"{name} must be a number in [{lo:g}, {hi:g}], got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.ticks == 0:
            raise DesignError("a position-mode tendon needs ticks > 0 (0 never pulls)")
        if self.max_tension > _MAX_TENSION:
            raise DesignError(
                f"tension limit {self.max_tension:.0f} N exceeds {_MAX_TENSION:g} N: check the spool radius"
            )

    @property
    def mode(self) -> str:
        """``position``."""
        return "position"

    @property
    def torque_limit(self) -> float:
        """Motor torque limit [N·m]: torque ∝ current up to the 5 V stall current."""
        return XL330_STALL_TORQUE * min(self.current_limit, XL330_STALL_CURRENT) / XL330_STALL_CURRENT

    @property
    def max_tension(self) -> float:
        """Tension limit [N]: the torque limit over the spool radius (52 N at the defaults)."""
        return self.torque_limit / self.spool_radius

    @property
    def pull(self) -> float:
        """Tendon length the goal winds in [m]: ``r · 2π · ticks / 4096``."""
        return self.spool_radius * 2.0 * math.pi * self.ticks / TICKS_PER_TURN

    @property
    def pull_speed(self) -> float:
        """Largest tendon speed [m/s]: the no-load speed times the spool radius."""
        return self.speed * self.spool_radius

    @property
    def stiffness(self) -> float:
        """Servo stiffness on the tendon length [N/m]: :attr:`max_tension` at ``saturation_ticks``."""
        return self.max_tension / (self.spool_radius * 2.0 * math.pi * self.saturation_ticks / TICKS_PER_TURN)

    @property
    def damping(self) -> float:
        """Servo damping on the tendon speed [N·s/m]: the motor's back-EMF line, stall torque over no-load speed, at the spool."""
        return XL330_STALL_TORQUE / XL330_NO_LOAD_SPEED / self.spool_radius**2

    def text(self) -> str:
        """The ``--tendon`` text of this drive."""
        return f"position:{self.ticks:g}"


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
