"""Dynamixel protocol-2.0 emulator of XL330-M288 motors on a pseudo-terminal.

The emulator is a protocol peer, not a mock: it parses the bytes that the real dynamixel-sdk
writes (header, byte stuffing, CRC-16), answers with status packets, and keeps a control table
per motor. Several motors share one emulated bus, as on a U2D2. Supported instructions: ping,
read, write, reboot, sync read and sync write (and broadcast ping). Writes to the EEPROM area
(addresses below 64) while torque is on return an access error, as on the real motor. The present
position follows the goal position at a finite speed while torque is on; an optional obstacle
(`XL330Emulator.obstacle`) stops it at a position, where it presses at its current limit as a motor in
current-based position mode stalls on a stiff finger.

Pure Python, no dependencies: ``os.openpty`` and a thread. Use it as a context manager::

    with XL330Emulator(ids=(1, 2)) as emu:
        port = emu.port  # e.g. /dev/pts/7, opened by dynamixel_sdk.PortHandler

The constructor returns once the serving thread is reading the bus. Faults can be injected by time
(`XL330Emulator.cut_link`) or by events, which do not depend on how fast either side runs: drop the next
n packets (`XL330Emulator.drop_packets`), or cut the link at a goal write until the client tries to
switch torque off (`XL330Emulator.cut_link_on_goal` without a duration). A software peer answers only
when the host schedules it: on a loaded host its replies can miss the SDK's 34 ms window of a 16 ms
adapter latency, which real motors, answering from their own hardware, do not.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import select
import struct
import threading
import time
import tty
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from .xl330 import ADDR, XL330_MODEL_NUMBER

__all__ = [
    "XL330Emulator",
    "emulator_process",
    "crc16",
    "stuff",
    "unstuff",
]

_FIRMWARE_VERSION = 52  # any plausible value; reported at address 6
_HEADER = b"\xff\xff\xfd\x00"
_BROADCAST_ID = 0xFE
_EEPROM_END = 64  # addresses below this are EEPROM: writable only with torque off
_TABLE_SIZE = 147  # last item: Present Temperature at 146 (1 byte)
_CHILD_START_S = 20.0  # spawn start-up budget of `emulator_process` [s]
_THREAD_START_S = (
    20.0  # the serving thread reads the bus within this time of its start, or the emulator fails [s]
)
_POLL_S = 0.02  # serving thread wake-up period; bounds close() latency
_EXTENDED_RANGE = 1_048_575  # |goal| limit in extended / current-based position modes [ticks]

# Instructions (protocol 2.0)
_INST_PING = 0x01
_INST_READ = 0x02
_INST_WRITE = 0x03
_INST_REBOOT = 0x08
_INST_STATUS = 0x55
_INST_SYNC_READ = 0x82
_INST_SYNC_WRITE = 0x83

# Status error numbers (protocol 2.0, low 7 bits of the error byte)
_ERR_INSTRUCTION = 2
_ERR_CRC = 3
_ERR_DATA_RANGE = 4
_ERR_DATA_LENGTH = 5
_ERR_DATA_LIMIT = 6
_ERR_ACCESS = 7


# (address, size, default). Items not listed read as zero.
_ITEMS: tuple[tuple[int, int, int], ...] = (
    (0, 2, XL330_MODEL_NUMBER),
    (6, 1, _FIRMWARE_VERSION),
    (8, 1, 1),  # baud rate index 1 = 57600 bps (factory default)
    (9, 1, 250),  # return delay 500 us (factory default; the emulator answers at once)
    (11, 1, 3),  # operating mode 3 = position control (factory default)
    (13, 1, 2),  # protocol 2.0
    (24, 4, 10),  # moving threshold [0.229 rev/min]
    (31, 1, 70),  # temperature limit [deg C]
    (32, 2, 70),  # max voltage limit [0.1 V]
    (34, 2, 35),  # min voltage limit [0.1 V]
    (36, 2, 885),  # PWM limit
    (38, 2, 1750),  # current limit [mA]
    (44, 4, 445),  # velocity limit [0.229 rev/min]
    (48, 4, 4095),  # max position limit [tick]
    (52, 4, 0),  # min position limit [tick]
    (63, 1, 52),  # shutdown conditions
    (68, 1, 2),  # status return level: answer every instruction
    (84, 2, 400),  # position P gain
    (102, 2, 1750),  # goal current [mA]
    (144, 2, 50),  # present input voltage [0.1 V]
    (146, 1, 30),  # present temperature [deg C]
)
_READ_ONLY = (range(0, 7), range(70, 71), range(120, _TABLE_SIZE))


def crc16(data: bytes | bytearray) -> int:
    """CRC-16 of a Dynamixel 2.0 packet (polynomial 0x8005, MSB first, initial value 0)."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def stuff(payload: bytes) -> bytes:
    """Insert 0xFD after every FF FF FD inside instruction + parameters (byte stuffing)."""
    out = bytearray()
    for byte in payload:
        out.append(byte)
        if out[-3:] == b"\xff\xff\xfd":
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes) -> bytes:
    """Remove the stuffed 0xFD that follows every FF FF FD (inverse of `stuff`)."""
    out = bytearray()
    i = 0
    while i < len(payload):
        out.append(payload[i])
        if out[-3:] == b"\xff\xff\xfd" and i + 1 < len(payload) and payload[i + 1] == 0xFD:
            i += 1
        i += 1
    return bytes(out)


