"""A pull ends at the goal or at a stall: an emulated XL330 pressing on an obstacle at its current limit."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from mjcodesign.design.servo import TendonPosition
from mjcodesign.errors import HardwareError
from mjcodesign.hardware.tendon import FingerMotor, PullOutcome, TendonConfig, TendonMotors

pytest.importorskip("dynamixel_sdk")

_RETRIES, _LATENCY_MS = 10, 100.0  # a loaded 2-core host (see test_hw_tendon.py)
_SLACK = 2048  # the emulator's initial position [tick]
_SHORT = 600  # an obstacle 400 ticks short of the paper's 1000-tick goal, as a stiff finger stalls [tick]


def _config(port: str, **kw) -> TendonConfig:
    return TendonConfig(
        port=port,
        motors=(FingerMotor(1, "A"), FingerMotor(2, "B")),
        retries=_RETRIES,
        latency_ms=_LATENCY_MS,
        drive=TendonPosition(ticks=1000, current_limit=0.9),
        **kw,
    )


def test_pull_into_an_obstacle_stalls_there_at_the_current_limit(emulator):
    emulator.obstacle(1, _SLACK + _SHORT)  # finger A meets the object; B closes freely
    with TendonMotors(_config(emulator.port, move_timeout_s=3.0)) as motors:
        assert emulator.value(1, "goal_current", 2) == 900  # the drive's limit, written at open
        t0 = time.monotonic()
        report = motors.pull_report()
        elapsed = time.monotonic() - t0
        a, b = report[1], report[2]
        assert a.outcome is PullOutcome.STALLED and a.displacement_ticks == _SHORT
        assert a.current_ma == 900 and a.goal_ticks == 1000
        assert b.outcome is PullOutcome.REACHED
        assert abs(b.displacement_ticks - 1000) <= motors.config.tolerance_ticks
        assert abs(b.current_ma) < 0.8 * 900
        # Stalled after the stall window, long before the timeout.
        assert motors.config.stall_window_s <= elapsed < motors.config.move_timeout_s
        # T = 0.52 N·m · min(I, 1.47 A) / 1.47 A / r: 0.9 A on the 8 mm horn pulls 39.8 N
        assert a.as_dict() == {
            "dxl_id": 1,
            "outcome": "stalled",
            "stalled": True,
            "displacement_ticks": 600,
            "goal_ticks": 1000,
            "current_ma": 900,
            "tension_n": pytest.approx(0.52 * 0.9 / 1.47 / 0.008, abs=0.005),
        }
        assert b.as_dict()["stalled"] is False and b.tension_n < a.tension_n
        assert emulator.value(1, "present_position") == _SLACK + _SHORT
        assert emulator.value(1, "goal_position") == _SLACK + 1000  # the goal stays where it was sent
        emulator.obstacle(1, None)
        assert motors.pull(0) == pytest.approx({1: 0, 2: 0}, abs=motors.config.tolerance_ticks)


class _Arm:
    """An arm that goes where it is told at once; the hand stays open by the object's width."""

    def __init__(self):
        self.T = np.eye(4)

    def move_to(self, target, what=""):
        self.T = np.array(target)

    def lift(self, height):
        self.T[2, 3] += height

    def set_width(self, width):
        pass

    def grasp(self, width):
        self.held_width = width + 0.01  # the object keeps the fingers apart

    def width(self):
        return self.held_width

    def pose(self):
        return self.T


def test_the_grasp_report_gives_each_motors_pull(emulator):
    """``hw grasp --json`` prints this report: one ``pulls`` entry per motor, the stalled one named."""
    from mjcodesign.hardware.camera import GripperGeometry
    from mjcodesign.hardware.pipeline import GraspSettings, auto_candidate, execute, plan_grasp
    from mjcodesign.hardware.selftest import BOX_CENTRE, BOX_SIZE, sample_box_surface

    cloud = sample_box_surface(BOX_SIZE, BOX_CENTRE, 500)
    plan = plan_grasp(auto_candidate(cloud, GripperGeometry()), cloud, GraspSettings())
    emulator.obstacle(2, _SLACK + _SHORT)  # finger B meets the object short of the goal
    with TendonMotors(_config(emulator.port)) as motors:
        report = execute(plan, _Arm(), motors).as_dict()
    a, b = report["pulls"]
    assert (a["dxl_id"], a["stalled"], a["outcome"]) == (1, False, "reached")
    assert (b["dxl_id"], b["stalled"], b["outcome"]) == (2, True, "stalled")
    assert a["goal_ticks"] == b["goal_ticks"] == plan.tendon_ticks == 1000
    assert abs(a["displacement_ticks"] - 1000) <= 10 and b["displacement_ticks"] == _SHORT
    assert b["current_ma"] == 900 and b["tension_n"] == pytest.approx(39.8, abs=0.05)
    assert report["tendon_ticks"] == round((a["displacement_ticks"] + _SHORT) / 2)
    assert json.loads(json.dumps(report)) == report


def test_pull_without_an_obstacle_reaches_the_goal_on_both(emulator):
    with TendonMotors(_config(emulator.port)) as motors:
        report = motors.pull_report()
    assert {r.outcome for r in report.values()} == {PullOutcome.REACHED}


def test_a_jam_that_draws_no_current_times_out_with_a_clear_error(emulator):
    emulator.obstacle(2, _SLACK, current_ma=0)  # B cannot move and draws nothing: not a stall
    with TendonMotors(_config(emulator.port, move_timeout_s=0.5)) as motors:
        with pytest.raises(
            HardwareError, match=r"neither reached its goal nor stalled.*B at 0 ticks, 0 mA"
        ) as err:
            motors.pull(1000)
    assert "A at" not in str(err.value)  # A reached its goal: only B is named
    assert not any(emulator.torque(i) for i in emulator.ids)


def test_still_below_the_current_threshold_is_not_a_stall(emulator):
    # Pressing at 70 % of the limit: under the 80 % threshold, so the pull times out.
    emulator.obstacle(1, _SLACK + _SHORT, current_ma=630)
    with TendonMotors(_config(emulator.port, move_timeout_s=0.5)) as motors:
        with pytest.raises(HardwareError, match="A at 600 ticks, 630 mA"):
            motors.pull()


def test_stall_settings_are_checked():
    with pytest.raises(HardwareError, match="stall_current"):
        TendonConfig(port="/dev/x", stall_current=1.5)
    with pytest.raises(HardwareError, match="stall_window_s"):
        TendonConfig(port="/dev/x", stall_window_s=0.0)
