"""The tendon driver (dynamixel-sdk) against the XL330 emulator."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from mjcodesign.errors import HardwareError
from mjcodesign.hardware.dxl_emulator import XL330Emulator
from mjcodesign.hardware.tendon import FingerMotor, TendonConfig, TendonMotors, raise_on_signals

pytest.importorskip("dynamixel_sdk")


# The in-process emulator shares the GIL with the SDK's busy-polling reader; on a loaded 2-core
# machine a reply occasionally missed the SDK's 34 ms timeout (16 ms latency) ten times in a row,
# so these tests allow more attempts than the default 3 and a 100 ms adapter latency (a 202 ms
# reply window); the timeout itself is tested below with the default latency.
TEST_RETRIES = 10
TEST_LATENCY_MS = 100.0


def config(port, **kw):
    kw.setdefault("retries", TEST_RETRIES)
    kw.setdefault("latency_ms", TEST_LATENCY_MS)
    return TendonConfig(port=port, motors=(FingerMotor(1, "A"), FingerMotor(2, "B")), **kw)


def all_off(emu):
    return not any(emu.torque(i) for i in emu.ids)


def test_open_sets_mode_and_torque(emulator):
    with TendonMotors(config(emulator.port)) as motors:
        assert all(emulator.torque(i) for i in (1, 2))
        assert emulator.value(1, "operating_mode", 1) == 5
        assert motors.slack == {1: 2048, 2: 2048}
    assert all_off(emulator)


def test_pull_reaches_goal_and_torque_off_after(emulator):
    with TendonMotors(config(emulator.port)) as motors:
        final = motors.pull(1000)
        assert all(abs(v - 1000) <= 10 for v in final.values())
        # pull() returns once every motor is within the tolerance of its goal (it polls), so the
        # motor may still be a few ticks short of the goal it was sent: 2048 + 1000.
        assert emulator.value(1, "goal_position") == 3048
        assert abs(emulator.value(1, "present_position") - 3048) <= motors.config.tolerance_ticks
        motors.pull(0)
    assert all_off(emulator)


def test_pull_beyond_limits_refused_before_write(emulator):
    cfg = config(emulator.port)
    with pytest.raises(HardwareError, match="outside the limits"):
        cfg.check_pull(5000)
    with TendonMotors(cfg) as motors:
        before = emulator.packets
        with pytest.raises(HardwareError, match="outside the limits"):
            motors.pull(5000)
        assert emulator.packets == before  # nothing was sent
        assert emulator.value(1, "goal_position") == 2048
    assert all_off(emulator)


def test_missing_id_fails_cleanly(emulator):
    cfg = TendonConfig(port=emulator.port, motors=(FingerMotor(1), FingerMotor(7)))
    with pytest.raises(HardwareError, match="ID 7.*did not answer"):
        with TendonMotors(cfg):
            pass
    assert all_off(emulator)


def test_wrong_model_refused(emulator):
    # Pretend another motor model by checking that a model mismatch message is produced:
    # the emulator only emulates XL330, so patch the expected number through the module.
    from mjcodesign.hardware import tendon

    old = tendon.XL330_MODEL_NUMBER
    tendon.XL330_MODEL_NUMBER = 1060  # XL430-W250
    try:
        with pytest.raises(HardwareError, match="model number 1200"):
            TendonMotors(config(emulator.port)).open()
    finally:
        tendon.XL330_MODEL_NUMBER = old
    assert all_off(emulator)


def test_bad_port():
    with pytest.raises(HardwareError, match="cannot open serial port"):
        TendonMotors(config("/dev/does-not-exist")).open()


# The faults below are events, not durations: a packet is dropped whenever it comes, so the outcome does
# not depend on how soon the emulator's thread is scheduled. (A link cut for 50 ms against 34 ms reply
# windows of a 16 ms latency failed at the first ping on a cold, loaded run: a software peer's reply waits
# for the host's scheduler, and with two busy loops 5-22% of pings took longer than 34 ms, up to 144 ms.)


def test_transient_timeout_is_retried(emulator):
    with TendonMotors(config(emulator.port)) as motors:
        emulator.drop_packets(2)  # the first two attempts of the read time out unanswered
        assert motors.present() == {1: 2048, 2: 2048}
    assert emulator.dropped == 2


def test_lost_link_mid_move_fails_cleanly_and_torque_off():
    # 1000 ticks take 10 s at 100 tick/s: the shaft is still moving when torque goes off.
    with XL330Emulator(ids=(1, 2), speed_ticks_s=100.0) as emulator:
        emulator.cut_link_on_goal()  # down from the goal write until the first torque-off attempt
        t0 = time.monotonic()
        with pytest.raises(HardwareError, match="serial link to the tendon motors lost"):
            with TendonMotors(config(emulator.port, retries=3, safe_stop_s=2.0)) as motors:
                motors.pull(1000)
        assert time.monotonic() - t0 < 3.0
        assert emulator.dropped == 3 + 1  # the three attempts of the position read, one torque-off
        assert all_off(emulator)  # torque off once the link came back, within safe_stop_s
        assert emulator.value(1, "present_position") < 3048


def test_link_never_back_reports_unconfirmed_torque_off(emulator):
    motors = TendonMotors(config(emulator.port, safe_stop_s=0.2))
    motors.open()
    emulator.cut_link(5.0)
    with pytest.raises(HardwareError, match="could not confirm torque off"):
        motors.close()
    emulator.cut_link(0.0)


def test_sigterm_inside_block_torques_off(emulator):
    # The handler outside the block is put back, whatever it was (SIG_DFL, or one an earlier test's
    # library installed in this process: Ray's driver sets its own).
    before = signal.getsignal(signal.SIGTERM)
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGTERM))
    with pytest.raises(SystemExit):
        with raise_on_signals(), TendonMotors(config(emulator.port)) as motors:
            timer.start()
            for _ in range(200):
                motors.present()
                time.sleep(0.005)
    timer.join()
    assert all_off(emulator)
    assert signal.getsignal(signal.SIGTERM) is before


def test_reply_window_follows_latency(emulator):
    # SDK formula: t = bytes * t_byte + 2 * latency + 2 [ms]; t_byte = 1000 * 10 / 57600 ms at 57600 baud.
    for latency in (16.0, 100.0):
        with TendonMotors(config(emulator.port, latency_ms=latency)) as motors:
            motors._port.setPacketTimeout(14)
            expected = 14 * 10_000 / 57600 + 2 * latency + 2.0
            assert motors._port.packet_timeout == pytest.approx(expected, rel=1e-12)


def test_config_validation():
    with pytest.raises(HardwareError):
        TendonConfig(port="/dev/x", latency_ms=0.0)
    with pytest.raises(HardwareError):
        FingerMotor(300)
    with pytest.raises(HardwareError):
        FingerMotor(1, min_ticks=10)
    with pytest.raises(HardwareError, match="duplicate"):
        TendonConfig(port="/dev/x", motors=(FingerMotor(1), FingerMotor(1)))