def _packet(dxl_id: int, instruction: int, params: bytes) -> bytes:
    body = stuff(bytes([instruction]) + params)
    head = _HEADER + bytes([dxl_id]) + struct.pack("<H", len(body) + 2)
    pkt = head + body
    return pkt + struct.pack("<H", crc16(pkt))


@dataclass
class _Motor:
    """One emulated XL330: its control table and the state of its position follower."""

    dxl_id: int
    speed_ticks_s: float
    table: bytearray
    position: float = 0.0  # present position [tick], continuous
    stamp: float = 0.0  # time of the last position update [s, monotonic]
    obstacle: int | None = None  # position the shaft cannot pass [tick]; None: free
    obstacle_ma: int | None = None  # present current while pressing on it [mA]; None: the limit
    obstacle_side: int = -1  # side of the obstacle the shaft is on: -1 below, +1 above

    @classmethod
    def new(cls, dxl_id: int, speed_ticks_s: float, position: int) -> _Motor:
        motor = cls(dxl_id, speed_ticks_s, bytearray(_TABLE_SIZE))
        motor.factory_ram()
        for addr, size, value in _ITEMS:
            if addr < _EEPROM_END:
                motor.put(addr, size, value)
        motor.put(ADDR["id"], 1, dxl_id)
        motor.position = float(position)
        motor.stamp = time.monotonic()
        motor.put(ADDR["goal_position"], 4, position)
        motor.sync()
        return motor

    def factory_ram(self) -> None:
        self.table[_EEPROM_END:] = bytes(_TABLE_SIZE - _EEPROM_END)
        for addr, size, value in _ITEMS:
            if addr >= _EEPROM_END:
                self.put(addr, size, value)

    def get(self, addr: int, size: int, signed: bool = False) -> int:
        return int.from_bytes(self.table[addr : addr + size], "little", signed=signed)

    def put(self, addr: int, size: int, value: int) -> None:
        self.table[addr : addr + size] = (value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")

    @property
    def torque(self) -> bool:
        return self.table[ADDR["torque_enable"]] == 1

    def sync(self) -> None:
        """Advance the present position toward the goal and refresh the read-only items."""
        now = time.monotonic()
        goal = self.get(ADDR["goal_position"], 4, signed=True)
        pressing = False
        if self.torque:
            target = float(goal)
            if self.obstacle is not None and (goal - self.obstacle) * self.obstacle_side < 0:
                target, pressing = float(self.obstacle), True  # the goal lies beyond the obstacle
            step = self.speed_ticks_s * (now - self.stamp)
            delta = target - self.position
            if abs(delta) <= step:
                self.position = target
            else:
                self.position += math.copysign(step, delta)
                pressing = False  # still on its way to the obstacle
        self.stamp = now
        present = round(self.position)
        moving = self.torque and present != goal and not pressing
        current = 0
        if pressing:
            limit = min(self.get(ADDR["goal_current"], 2), self.get(ADDR["current_limit"], 2))
            magnitude = limit if self.obstacle_ma is None else self.obstacle_ma
            current = round(math.copysign(magnitude, goal - self.position))
        self.put(ADDR["present_current"], 2, current)
        self.put(ADDR["present_position"], 4, present)
        self.put(ADDR["present_velocity"], 4, round(self.speed_ticks_s / 15.6) if moving else 0)
        self.put(ADDR["moving"], 1, int(moving))

    def check_write(self, addr: int, data: bytes) -> int:
        """Protocol error number that a write of `data` at `addr` would cause (0: allowed)."""
        end = addr + len(data)
        if not data or end > _TABLE_SIZE:
            return _ERR_ACCESS
        if any(a in r for a in range(addr, end) for r in _READ_ONLY):
            return _ERR_ACCESS
        if addr < _EEPROM_END and self.torque:
            return _ERR_ACCESS  # EEPROM is locked while torque is on
        if addr <= ADDR["operating_mode"] < end:
            if data[ADDR["operating_mode"] - addr] not in (0, 1, 3, 4, 5, 16):
                return _ERR_DATA_RANGE
        if addr <= ADDR["torque_enable"] < end and data[ADDR["torque_enable"] - addr] > 1:
            return _ERR_DATA_RANGE
        gp = ADDR["goal_position"]
        if addr <= gp and gp + 4 <= end:
            goal = int.from_bytes(data[gp - addr : gp - addr + 4], "little", signed=True)
            mode = self.table[ADDR["operating_mode"]]
            if mode == 3:
                lo = self.get(ADDR["min_position_limit"], 4)
                hi = self.get(ADDR["max_position_limit"], 4)
                if not lo <= goal <= hi:
                    return _ERR_DATA_LIMIT
            elif abs(goal) > _EXTENDED_RANGE:
                return _ERR_DATA_LIMIT
        return 0

    def write(self, addr: int, data: bytes) -> int:
        self.sync()
        err = self.check_write(addr, data)
        if err == 0:
            self.table[addr : addr + len(data)] = data
            if addr <= ADDR["torque_enable"] < addr + len(data) and not self.torque:
                # Torque off: the goal snaps to where the shaft is, as on the real motor.
                self.put(ADDR["goal_position"], 4, round(self.position))
            self.sync()
        return err

    def read(self, addr: int, size: int) -> tuple[int, bytes]:
        if size <= 0 or addr + size > _TABLE_SIZE:
            return _ERR_ACCESS, b""
        self.sync()
        return 0, bytes(self.table[addr : addr + size])


class XL330Emulator:
    """A bus of emulated XL330-M288 motors behind a pseudo-terminal.

    Args:
        ids: Motor IDs on the bus.
        speed_ticks_s: Speed at which the present position follows the goal [tick/s].
            The real XL330-M288 does about 7,000 tick/s unloaded at 5 V (103 rev/min).
        initial_position: Present position of every motor at start [tick].
    """

    def __init__(
        self,
        ids: Iterable[int] = (1,),
        *,
        speed_ticks_s: float = 4000.0,
        initial_position: int = 2048,
    ) -> None:
        ids = tuple(int(i) for i in ids)
        if not ids or any(not 0 <= i < _BROADCAST_ID for i in ids) or len(set(ids)) != len(ids):
            raise ValueError(f"motor IDs must be distinct and in 0..252, got {ids}")
        if not (math.isfinite(speed_ticks_s) and speed_ticks_s > 0):
            raise ValueError(f"speed_ticks_s must be finite and positive, got {speed_ticks_s}")
        self._motors = {i: _Motor.new(i, speed_ticks_s, initial_position) for i in ids}
        self._lock = threading.Lock()
        self._link_down_until = 0.0
        self._cut_on_goal_s = 0.0
        self._cut_on_goal_until_torque_off = False
        self._down_until_torque_off = False
        self._drop_next = 0
        self.packets = 0
        """Instruction packets received with a valid CRC (including ones for absent IDs)."""
        self.dropped = 0
        """Packets dropped unanswered by `drop_packets`, or by `cut_link_on_goal` without a duration."""
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line discipline: bytes pass unchanged
        self.port = os.ttyname(self._slave)
        """Path of the pseudo-terminal that a client opens (e.g. ``/dev/pts/7``)."""
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="xl330-emulator", daemon=True)
        self._thread.start()
        if not self._ready.wait(_THREAD_START_S):  # the ready signal: the bus is being read
            self.close()
            raise RuntimeError(f"the emulator's serving thread did not start within {_THREAD_START_S:g} s")

    # ---- inspection and fault injection (for tests and manual trials) ----

    @property
    def ids(self) -> tuple[int, ...]:
        """Motor IDs on the bus."""
        return tuple(self._motors)

    def value(self, dxl_id: int, item: str, size: int = 4, signed: bool = True) -> int:
        """Read a control-table item of one motor directly (not over the bus)."""
        with self._lock:
            motor = self._motors[dxl_id]
            motor.sync()
            return motor.get(ADDR[item], size, signed)

    def torque(self, dxl_id: int) -> bool:
        """Whether torque is enabled on one motor."""
        return self.value(dxl_id, "torque_enable", 1) == 1

    def obstacle(self, dxl_id: int, position: int | None, *, current_ma: int | None = None) -> None:
        """Put an obstacle that the shaft of one motor cannot pass at `position` [tick]; None removes it.

        A goal beyond it leaves the motor pressing on it, not moving, with its present current at
        the smaller of Goal Current and Current Limit (the saturation of current-based position
        mode), or at `current_ma` [mA] when given (0 emulates a jam that draws no current).
        """
        with self._lock:
            motor = self._motors[dxl_id]
            motor.sync()
            motor.obstacle = None if position is None else int(position)
            if position is not None:  # a shaft on the obstacle itself is below it
                motor.obstacle_side = 1 if motor.position > position else -1
            motor.obstacle_ma = None if current_ma is None else int(current_ma)
            motor.sync()

    def cut_link(self, duration_s: float) -> None:
        """Drop every byte from now on for `duration_s` seconds, as an unplugged cable would."""
        with self._lock:
            self._link_down_until = time.monotonic() + duration_s

    def cut_link_on_goal(self, duration_s: float | None = None) -> None:
        """Cut the link right after the next goal-position write is applied.

        For `duration_s` seconds; or, when None, until the client gives up and tries to switch torque
        off: that attempt is dropped too, and the link is back for its next one. Whatever the link
        drops is neither applied nor answered.
        """
        with self._lock:
            self._cut_on_goal_s = 0.0 if duration_s is None else duration_s
            self._cut_on_goal_until_torque_off = duration_s is None

    def drop_packets(self, n: int) -> None:
        """Drop the next `n` instruction packets, whenever they come: neither applied nor answered."""
        with self._lock:
            self._drop_next = n

    # ---- lifecycle ----

    def close(self) -> None:
        """Stop serving and close the pseudo-terminal."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> XL330Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- serving ----

    def _serve(self) -> None:
        buf = bytearray()
        self._ready.set()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], _POLL_S)
                if not ready:
                    continue
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            with self._lock:
                if time.monotonic() < self._link_down_until:
                    buf.clear()
                    continue
                buf += chunk
                replies = self._consume(buf)
            for reply in replies:
                try:
                    os.write(self._master, reply)
                except OSError:
                    return

    def _consume(self, buf: bytearray) -> list[bytes]:
        """Parse every complete packet at the head of `buf`; return the status packets."""
        replies: list[bytes] = []
        while True:
            start = buf.find(_HEADER)
            if start < 0:
                del buf[: max(0, len(buf) - 3)]  # keep a possible partial header
                return replies
            del buf[:start]
            if len(buf) < 7:
                return replies
            length = struct.unpack_from("<H", buf, 5)[0]
            if len(buf) < 7 + length:
                return replies
            pkt = bytes(buf[: 7 + length])
            del buf[: 7 + length]
            if length < 3:
                continue
            dxl_id = pkt[4]
            if crc16(pkt[:-2]) != struct.unpack_from("<H", pkt, len(pkt) - 2)[0]:
                if dxl_id in self._motors:
                    replies.append(_packet(dxl_id, _INST_STATUS, bytes([_ERR_CRC])))
                continue
            body = unstuff(pkt[7:-2])
            if self._dropped(body[0], body[1:]):
                continue
            self.packets += 1
            replies += self._execute(dxl_id, body[0], body[1:])

    def _dropped(self, inst: int, params: bytes) -> bool:
        """Whether an event-triggered fault drops this packet (`drop_packets`, `cut_link_on_goal`)."""
        if self._drop_next > 0:
            self._drop_next -= 1
        elif self._down_until_torque_off:
            self._down_until_torque_off = not _is_torque_off(inst, params)
        else:
            return False
        self.dropped += 1
        return True

    def _status(self, dxl_id: int, error: int, data: bytes = b"") -> bytes:
        return _packet(dxl_id, _INST_STATUS, bytes([error]) + data)

    def _execute(self, dxl_id: int, inst: int, params: bytes) -> list[bytes]:
        motors = self._motors
        targets = list(motors) if dxl_id == _BROADCAST_ID else [dxl_id] if dxl_id in motors else []
        if inst == _INST_PING:
            data = struct.pack("<HB", XL330_MODEL_NUMBER, _FIRMWARE_VERSION)
            return [self._status(i, 0, data) for i in targets]
        if inst == _INST_READ and dxl_id in motors:
            if len(params) != 4:
                return [self._status(dxl_id, _ERR_DATA_LENGTH)]
            addr, size = struct.unpack("<HH", params)
            err, data = motors[dxl_id].read(addr, size)
            return [self._status(dxl_id, err, data)]
        if inst == _INST_WRITE and dxl_id in motors:
            if len(params) < 3:
                return [self._status(dxl_id, _ERR_DATA_LENGTH)]
            addr = struct.unpack_from("<H", params)[0]
            err = motors[dxl_id].write(addr, params[2:])
            self._after_write(addr, params[2:], err)
            return [self._status(dxl_id, err)]
        if inst == _INST_REBOOT and dxl_id in motors:
            motors[dxl_id].factory_ram()
            motors[dxl_id].put(ADDR["goal_position"], 4, round(motors[dxl_id].position))
            motors[dxl_id].sync()
            return [self._status(dxl_id, 0)]
        if inst == _INST_SYNC_READ and dxl_id == _BROADCAST_ID and len(params) >= 4:
            addr, size = struct.unpack_from("<HH", params)
            replies = []
            for i in params[4:]:
                if i in motors:
                    err, data = motors[i].read(addr, size)
                    replies.append(self._status(i, err, data))
            return replies
        if inst == _INST_SYNC_WRITE and dxl_id == _BROADCAST_ID and len(params) >= 4:
            addr, size = struct.unpack_from("<HH", params)
            records = params[4:]
            for k in range(0, len(records) - size, size + 1):
                i, data = records[k], records[k + 1 : k + 1 + size]
                if i in motors and len(data) == size:
                    self._after_write(addr, data, motors[i].write(addr, data))
            return []  # sync write has no status packet
        if dxl_id in motors:
            return [self._status(dxl_id, _ERR_INSTRUCTION)]
        return []

    def _after_write(self, addr: int, data: bytes, err: int) -> None:
        gp = ADDR["goal_position"]
        if err != 0 or not addr <= gp < addr + len(data):
            return
        if self._cut_on_goal_s > 0:
            self._link_down_until = time.monotonic() + self._cut_on_goal_s
            self._cut_on_goal_s = 0.0
        if self._cut_on_goal_until_torque_off:
            self._down_until_torque_off = True
            self._cut_on_goal_until_torque_off = False


def _is_torque_off(inst: int, params: bytes) -> bool:
    """Whether an instruction writes 0 to Torque Enable (a write, or a sync write's first record)."""
    te = ADDR["torque_enable"]
    if inst == _INST_WRITE and len(params) >= 3:
        addr = struct.unpack_from("<H", params)[0]
        return addr <= te < addr + len(params) - 2 and params[2 + te - addr] == 0
    if inst == _INST_SYNC_WRITE and len(params) >= 6:
        addr, size = struct.unpack_from("<HH", params)
        return addr <= te < addr + size and params[5 + te - addr] == 0
    return False


def _serve_in_child(conn: object, ids: tuple[int, ...], speed: float, position: int, cut_s: float) -> None:
    with XL330Emulator(ids, speed_ticks_s=speed, initial_position=position) as emu:
        if cut_s > 0:
            emu.cut_link_on_goal(cut_s)
        conn.send(emu.port)  # type: ignore[attr-defined]
        try:
            conn.recv()  # type: ignore[attr-defined]  # any message, or EOF, stops the child
        except EOFError:
            pass


@contextmanager
def emulator_process(
    ids: Iterable[int] = (1,),
    *,
    speed_ticks_s: float = 4000.0,
    initial_position: int = 2048,
    cut_link_on_goal_s: float = 0.0,
) -> Iterator[str]:
    """Run an `XL330Emulator` in a child process and yield its port.

    `cut_link_on_goal_s` > 0 arms `XL330Emulator.cut_link_on_goal` in the child.

    A separate process keeps the emulator's replies prompt when the client process is busy (for
    example with an in-process simulator), as a real motor's would be. Inspect its state over the
    bus, as with real motors.
    """
    args = (tuple(ids), speed_ticks_s, initial_position, cut_link_on_goal_s)
    with child_process(_serve_in_child, args, what="the emulator process", start_s=_CHILD_START_S) as started:
        yield started[1]  # the port


@contextmanager
def child_process(
    target: Callable[..., None],
    args: tuple,
    *,
    what: str,
    start_s: float,
    grace_s: float = 2.0,
    error: type[Exception] = RuntimeError,
) -> Iterator[tuple[Any, Any]]:
    """Run ``target(conn, *args)`` in a spawned child; yield its pipe end and its first message.

    The child answers over ``conn`` once it is ready, or exits; ``error`` is raised if it says
    nothing within ``start_s`` or exits first. On leaving, the child is stopped (:func:`stop_child`).
    """
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=target, args=(child, *args), daemon=True)
    proc.start()
    child.close()  # the child's end lives in the child: its exit then reads as EOF here
    try:
        if not parent.poll(start_s):
            raise error(f"{what} did not start within {start_s:g} s")
        try:
            first = parent.recv()
        except EOFError:
            proc.join(timeout=5.0)
            raise error(f"{what} exited while starting (exit code {proc.exitcode})") from None
        yield parent, first
    finally:
        stop_child(parent, proc, grace_s=grace_s)


def stop_child(conn: object, proc: object, grace_s: float) -> None:
    """Ask a peer's child process to stop (``None`` on its pipe); terminate it after ``grace_s``."""
    try:
        conn.send(None)  # type: ignore[attr-defined]
    except OSError:
        pass
    proc.join(timeout=grace_s)
    if proc.is_alive():
        proc.terminate()
        proc.join(timeout=grace_s)
