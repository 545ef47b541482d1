"""The real dynamixel-sdk against the XL330 emulator: bytes over a pseudo-terminal."""

from __future__ import annotations

import os
import time

import pytest

from mjcodesign.hardware.dxl_emulator import XL330Emulator, crc16, stuff, unstuff
from mjcodesign.hardware.xl330 import ADDR, XL330_MODEL_NUMBER

dxl = pytest.importorskip("dynamixel_sdk")


def test_crc_matches_sdk_table():
    # The SDK computes CRC-16 (poly 0x8005) from a lookup table; ours is bitwise.
    ph = dxl.PacketHandler(2.0)
    for n in (1, 7, 100, 255):
        data = os.urandom(n)
        assert crc16(data) == ph.updateCRC(0, list(data), n)


def test_byte_stuffing_round_trip():
    payload = b"\x03\x74\x00\xff\xff\xfd\xff"
    stuffed = stuff(payload)
    assert stuffed == b"\x03\x74\x00\xff\xff\xfd\xfd\xff"
    assert unstuff(stuffed) == payload


def test_ping_model_and_missing_id(sdk_port):
    port, ph = sdk_port
    model, result, error = ph.ping(port, 1)
    assert (model, result, error) == (XL330_MODEL_NUMBER, dxl.COMM_SUCCESS, 0)
    t0 = time.monotonic()
    _, result, _ = ph.ping(port, 7)
    assert result == dxl.COMM_RX_TIMEOUT
    assert time.monotonic() - t0 < 1.0  # the reply window (2 * 100 + 2 ms and the bytes), not a hang


def test_broadcast_ping_lists_both(sdk_port):
    port, ph = sdk_port
    found, result = ph.broadcastPing(port)
    assert result == dxl.COMM_SUCCESS
    assert {i: v[0] for i, v in found.items()} == {1: XL330_MODEL_NUMBER, 2: XL330_MODEL_NUMBER}


def test_eeprom_locked_while_torque_on(sdk_port):
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 1, ADDR["operating_mode"], 5) == (dxl.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, ADDR["torque_enable"], 1) == (dxl.COMM_SUCCESS, 0)
    _, error = ph.write1ByteTxRx(port, 1, ADDR["operating_mode"], 3)
    assert error == dxl.ERRNUM_ACCESS
    assert ph.read1ByteTxRx(port, 1, ADDR["operating_mode"])[0] == 5
    # Read-only items refuse writes too.
    assert ph.write2ByteTxRx(port, 1, ADDR["model_number"], 1)[1] == dxl.ERRNUM_ACCESS


def test_position_follows_goal_at_finite_speed(sdk_port):
    port, ph = sdk_port
    speed = 20_000.0  # conftest.FAST_TICKS_S [tick/s]
    ph.write1ByteTxRx(port, 1, ADDR["torque_enable"], 1)
    start = ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0]
    t0 = time.monotonic()
    ph.write4ByteTxRx(port, 1, ADDR["goal_position"], start + 2000)
    mid = ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0]
    elapsed = time.monotonic() - t0
    # position(t) = start + v*t until the goal: 2000 ticks take 0.1 s at 20k tick/s.
    assert start <= mid <= start + speed * elapsed + 1
    assert mid < start + 2000
    time.sleep(0.15)
    assert ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0] == start + 2000


def test_obstacle_stops_the_shaft_and_it_presses_at_the_current_limit(sdk_port, emulator):
    port, ph = sdk_port
    ph.write1ByteTxRx(port, 1, ADDR["torque_enable"], 1)
    start = ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0]
    emulator.obstacle(1, start - 300)  # below the shaft: a pay-out goal presses on it
    ph.write2ByteTxRx(port, 1, ADDR["goal_current"], 700)  # under the 1750 mA Current Limit
    ph.write4ByteTxRx(port, 1, ADDR["goal_position"], start - 1000)
    time.sleep(0.1)  # 300 ticks take 15 ms at 20k tick/s
    assert ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0] == start - 300
    # Present Current: 2 bytes, two's complement, 1 mA; negative while pushing toward lower ticks,
    # saturated at min(Goal Current, Current Limit).
    raw = ph.read2ByteTxRx(port, 1, ADDR["present_current"])[0]
    assert raw - (1 << 16) == -700
    assert ph.read1ByteTxRx(port, 1, ADDR["moving"])[0] == 0
    ph.write4ByteTxRx(port, 1, ADDR["goal_position"], start)  # away from it: free, no current
    time.sleep(0.1)
    assert ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0] == start
    assert ph.read2ByteTxRx(port, 1, ADDR["present_current"])[0] == 0


def test_no_motion_without_torque(sdk_port):
    port, ph = sdk_port
    start = ph.read4ByteTxRx(port, 2, ADDR["present_position"])[0]
    ph.write4ByteTxRx(port, 2, ADDR["goal_position"], start + 500)
    time.sleep(0.05)
    assert ph.read4ByteTxRx(port, 2, ADDR["present_position"])[0] == start


