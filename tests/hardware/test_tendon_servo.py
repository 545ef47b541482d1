"""The robot's tendon motors run the simulator's servo: one TendonPosition sets both (XL330 emulator)."""

from __future__ import annotations

import pytest

from mjcodesign.design.servo import PAPER_TICKS, XL330_OPERATING_MODE, TendonPosition
from mjcodesign.errors import HardwareError
from mjcodesign.hardware.tendon import FingerMotor, TendonConfig, TendonMotors

pytest.importorskip("dynamixel_sdk")

_RETRIES, _LATENCY_MS = 10, 100.0  # a loaded 2-core host (see test_hw_tendon.py)


def _config(port: str, drive: TendonPosition) -> TendonConfig:
    return TendonConfig(
        port=port,
        motors=(FingerMotor(1, "A"), FingerMotor(2, "B")),
        retries=_RETRIES,
        latency_ms=_LATENCY_MS,
        drive=drive,
    )


def test_motors_take_mode_current_limit_and_goal_from_the_drive(emulator):
    drive = TendonPosition(ticks=600, current_limit=0.9)
    with TendonMotors(_config(emulator.port, drive)) as motors:
        for i in (1, 2):
            assert emulator.value(i, "operating_mode", 1) == XL330_OPERATING_MODE == 5
            assert emulator.value(i, "current_limit", 2) == 900  # 0.9 A in the register's 1 mA units
            assert emulator.value(i, "profile_velocity", 4) == 0  # no profile: full speed, as simulated
        final = motors.pull()  # the drive's goal
        assert emulator.value(1, "goal_position") == motors.slack[1] + 600
        assert all(abs(v - 600) <= motors.config.tolerance_ticks for v in final.values())


def test_default_drive_is_the_papers_pull_at_the_factory_current_limit(emulator):
    with TendonMotors(_config(emulator.port, TendonPosition())) as motors:
        assert emulator.value(1, "current_limit", 2) == 1750
        assert motors.config.drive.goal_ticks == PAPER_TICKS == 1000


def test_config_refuses_a_force_drive():
    from mjcodesign.scenarios import TendonForce

    with pytest.raises(HardwareError, match="TendonPosition"):
        TendonConfig(port="/dev/null", drive=TendonForce(tension=10.0))
