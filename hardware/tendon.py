"""Tendon motors: Dynamixel XL330-M288 on protocol 2.0 through dynamixel-sdk.

One motor per finger pulls that finger's tendon. Positions are in encoder ticks (4096 per turn). The
motors run as the simulator's servo (:class:`mjcodesign.design.servo.TendonPosition`, the config's
``drive``): its operating mode (current-based position), its Current Limit and, by default, its goal,
written once with no velocity profile.
A pull is a displacement from the *slack* position, which is the present position read when the
motors are opened; each finger has its own displacement limits, and a command outside them is
refused before anything is written. A pull ends when every motor has either reached its goal or
stalled: a stiff finger closing on an object stops the motor short of its goal at its current limit
(current-based position mode holds that current), so a motor whose position has not changed over a
window while its present current is at the limit is done too (`PullOutcome.STALLED`). Every exit path (normal, exception, SIGINT/SIGTERM through
`raise_on_signals`) leaves the motors with torque off.

``dynamixel_sdk`` is imported lazily, inside `TendonMotors.open`.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, TypeVar

from mjcodesign.design.servo import (
    PAPER_TICKS,
    TICKS_PER_TURN,
    XL330_CURRENT_UNIT,
    XL330_OPERATING_MODE,
    TendonPosition,
)
from mjcodesign.errors import HardwareError

from .xl330 import ADDR, XL330_MODEL_NUMBER

__all__ = [
    "FingerMotor",
    "MotorPull",
    "PullOutcome",
    "TendonConfig",
    "TendonMotors",
    "port_handler",
    "raise_on_signals",
    "PAPER_PULL_TICKS",
]

PAPER_PULL_TICKS = PAPER_TICKS  # the paper's hardware tendon pull, of 4096 ticks per turn
_PROTOCOL = 2.0
_COMM_SUCCESS = 0  # dynamixel_sdk.COMM_SUCCESS
_T = TypeVar("_T")
_STATE_ADDR = ADDR["present_current"]  # one sync read from Present Current to Present Position
_STATE_SIZE = ADDR["present_position"] + 4 - _STATE_ADDR  # current (2), velocity (4), position (4)


@dataclass(frozen=True)
class FingerMotor:
    """The tendon motor of one finger.

    Args:
        dxl_id: Dynamixel ID on the bus (0..252).
        name: Finger name, used in messages.
        min_ticks: Smallest allowed displacement from the slack position [tick]; negative
            values let the spool pay out.
        max_ticks: Largest allowed pull from the slack position [tick].
    """

    dxl_id: int
    name: str = ""
    min_ticks: int = -100
    max_ticks: int = 1500

    def __post_init__(self) -> None:
        if not 0 <= self.dxl_id <= 252:
            raise HardwareError(f"Dynamixel ID must be in 0..252, got {self.dxl_id}")
        if not self.min_ticks <= 0 <= self.max_ticks:
            raise HardwareError(
                f"finger {self.label}: limits [{self.min_ticks}, {self.max_ticks}] must contain 0"
            )
        if self.max_ticks - self.min_ticks > 4 * TICKS_PER_TURN:
            raise HardwareError(f"finger {self.label}: limits span more than 4 turns")

    @property
    def label(self) -> str:
        """Name for messages: the finger name, else the ID."""
        return self.name or f"ID {self.dxl_id}"

    def check(self, ticks: int) -> None:
        """Raise `HardwareError` if a displacement of `ticks` is outside this finger's limits."""
        if not self.min_ticks <= ticks <= self.max_ticks:
            raise HardwareError(
                f"tendon {self.label}: {ticks} ticks is outside the limits "
                f"[{self.min_ticks}, {self.max_ticks}]"
            )


