"""The grasp against franky-sim (libfranka protocol over loopback) and the XL330 emulator."""

from __future__ import annotations

import gc
import json
import time

import numpy as np
import pytest

pytest.importorskip("franky")
pytest.importorskip("franky_sim")
pytest.importorskip("dynamixel_sdk")

from hardware.camera import save_point_cloud  # noqa: E402
from hardware.dxl_emulator import emulator_process  # noqa: E402
from hardware.grasp import GraspJob, run_job  # noqa: E402
from hardware.pipeline import GraspReport  # noqa: E402
from hardware.selftest import (  # noqa: E402
    BOX_CENTRE,
    BOX_SIZE,
    SETTLE_S,
    franka_sim,
    sample_box_surface,
    torque_over_bus,
)
from mjcodesign.errors import HardwareError  # noqa: E402

IDS = (1, 2)
T_BASE_CAMERA = np.array([[1.0, 0, 0, 0.2], [0, -1, 0, 0.1], [0, 0, -1, 0.7], [0, 0, 0, 1]])


@pytest.fixture
def scene():
    with franka_sim() as s:
        yield s
        # franky clients kept alive by reference cycles (e.g. a traceback held by pytest) would
        # otherwise be destroyed at a random later time, stalling whatever test runs then.
        gc.collect()


@pytest.fixture
def cloud_files(tmp_path):
    base = sample_box_surface(BOX_SIZE, BOX_CENTRE, 1500, seed=3)
    cam = (base - T_BASE_CAMERA[:3, 3]) @ T_BASE_CAMERA[:3, :3]
    save_point_cloud(tmp_path / "cloud.ply", cam)
    (tmp_path / "calib.json").write_text(json.dumps({"T_base_camera": T_BASE_CAMERA.tolist()}))
    return tmp_path / "cloud.ply", tmp_path / "calib.json"


def joints(scene):
    return scene.sim.data.qpos[:7].copy()


def test_pick_and_lift(scene, cloud_files):
    cloud, calib = cloud_files
    with emulator_process(IDS) as port:
        job = GraspJob(
            robot=scene.host, dxl=port, pose="auto", cloud=cloud, calibration=calib,
            speed_factor=0.5, tendon_retries=10, realtime=False,
        )  # fmt: skip
        z0 = scene.box_z()
        lifted = []

        def measure():
            time.sleep(SETTLE_S)  # the simulated box lags the hand a little
            lifted.append(scene.box_z() - z0)

        report = run_job(job, print, after_lift=measure)
        assert isinstance(report, GraspReport)
        print(f"franky-sim: box lifted {lifted[0]:.4f} m, arm {report.lift_m:.4f} m")
        assert report.held and report.ok
        assert report.lift_m == pytest.approx(0.10, abs=0.005)
        # The box follows the hand to within 2.5 cm (slip in the PD hand and settling).
        assert lifted[0] > 0.075
        assert report.tendon_ticks == pytest.approx(1000, abs=10)
        assert not any(torque_over_bus(port, IDS).values())


def test_lost_link_mid_grasp_no_lift_torque_off(scene, cloud_files):
    cloud, calib = cloud_files
    with emulator_process(IDS, cut_link_on_goal_s=1.0) as port:
        job = GraspJob(
            robot=scene.host, dxl=port, pose="auto", cloud=cloud, calibration=calib,
            speed_factor=0.5, tendon_retries=5, realtime=False,
        )  # fmt: skip
        z_box = scene.box_z()
        with pytest.raises(HardwareError, match="serial link to the tendon motors lost"):
            run_job(job, print)
        assert scene.box_z() == pytest.approx(z_box, abs=0.005)  # never lifted
        assert not any(torque_over_bus(port, IDS).values())
