"""The tendon motor: a Dynamixel XL330-M288-T per finger winding its tendon on the motor horn.

One :class:`TendonPosition` is what both the simulator and the robot drive: the simulated grasp
(:mod:`mjcodesign.scenarios.drive`) pulls the tendon as this motor does, and the hardware driver
(``mjcodesign.hardware.tendon``) writes its operating mode, current limit and goal from the same object.
The motor runs in current-based position mode (operating mode 5): a position goal of ``ticks`` of 4096
from the slack position, written once, approached at most at the no-load speed, with at most the
torque the current limit allows.

Hardware facts (ROBOTIS e-manual, XL330-M288-T): gear ratio 288.4:1, stall torque 0.52 N·m at 1.47 A
and 5.0 V (0.42 N·m at 1.11 A and 3.7 V), no-load speed 103 rpm at 5 V, 4096 ticks per turn, Current
Limit (register 38, 1 mA per unit) factory default and top value 1750. At 5 V the supply caps the
current at the stall current, so the tension limit at the default is 0.52 N·m / r. The spool is the
authors' motor horn (``hardware/motor_horn.stl`` in their repository): a 16 mm disc, 4 mm thick, whose
rim the tendon wraps, r = 8 mm; the tension limit is then 65 N and one tick winds 0.012 mm. The
paper's hardware pulls 1000 ticks (about 12.3 mm of tendon on that horn), then lifts 10 cm.

Light (no MuJoCo): the hardware driver imports it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mjcodesign.errors import DesignError

__all__ = [
    "TendonPosition",
    "TICKS_PER_TURN",
    "XL330_GEAR_RATIO",
    "XL330_STALL_TORQUE",
    "XL330_STALL_CURRENT",
    "XL330_NO_LOAD_SPEED",
    "XL330_CURRENT_UNIT",
    "XL330_CURRENT_LIMIT",
    "XL330_OPERATING_MODE",
    "PAPER_TICKS",
    "HORN_RADIUS",
    "SPOOL_RADIUS_RANGE",
    "CURRENT_LIMIT_RANGE",
]

TICKS_PER_TURN = 4096
"""Encoder ticks per motor output turn (XL330)."""
XL330_GEAR_RATIO = 288.4
"""Gear ratio of the XL330-M288-T (ROBOTIS e-manual): the output figures below already include it."""
XL330_STALL_TORQUE = 0.52
"""Stall torque [N·m] at 5.0 V (ROBOTIS e-manual, XL330-M288-T)."""
XL330_STALL_CURRENT = 1.47
"""Stall current [A] at 5.0 V (ROBOTIS e-manual); torque is taken proportional to current below it."""
XL330_NO_LOAD_SPEED = 103.0 / 60.0 * 2.0 * math.pi
"""No-load speed [rad/s] at 5 V: 103 rpm (ROBOTIS e-manual)."""
XL330_CURRENT_UNIT = 1e-3
"""Current Limit (register 38) unit [A]: 1 mA per unit (ROBOTIS e-manual, XL330 control table)."""
XL330_CURRENT_LIMIT = 1.75
"""Current Limit, register 38, factory default and top value [A] (1750 mA; the authors' motor script
keeps it, and :class:`TendonPosition` writes this default to the motors)."""
XL330_OPERATING_MODE = 5
"""Operating Mode (register 11) of current-based position control: position goals under a current limit."""
PAPER_TICKS = 1000
"""The paper's hardware tendon pull [ticks of 4096]: "a consistent displacement of 1000 units"."""
HORN_RADIUS = 0.008
"""Spool radius [m]: the authors' motor horn (``hardware/motor_horn.stl``) is a 16 mm disc, 4 mm thick,
whose rim the tendon wraps (its largest radius, measured on the STL, is 8.00 mm)."""
SPOOL_RADIUS_RANGE = (0.0075, 0.0085)
"""Effective spool radius range [m] for sensitivity studies: the horn's rim steps between 7.6 and
8.0 mm on the STL (lower end, rounded down), and the tendon's centre line lies half a line diameter
outside the rim it wraps (upper end: 0.5 mm, about one diameter of the 80 lb braided line, assumed)."""
CURRENT_LIMIT_RANGE = (1.11, XL330_CURRENT_LIMIT)
"""Current limit range [A] for sensitivity studies: the stall current at the bottom of the supply range
(1.11 A at 3.7 V, ROBOTIS e-manual: the torque a sagging supply still gives, 0.39 N·m at the 5 V
torque constant) to the factory default 1.75 A (above the 1.47 A stall current: the torque bounds)."""
_SATURATION_TICKS = 64
"""Tendon error [ticks] at which the servo reaches its tension limit: sets the servo stiffness
k = T_max / (64 ticks of tendon), 65 N over 0.79 mm on the 8 mm horn. The XL330's position gain in
current units is not published; the grasp outcomes change little when this is halved or doubled
(docs/benchmarks.md, position-mode servo stiffness), because a closed grasp saturates the current."""
_MAX_TENSION = 200.0
"""Largest tension limit [N] a servo may have: far above any hobby servo on a spool of a few mm."""


def _torque_at(current: float) -> float:
    """XL330 output torque [N·m] at current [A] >= 0: proportional to it up to the 5 V stall current."""
    return XL330_STALL_TORQUE * min(current, XL330_STALL_CURRENT) / XL330_STALL_CURRENT


@dataclass(frozen=True, kw_only=True)
class TendonPosition:
    """The XL330 in current-based position mode winding the tendon on a spool (the hardware's drive).

    The goal is ``ticks`` from the slack position; the length target moves towards it at the motor's
    no-load speed from the start of the tighten phase, and a pull-only servo tracks it with at most
    :attr:`max_tension`.
    """

    ticks: float = float(PAPER_TICKS)
    """Goal position from the slack position [ticks of 4096] (paper's hardware: 1000)."""
    spool_radius: float = HORN_RADIUS
    """Spool radius [m] (the authors' motor horn: 8 mm; :data:`SPOOL_RADIUS_RANGE`)."""
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
            ("current_limit", XL330_CURRENT_UNIT, XL330_CURRENT_LIMIT),
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
        return _torque_at(self.current_limit)

    @property
    def max_tension(self) -> float:
        """Tension limit [N]: the torque limit over the spool radius (65 N at the defaults)."""
        return self.torque_limit / self.spool_radius

    def tension_at(self, current: float) -> float:
        """Tendon tension [N] at motor current ``current`` [A] of either sign (static: no gear friction)."""
        return _torque_at(abs(current)) / self.spool_radius

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

    @property
    def goal_ticks(self) -> int:
        """The goal the motors are sent [ticks from the slack position]: :attr:`ticks` rounded."""
        return int(round(self.ticks))

    @property
    def current_limit_register(self) -> int:
        """Current Limit (register 38) value the motors are written [units of 1 mA]."""
        return int(round(self.current_limit / XL330_CURRENT_UNIT))

    def text(self) -> str:
        """The ``--tendon`` text of this drive."""
        return f"position:{self.ticks:g}"