@dataclass(frozen=True)
class TendonConfig:
    """Serial bus and motors of the tendon drive.

    Args:
        port: Serial device of the U2D2 (or of the emulator), e.g. ``/dev/ttyUSB0``.
        motors: One `FingerMotor` per finger.
        baudrate: Bus speed [bit/s]; the paper's set-up and the XL330 default are 57600.
        retries: Attempts per transaction before a serial timeout becomes a failure.
        move_timeout_s: Longest wait for a pull to reach its goal [s].
        tolerance_ticks: A motor within this many ticks of its goal has arrived [tick].
        safe_stop_s: How long to keep trying to switch torque off after a failure [s].
        latency_ms: Latency of the USB-serial adapter [ms]. A reply is awaited for
            ``bytes * t_byte + 2 * latency_ms + 2`` ms, the SDK's formula, which fixes the latency
            at 16 ms (the FTDI default); raise it for slow adapters or a loaded host.
        drive: The servo every motor runs as, the simulator's own: its Current Limit is written at
            open (and as the Goal Current, the current its position controller may use), and its
            goal is what `TendonMotors.pull` pulls by default.
        stall_ticks: A motor that moves no more than this over `stall_window_s` is not moving [tick].
        stall_window_s: How long a motor must stay still at its current limit to count as
            stalled [s].
        stall_current: Fraction of the Current Limit at or above which the present current counts as
            at the limit [-]. The XL330 reports its current in 1 mA units with ripple of a few tens
            of mA about the saturated value, well above an unloaded motor's draw.
    """

    port: str
    motors: tuple[FingerMotor, ...] = (FingerMotor(1, "A"), FingerMotor(2, "B"))
    baudrate: int = 57600
    retries: int = 3
    move_timeout_s: float = 3.0
    tolerance_ticks: int = 10
    safe_stop_s: float = 2.0
    latency_ms: float = 16.0
    drive: TendonPosition = field(default_factory=TendonPosition)
    stall_ticks: int = 3
    stall_window_s: float = 0.2
    stall_current: float = 0.8
    poll_s: float = field(default=0.01, repr=False)

    def __post_init__(self) -> None:
        if not self.port:
            raise HardwareError("no serial port given for the tendon motors")
        if not self.motors:
            raise HardwareError("no tendon motors configured")
        ids = [m.dxl_id for m in self.motors]
        if len(set(ids)) != len(ids):
            raise HardwareError(f"duplicate Dynamixel IDs: {ids}")
        if self.retries < 1 or self.move_timeout_s <= 0 or self.tolerance_ticks < 0:
            raise HardwareError("retries, move_timeout_s and tolerance_ticks must be positive")
        if self.safe_stop_s < 0 or self.poll_s <= 0:
            raise HardwareError("safe_stop_s and poll_s must be positive")
        if not (0 < self.latency_ms <= 1000):
            raise HardwareError(f"latency_ms must be in (0, 1000] ms, got {self.latency_ms}")
        if self.stall_ticks < 0 or self.stall_window_s <= 0 or not 0 < self.stall_current <= 1:
            raise HardwareError(
                "stall_ticks must be >= 0, stall_window_s > 0 and stall_current in (0, 1], got "
                f"{self.stall_ticks}, {self.stall_window_s}, {self.stall_current}"
            )
        if not isinstance(self.drive, TendonPosition):
            raise HardwareError(f"the tendon motors run a TendonPosition servo, got {self.drive!r}")

    def check_pull(self, ticks: int) -> None:
        """Raise `HardwareError` if pulling every tendon by `ticks` is outside any limit."""
        for motor in self.motors:
            motor.check(ticks)


class PullOutcome(StrEnum):
    """How one motor's pull ended."""

    REACHED = "reached"
    """Within `TendonConfig.tolerance_ticks` of its goal."""
    STALLED = "stalled"
    """Still, at its current limit, short of its goal (the finger met the object)."""


@dataclass(frozen=True)
class MotorPull:
    """The end of one motor's pull.

    Args:
        dxl_id: Dynamixel ID.
        outcome: Reached its goal or stalled.
        displacement_ticks: Final displacement from the slack position [tick].
        goal_ticks: Commanded displacement [tick].
        current_ma: Present current at the end [mA], signed as the motor reports it.
        tension_n: Tendon tension at that current [N], estimated by the drive's torque model
            (`TendonPosition.tension_at`: torque ∝ current, no gear friction).
    """

    dxl_id: int
    outcome: PullOutcome
    displacement_ticks: int
    goal_ticks: int
    current_ma: int
    tension_n: float

    def as_dict(self) -> dict:
        """JSON-ready fields; the outcome as its text, and whether it stalled."""
        return {
            "dxl_id": self.dxl_id,
            "outcome": self.outcome.value,
            "stalled": self.outcome is PullOutcome.STALLED,
            "displacement_ticks": self.displacement_ticks,
            "goal_ticks": self.goal_ticks,
            "current_ma": self.current_ma,
            "tension_n": round(self.tension_n, 2),
        }