def test_sync_write_and_sync_read(sdk_port):
    port, ph = sdk_port
    for i in (1, 2):
        ph.write1ByteTxRx(port, i, ADDR["torque_enable"], 1)
    write = dxl.GroupSyncWrite(port, ph, ADDR["goal_position"], 4)
    write.addParam(1, list((1000).to_bytes(4, "little")))
    write.addParam(2, list((3000).to_bytes(4, "little")))
    assert write.txPacket() == dxl.COMM_SUCCESS
    time.sleep(0.1)
    read = dxl.GroupSyncRead(port, ph, ADDR["present_position"], 4)
    read.addParam(1)
    read.addParam(2)
    assert read.txRxPacket() == dxl.COMM_SUCCESS
    assert read.getData(1, ADDR["present_position"], 4) == 1000
    assert read.getData(2, ADDR["present_position"], 4) == 3000


def test_stuffed_negative_goal_round_trip(sdk_port):
    # -131073 = 0xFFFDFFFF: its little-endian bytes FF FF FD FF need stuffing both ways, and
    # 4-byte reads come back unsigned.
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 1, ADDR["operating_mode"], 5)[1] == 0
    assert ph.write4ByteTxRx(port, 1, ADDR["goal_position"], -131073 & 0xFFFFFFFF)[1] == 0
    value, result, _ = ph.read4ByteTxRx(port, 1, ADDR["goal_position"])
    assert result == dxl.COMM_SUCCESS
    assert value == 0xFFFDFFFF


def test_position_mode_enforces_limits(sdk_port):
    port, ph = sdk_port
    _, error = ph.write4ByteTxRx(port, 1, ADDR["goal_position"], 5000)  # limit is 4095
    assert error == dxl.ERRNUM_DATA_LIMIT


def test_reboot_clears_ram_keeps_eeprom(sdk_port):
    port, ph = sdk_port
    ph.write1ByteTxRx(port, 1, ADDR["operating_mode"], 5)
    ph.write1ByteTxRx(port, 1, ADDR["torque_enable"], 1)
    assert ph.reboot(port, 1) == (dxl.COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 1, ADDR["torque_enable"])[0] == 0
    assert ph.read1ByteTxRx(port, 1, ADDR["operating_mode"])[0] == 5


def test_corrupt_crc_gets_crc_error(emulator):
    serial = pytest.importorskip("serial")
    with serial.Serial(emulator.port, 57600, timeout=0.5) as s:
        # A ping to ID 1 with a wrong CRC: FF FF FD 00 | 01 | 03 00 | 01 | CRC
        s.write(b"\xff\xff\xfd\x00\x01\x03\x00\x01\x00\x00")
        reply = s.read(11)
    assert reply[:5] == b"\xff\xff\xfd\x00\x01" and reply[7] == 0x55
    assert reply[8] == dxl.ERRNUM_CRC


def test_link_cut_times_out_then_recovers(sdk_port, emulator):
    port, ph = sdk_port
    cut_s = 0.5  # longer than the ping's 204 ms reply window
    back = time.monotonic() + cut_s
    emulator.cut_link(cut_s)
    assert ph.ping(port, 1)[1] == dxl.COMM_RX_TIMEOUT
    time.sleep(max(0.0, back - time.monotonic()) + 0.05)
    assert ph.ping(port, 1)[1] == dxl.COMM_SUCCESS


_PATIENT_LATENCY_MS = 5000.0
"""Adapter latency of a port that waits 10 s for a reply: for tests of what the emulator answers, not
when. The emulator is a thread of this process: on a starved host it can go unscheduled for longer
than the 204 ms window of the shared fixture (a read timed out, -3001, with two busy loops beside it)."""


@pytest.fixture
def patient_sdk_port(emulator):
    """A real dynamixel-sdk port to the emulator whose reply window no scheduling delay exceeds."""
    from mjcodesign.hardware.tendon import port_handler

    port = port_handler(dxl, emulator.port, _PATIENT_LATENCY_MS)
    assert port.openPort() and port.setBaudRate(57600)
    yield port, dxl.PacketHandler(2.0)
    port.closePort()


def test_reads_in_a_row(patient_sdk_port):
    # No time limit here (speed lives in benchmarks): every read answers, with the resting position.
    port, ph = patient_sdk_port
    n = 50
    t0 = time.perf_counter()
    for _ in range(n):
        assert ph.read4ByteTxRx(port, 1, ADDR["present_position"])[1:] == (dxl.COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 1, ADDR["present_position"])[0] == 2048  # the emulator's initial
    print(f"emulator read round trip: {(time.perf_counter() - t0) / n * 1e3:.2f} ms")


def test_close_is_prompt():
    emu = XL330Emulator(ids=(3,))
    t0 = time.monotonic()
    emu.close()
    assert time.monotonic() - t0 < 0.5


def test_rejects_bad_ids():
    with pytest.raises(ValueError):
        XL330Emulator(ids=(1, 1))
    with pytest.raises(ValueError):
        XL330Emulator(ids=(300,))


@pytest.mark.parametrize("speed", [-5.0, 0.0, float("nan"), float("inf")])
def test_rejects_a_speed_that_is_not_finite_and_positive(speed):
    with pytest.raises(ValueError, match="speed"):
        XL330Emulator(ids=(1,), speed_ticks_s=speed)
