"""`python -m mjcodesign.cli hw …` end to end, in a subprocess, against the protocol peers.

Each refusal exits 2 with one line on stderr, and nothing moves; motors end with torque off.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.hardware.dxl_emulator import XL330Emulator
from mjcodesign.hardware.selftest import BOX_CENTRE, BOX_SIZE, sample_box_surface
from mjcodesign.hardware.tendon import TendonConfig

ROOT = Path(__file__).resolve().parents[2]
pytest.importorskip("dynamixel_sdk")


_LATENCY_MS = "100"  # adapter latency for the emulator: rides out a loaded host (as the library tests)


def cli(*args, timeout=120):
    if "--dxl" in args and "--latency-ms" not in args:
        args = (*args, "--latency-ms", _LATENCY_MS)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", "hw", *args],
        capture_output=True, text=True, timeout=timeout, env=env, cwd=ROOT,
    )  # fmt: skip


def refused(proc):
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    return lines[0]


def untouched(emu):
    for i in emu.ids:
        assert not emu.torque(i)
        assert emu.value(i, "present_position") == 2048
        assert emu.value(i, "goal_position") == 2048


def test_tendon_pull_and_release():
    with XL330Emulator(ids=(1, 2), speed_ticks_s=20_000) as emu:
        proc = cli("tendon", "--dxl", emu.port, "--ticks", "1000")
        assert proc.returncode == 0, proc.stderr
        # A pull has arrived once every motor is within the tolerance of its goal (TendonConfig): the
        # displacement printed is read then, and the emulated motors go on to the goal itself.
        shown = dict(re.findall(r"ID (\d+): (-?\d+)", proc.stdout.splitlines()[0]))
        assert set(shown) == {"1", "2"}, proc.stdout
        assert all(abs(int(v) - 1000) <= TendonConfig.tolerance_ticks for v in shown.values()), proc.stdout
        assert emu.value(1, "present_position") == 3048
        assert not emu.torque(1) and not emu.torque(2)


def test_ticks_beyond_limits_refused_before_any_byte():
    with XL330Emulator(ids=(1, 2)) as emu:
        line = refused(cli("tendon", "--dxl", emu.port, "--ticks", "5000"))
        assert "outside the limits" in line
        assert emu.packets == 0
        untouched(emu)


def test_missing_motor_id_refused():
    with XL330Emulator(ids=(1, 2)) as emu:
        line = refused(cli("tendon", "--dxl", emu.port, "--ids", "1,7", "--ticks", "100"))
        assert "ID 7" in line and "did not answer" in line
        untouched(emu)


def test_lost_link_mid_move_refused_torque_off():
    # 1000 ticks take 10 s at 100 tick/s. The link goes down at the goal write and comes back when the
    # command, having given up on the position read, tries to switch torque off (events, not a clock:
    # test_hw_tendon says why).
    with XL330Emulator(ids=(1, 2), speed_ticks_s=100) as emu:
        emu.cut_link_on_goal()
        line = refused(cli("tendon", "--dxl", emu.port, "--ticks", "1000"))
        assert "serial link to the tendon motors lost" in line
        assert emu.dropped == 3 + 1  # the default three attempts of the position read, one torque-off
        assert not emu.torque(1) and not emu.torque(2)
        # Torque went off mid-move: the shaft stopped short of the goal.
        assert emu.value(1, "present_position") < 3048


def test_pose_outside_workspace_refused(tmp_path):
    np.save(tmp_path / "cloud.npy", sample_box_surface(BOX_SIZE, BOX_CENTRE, 500))
    far = np.diag([1.0, -1.0, -1.0, 1.0])
    far[:3, 3] = [1.5, 0.0, 0.2]
    np.savez(tmp_path / "poses.npz", poses=far[None])
    with XL330Emulator(ids=(1, 2)) as emu:
        # No robot listens at this loopback address: a refusal must come before connecting.
        line = refused(
            cli("grasp", "--robot", "127.0.0.1", "--dxl", emu.port, "--no-realtime",
                "--pose", str(tmp_path / "poses.npz"), "--cloud", str(tmp_path / "cloud.npy"))
        )  # fmt: skip
        assert "outside the workspace" in line
        assert emu.packets == 0
        untouched(emu)


def test_grasp_dry_run_touches_nothing(tmp_path):
    np.save(tmp_path / "cloud.npy", sample_box_surface(BOX_SIZE, BOX_CENTRE, 500))
    with XL330Emulator(ids=(1, 2)) as emu:
        proc = cli("grasp", "--robot", "127.0.0.1", "--dxl", emu.port, "--pose", "auto",
                   "--cloud", str(tmp_path / "cloud.npy"), "--dry-run")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        assert "[dry run] 6. arm: lift 0.100 m" in proc.stdout
        assert emu.packets == 0


def test_bad_arguments_refused():
    line = refused(cli("grasp", "--cloud", "/nonexistent.ply", "--dry-run"))
    assert "not found" in line


def test_emulate_dxl_prints_port():
    import dynamixel_sdk as sdk

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "mjcodesign.cli", "hw", "emulate-dxl", "--seconds", "20"],
        stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT,
    )  # fmt: skip
    try:
        from mjcodesign.hardware.tendon import port_handler

        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/")
        # The SDK's own handler waits 16 ms of adapter latency; the emulator's poll is 20 ms (as above).
        handler = port_handler(sdk, port, float(_LATENCY_MS))
        assert handler.openPort() and handler.setBaudRate(57600)
        # Up to three attempts, as the driver makes (`TendonConfig.retries`): one 204 ms reply window was
        # missed once with the emulator process starved on a loaded host.
        for _attempt in range(3):
            model, result, _ = sdk.PacketHandler(2.0).ping(handler, 2)
            if result == sdk.COMM_SUCCESS:
                break
            handler.clearPort()
        handler.closePort()
        assert (model, result) == (1200, sdk.COMM_SUCCESS)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_selftest_watchdog_dumps_stacks_instead_of_hanging():
    pytest.importorskip("franky_sim")
    proc = cli("selftest", "--json", "--timeout-s", "0.5", timeout=60)
    assert proc.returncode == 1
    from mjcodesign.hardware.selftest import STATE_CHANNEL_NOTE

    # The loopback note comes first (the selftest says it before connecting), then the watchdog's dump.
    note, _, dump = proc.stderr.partition("\n")
    assert note == STATE_CHANNEL_NOTE.strip(), proc.stderr[:300]
    assert dump.startswith("Timeout (0:00:00.500000)!"), proc.stderr[:300]
    assert "run_selftest" in proc.stderr  # the main thread's stack, where it was
    assert proc.stdout == ""
    assert refused(cli("selftest", "--timeout-s", "0")) == "error: --timeout-s must be positive, got 0.0"


def test_selftest_json(tiny_checkpoint):
    """The whole grasp with the surrogate choosing among three candidates, as on the robot."""
    pytest.importorskip("franky_sim")
    # The selftest's own limits (20 s a motion, 150 s in all) come first; this one only backs them.
    # --density: the tiny checkpoint's range is 100-400 kg/m³; the box's own density (417) is outside it.
    args = ("selftest", "--json", "--surrogate", str(tiny_checkpoint), "--design", "soft", "--density", "300")
    proc = cli(*args, timeout=240)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    print(result)
    assert {"ok", "lift_m", "tendon_ticks", "steps"} <= result.keys()
    assert result["ok"] is True
    assert result["lift_m"] > 0.075 and result["tendon_ticks"] == pytest.approx(1000, abs=10)
    assert [(r["dxl_id"], r["goal_ticks"]) for r in result["pulls"]] == [(1, 1000), (2, 1000)]
    rows = result["candidates"]
    assert len(rows) == 3 and all(r["feasible"] and np.isfinite(r["success_score"]) for r in rows)
    assert result["selected"] == max(rows, key=lambda r: r["success_score"])["index"]
    assert [s["action"] for s in result["steps"]] == [
        "hand", "arm", "arm", "hand", "tendon", "arm", "check",
    ]  # fmt: skip