class _StallWatch:
    """Per-motor stall detector: still within `stall_ticks` for `stall_window_s` at the current limit."""

    def __init__(self, config: TendonConfig) -> None:
        self._config = config
        self._limit_ma = config.stall_current * config.drive.current_limit_register
        self._anchor: dict[int, tuple[int, float]] = {}  # position and time it was first seen there

    def stalled(self, dxl_id: int, position: int, current_ma: int, now: float) -> bool:
        anchor = self._anchor.get(dxl_id)
        if (
            anchor is None
            or abs(position - anchor[0]) > self._config.stall_ticks
            or abs(current_ma) < self._limit_ma
        ):
            self._anchor[dxl_id] = (position, now)
            return False
        return now - anchor[1] >= self._config.stall_window_s


def port_handler(sdk: Any, port: str, latency_ms: float) -> Any:
    """The SDK's port handler with the reply timeout computed from ``latency_ms``, not its fixed 16 ms."""

    class _Port(sdk.PortHandler):
        def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 (the SDK's name)
            self.packet_start_time = self.getCurrentTime()
            self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * latency_ms + 2.0

    return _Port(port)


def _signed32(value: int) -> int:
    """Two's-complement reading of an unsigned 4-byte value (the SDK returns it unsigned)."""
    return value - (1 << 32) if value & 0x80000000 else value


def _signed16(value: int) -> int:
    """Two's-complement reading of an unsigned 2-byte value."""
    return value - (1 << 16) if value & 0x8000 else value


def _le32(value: int) -> list[int]:
    return list((value & 0xFFFFFFFF).to_bytes(4, "little"))


class TendonMotors:
    """Driver of the tendon motors. Use as a context manager; it opens in `__enter__`.

    Opening pings every ID and checks the model number (XL330-M288 = 1200), switches torque off,
    writes the drive's operating mode and Current Limit (EEPROM items, so only with torque off),
    switches torque on, clears the velocity profile (the goal is approached at full speed, as the
    simulator assumes) and reads the slack positions. Closing switches torque off on every motor and closes the port.
    """

    def __init__(self, config: TendonConfig) -> None:
        self.config = config
        self._sdk: Any = None
        self._port: Any = None
        self._ph: Any = None
        self._slack: dict[int, int] = {}
        self._torque_on = False
        self._found: list[FingerMotor] = []  # motors that answered a ping

    # ---- lifecycle ----

    def __enter__(self) -> TendonMotors:
        self.open()
        return self

    def __exit__(self, exc_type: object, exc: BaseException | None, tb: object) -> None:
        try:
            self.close()
        except HardwareError as close_error:
            if exc is None:
                raise
            exc.add_note(str(close_error))  # keep the first failure as the one-line message

    def open(self) -> None:
        """Connect, check every motor and switch torque on in current-based position mode."""
        import dynamixel_sdk as sdk

        self._sdk = sdk
        self._port = port_handler(sdk, self.config.port, self.config.latency_ms)
        try:
            opened = self._port.openPort() and self._port.setBaudRate(self.config.baudrate)
        except Exception as exc:  # pyserial raises SerialException (an OSError) or ValueError
            raise HardwareError(f"cannot open serial port {self.config.port}: {exc}") from exc
        if not opened:
            raise HardwareError(f"cannot open serial port {self.config.port}")
        self._ph = sdk.PacketHandler(_PROTOCOL)
        self._found = []
        try:
            for motor in self.config.motors:
                model = self._ping(motor)
                self._found.append(motor)
                if model != XL330_MODEL_NUMBER:
                    raise HardwareError(
                        f"tendon {motor.label}: model number {model}, expected "
                        f"{XL330_MODEL_NUMBER} (XL330-M288)"
                    )
            self.torque(False)
            drive = self.config.drive
            for motor in self.config.motors:
                self._write(motor, "operating_mode", 1, XL330_OPERATING_MODE)
                self._write(motor, "current_limit", 2, drive.current_limit_register)
            self.torque(True)
            for motor in self.config.motors:
                self._write(motor, "profile_velocity", 4, 0)
                self._write(motor, "goal_current", 2, drive.current_limit_register)
            self._slack = self.present()
        except BaseException as exc:
            self.__exit__(type(exc), exc, None)
            raise

    def close(self) -> None:
        """Switch torque off (retrying for up to `safe_stop_s`) and close the port.

        Raises `HardwareError` if torque-off could not be confirmed on every motor.
        """
        if self._port is None:
            return
        try:
            deadline = time.monotonic() + self.config.safe_stop_s
            pending = list(self._found)
            while pending:
                pending = [m for m in pending if not self._try_torque_off(m)]
                if not pending or time.monotonic() > deadline:
                    break
                time.sleep(self.config.poll_s)
            self._torque_on = bool(pending)
        finally:
            self._port.closePort()
            self._port = None
        if pending:
            names = ", ".join(m.label for m in pending)
            raise HardwareError(f"could not confirm torque off on tendon {names}")

    # ---- commands ----

    @property
    def slack(self) -> dict[int, int]:
        """Present position of each motor when opened, by ID [tick]."""
        return dict(self._slack)

    def torque(self, on: bool) -> None:
        """Switch torque on or off on every motor."""
        for motor in self.config.motors:
            self._write(motor, "torque_enable", 1, int(on))
        self._torque_on = on

    def present(self) -> dict[int, int]:
        """Present position of every motor by ID, with one sync read [tick]."""
        raw = self._sync_read("present position", ADDR["present_position"], 4)
        return {i: _signed32(v[ADDR["present_position"]]) for i, v in raw.items()}

    def present_state(self) -> dict[int, tuple[int, int]]:
        """Present position [tick] and present current [mA] of every motor by ID, with one sync read."""
        raw = self._sync_read("present current and position", _STATE_ADDR, _STATE_SIZE)
        return {
            i: (_signed32(v[ADDR["present_position"]]), _signed16(v[ADDR["present_current"]]))
            for i, v in raw.items()
        }

    def _sync_read(self, what: str, addr: int, size: int) -> dict[int, dict[int, int]]:
        """One sync read of `size` bytes from `addr`; by ID, the raw value of each item read."""
        group = self._sdk.GroupSyncRead(self._port, self._ph, addr, size)
        for motor in self.config.motors:
            group.addParam(motor.dxl_id)
        items = {ADDR["present_position"]: 4, ADDR["present_current"]: 2}
        items = {a: n for a, n in items.items() if addr <= a and a + n <= addr + size}

        def once() -> dict[int, dict[int, int]]:
            result = group.txRxPacket()
            if result != _COMM_SUCCESS:
                raise _Comm(self._ph.getTxRxResult(result))
            out = {}
            for motor in self.config.motors:
                if not group.isAvailable(motor.dxl_id, addr, size):
                    raise _Comm(f"no data from {motor.label}")
                out[motor.dxl_id] = {a: group.getData(motor.dxl_id, a, n) for a, n in items.items()}
            return out

        return self._retry(f"sync read of {what}", once)

    def set_goal(self, goals: Mapping[int, int]) -> None:
        """Write absolute goal positions by ID with one sync write [tick]; no limit check."""
        group = self._sdk.GroupSyncWrite(self._port, self._ph, ADDR["goal_position"], 4)
        for dxl_id, goal in goals.items():
            group.addParam(dxl_id, _le32(int(goal)))

        def once() -> None:
            result = group.txPacket()
            if result != _COMM_SUCCESS:
                raise _Comm(self._ph.getTxRxResult(result))

        self._retry("sync write of goal position", once)

    def pull(self, ticks: int | None = None) -> dict[int, int]:
        """Pull every tendon `ticks` (default: the drive's goal) and wait; final displacement by ID [tick].

        :meth:`pull_report` with only the displacements: each motor reached its goal or stalled.
        """
        return {i: r.displacement_ticks for i, r in self.pull_report(ticks).items()}

    def pull_report(self, ticks: int | None = None) -> dict[int, MotorPull]:
        """Pull every tendon `ticks` (default: the drive's goal) from its slack position and wait.

        Waits until each motor has reached its goal (within `tolerance_ticks`) or stalled (still
        within `stall_ticks` for `stall_window_s` at `stall_current` of its Current Limit), and
        returns how each ended. A displacement outside a finger's limits is refused before anything
        is written; a motor that has done neither within `move_timeout_s` raises `HardwareError`.
        """
        if ticks is None:
            ticks = self.config.drive.goal_ticks
        self.config.check_pull(ticks)
        if not self._torque_on:
            raise HardwareError("tendon motors are not torqued on")
        cfg = self.config
        goals = {m.dxl_id: self._slack[m.dxl_id] + ticks for m in cfg.motors}
        self.set_goal(goals)
        watch = _StallWatch(cfg)
        deadline = time.monotonic() + cfg.move_timeout_s
        while True:
            state, now = self.present_state(), time.monotonic()
            ends: dict[int, PullOutcome | None] = {}
            for i, goal in goals.items():
                position, current = state[i]
                stalled = watch.stalled(i, position, current, now)  # updated every poll
                reached = abs(position - goal) <= cfg.tolerance_ticks
                ends[i] = PullOutcome.REACHED if reached else PullOutcome.STALLED if stalled else None
            if all(ends.values()):
                return {i: self._ended(i, ends[i], ticks, *state[i]) for i in goals}
            if now > deadline:
                late = ", ".join(
                    f"{m.label} at {state[m.dxl_id][0] - self._slack[m.dxl_id]} ticks, "
                    f"{state[m.dxl_id][1]} mA"
                    for m in cfg.motors
                    if ends[m.dxl_id] is None
                )
                raise HardwareError(
                    f"tendon pull of {ticks} ticks: neither reached its goal nor stalled at the current "
                    f"limit within {cfg.move_timeout_s} s: {late} (limit "
                    f"{cfg.drive.current_limit_register} mA; a jam or a cut tendon?)"
                )
            time.sleep(cfg.poll_s)

    def _ended(
        self, dxl_id: int, outcome: PullOutcome, ticks: int, position: int, current_ma: int
    ) -> MotorPull:
        tension = self.config.drive.tension_at(current_ma * XL330_CURRENT_UNIT)
        return MotorPull(dxl_id, outcome, position - self._slack[dxl_id], ticks, current_ma, tension)

    def displacement(self) -> dict[int, int]:
        """Present displacement from the slack position by ID [tick]."""
        now = self.present()
        return {i: now[i] - self._slack[i] for i in now}

    # ---- transactions ----

    def _retry(self, what: str, once: Callable[[], _T]) -> _T:
        last: _Comm | None = None
        for attempt in range(self.config.retries):
            if attempt:
                # A late answer to the failed attempt would be read as the reply to the next one.
                self._port.clearPort()
            try:
                return once()
            except _Comm as exc:
                last = exc
        raise HardwareError(
            f"serial link to the tendon motors lost: {what} failed {self.config.retries} times ({last})"
        ) from last

    def _ping(self, motor: FingerMotor) -> int:
        def once() -> int:
            model, result, error = self._ph.ping(self._port, motor.dxl_id)
            if result != _COMM_SUCCESS:
                raise _Comm(self._ph.getTxRxResult(result))
            return int(model)

        try:
            return self._retry(f"ping of {motor.label}", once)
        except HardwareError as exc:
            raise HardwareError(
                f"tendon motor {motor.label} (ID {motor.dxl_id}) did not answer on {self.config.port} "
                f"({self.config.retries} attempts; {exc.__cause__ or 'no reply'})"
            ) from None

    def _write(self, motor: FingerMotor, item: str, size: int, value: int) -> None:
        writer = {1: self._ph.write1ByteTxRx, 2: self._ph.write2ByteTxRx, 4: self._ph.write4ByteTxRx}[size]

        def once() -> None:
            result, error = writer(self._port, motor.dxl_id, ADDR[item], value)
            if result != _COMM_SUCCESS:
                raise _Comm(self._ph.getTxRxResult(result))
            if error:
                raise HardwareError(
                    f"tendon {motor.label}: writing {item}={value} refused: "
                    f"{self._ph.getRxPacketError(error)}"
                )

        self._retry(f"write of {item} to {motor.label}", once)

    def _try_torque_off(self, motor: FingerMotor) -> bool:
        # A signal or error may have interrupted a transaction and left the SDK's port marked
        # busy, which would refuse every later packet: release it and drop stale bytes.
        self._port.is_using = False
        try:
            self._port.clearPort()
            result, error = self._ph.write1ByteTxRx(self._port, motor.dxl_id, ADDR["torque_enable"], 0)
        except Exception:
            return False
        return result == _COMM_SUCCESS and not error


class _Comm(Exception):
    """One failed serial transaction (timeout, corrupt packet); retried by `_retry`."""


@contextmanager
def raise_on_signals(
    signals: tuple[int, ...] = (signal.SIGTERM, signal.SIGHUP),
) -> Iterator[None]:
    """Turn the given signals into `SystemExit` inside the block, so `with` exits run.

    SIGINT already raises `KeyboardInterrupt`. Outside the main thread this does nothing
    (Python only delivers signals to the main thread).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise SystemExit(128 + signum)

    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
