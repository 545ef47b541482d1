"""Point clouds, calibration, cropping, candidate loading and planning (no hardware)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.errors import HardwareError, PoseError
from mjcodesign.hardware.arm import Workspace
from mjcodesign.hardware.camera import (
    FileCamera,
    GripperGeometry,
    crop_to_gripper,
    load_calibration,
    load_point_cloud,
    save_point_cloud,
)
from mjcodesign.hardware.grasp import RobotGraspJob, run_job
from mjcodesign.hardware.pipeline import (
    Candidate,
    GraspPlan,
    GraspSettings,
    auto_candidate,
    load_candidates,
    plan_grasp,
    select_candidate,
)
from mjcodesign.hardware.selftest import BOX_CENTRE, BOX_SIZE, sample_box_surface
from mjcodesign.hardware.tendon import FingerMotor, TendonConfig

GEO = GripperGeometry()
TOP_DOWN = np.diag([1.0, -1.0, -1.0, 1.0])


def box_cloud():
    return sample_box_surface(BOX_SIZE, BOX_CENTRE, 2000)


@pytest.mark.parametrize("suffix", [".ply", ".npz", ".npy"])
def test_cloud_round_trip(tmp_path, suffix):
    pts = box_cloud()
    save_point_cloud(tmp_path / f"c{suffix}", pts)
    # PLY stores float32: 1e-7 relative, well under a micrometre here.
    np.testing.assert_allclose(load_point_cloud(tmp_path / f"c{suffix}"), pts, atol=1e-6)


def test_ascii_ply_with_extra_properties(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nend_header\n1 2 3 255\n4 5 6 0\n"
    )
    (tmp_path / "a.ply").write_text(text)
    np.testing.assert_array_equal(load_point_cloud(tmp_path / "a.ply"), [[1, 2, 3], [4, 5, 6]])


def test_bad_cloud_files(tmp_path):
    with pytest.raises(HardwareError, match="not found"):
        load_point_cloud(tmp_path / "none.ply")
    np.save(tmp_path / "bad.npy", np.zeros((5, 2)))
    with pytest.raises(HardwareError, match=r"shape \(N, 3\)"):
        load_point_cloud(tmp_path / "bad.npy")


def test_calibration_maps_camera_to_base(tmp_path):
    T = np.array([[0, -1, 0, 0.5], [-1, 0, 0, 0], [0, 0, -1, 0.6], [0, 0, 0, 1.0]])
    (tmp_path / "c.json").write_text(json.dumps({"T_base_camera": T.tolist()}))
    p_base = box_cloud()
    p_cam = (p_base - T[:3, 3]) @ T[:3, :3]  # inverse transform
    np.save(tmp_path / "cam.npy", p_cam)
    cam = FileCamera(tmp_path / "cam.npy", load_calibration(tmp_path / "c.json"))
    np.testing.assert_allclose(cam.capture(), p_base, atol=1e-12)


def test_calibration_must_be_rigid(tmp_path):
    np.save(tmp_path / "c.npy", np.diag([2.0, 1, 1, 1]))
    with pytest.raises(HardwareError, match="not a rigid"):
        load_calibration(tmp_path / "c.npy")


def test_crop_keeps_points_between_fingers():
    pose = TOP_DOWN.copy()
    pose[:3, 3] = [0.5, 0.0, 0.015]
    pts = np.array([[0.5, 0.0, 0.03], [0.5, 0.0, 0.2], [0.5, 0.05, 0.03], [0.6, 0.0, 0.03]])
    local = crop_to_gripper(pts, pose, GEO, 0.02, 0.02)
    # Only the first point: the second is above the 0.136 m fingers, the third outside the
    # opening plus finger thickness (0.02 + 0.014), the fourth beyond the finger width.
    np.testing.assert_allclose(local, [[0.0, 0.0, -0.015]], atol=1e-12)


def test_auto_pose_closes_across_narrow_side():
    cand = auto_candidate(box_cloud(), GEO)
    # The box is 0.04 m across y: closing axis is +-y, approach is down.
    assert abs(abs(cand.pose[1, 1]) - 1) < 1e-3
    np.testing.assert_allclose(cand.pose[:3, 2], [0, 0, -1])
    assert cand.pose[0, 0] > 0
    assert cand.s1 + cand.s2 == pytest.approx(0.04 - 0.02, abs=2e-3)
    np.testing.assert_allclose(cand.pose[:2, 3], BOX_CENTRE[:2], atol=3e-3)


def test_the_default_lift_is_the_papers_hardware_lift_of_the_real_regime():
    from mjcodesign.scenarios.grasp import PAPER_HARDWARE_LIFT, REAL_REGIME

    assert GraspSettings().lift_m == PAPER_HARDWARE_LIFT == REAL_REGIME.lift
    assert RobotGraspJob(None, None, cloud=Path("c.npy"), dry_run=True).settings.lift_m == PAPER_HARDWARE_LIFT
    assert GraspSettings(lift_m=0.05).lift_m == 0.05


def test_plan_checks_workspace_and_ticks():
    cloud = box_cloud()
    cand = Candidate(np.array(TOP_DOWN), 0.02, 0.02)  # at the origin: inside the robot base
    with pytest.raises(PoseError, match="outside the workspace"):
        plan_grasp(cand, cloud, GraspSettings())
    ok = auto_candidate(cloud, GEO)
    tendon = TendonConfig(port="/dev/null", motors=(FingerMotor(1, max_ticks=500),))
    with pytest.raises(HardwareError, match="outside the limits"):
        plan_grasp(ok, cloud, GraspSettings(), tendon)
    plan = plan_grasp(ok, cloud, GraspSettings())
    assert plan.lift_pose[2, 3] - plan.hand_pose[2, 3] == pytest.approx(0.10)
    np.testing.assert_allclose(plan.pre_pose[:3, 3] - plan.hand_pose[:3, 3], [0, 0, 0.10])


def test_asymmetric_openings_shift_the_hand():
    pose = TOP_DOWN.copy()
    pose[:3, 3] = [0.5, 0.0, 0.1]
    plan = plan_grasp(Candidate(pose, 0.03, 0.01), box_cloud(), GraspSettings())
    # Hand centre at (s1 - s2)/2 = 0.01 m along the gripper y axis, which is world -y here.
    np.testing.assert_allclose(plan.hand_pose[:3, 3], [0.5, -0.01, 0.1], atol=1e-12)
    assert plan.width == pytest.approx(0.04)


def test_select_prefers_more_points(tmp_path):
    cloud = box_cloud()
    good = auto_candidate(cloud, GEO).pose
    off = good.copy()
    off[0, 3] += 0.2  # valid, but nothing between the fingers
    outside = good.copy()
    outside[2, 3] = 2.0
    np.savez(tmp_path / "p.npz", poses=np.stack([off, outside, good]))
    cands = load_candidates(tmp_path / "p.npz", GEO)
    plan = select_candidate(cands, cloud, GraspSettings())
    assert plan.index == 2 and plan.n_points > 100
    np.save(tmp_path / "one.npy", outside)
    with pytest.raises(PoseError, match="outside the workspace"):
        select_candidate(load_candidates(tmp_path / "one.npy", GEO), cloud, GraspSettings())


def test_pose_file_errors(tmp_path):
    np.savez(tmp_path / "p.npz", other=np.eye(4))
    with pytest.raises(PoseError, match="'poses' or 'T_pose'"):
        load_candidates(tmp_path / "p.npz", GEO)
    np.savez(tmp_path / "t.npz", T_pose=np.eye(4)[None] * 2)
    with pytest.raises(PoseError, match="not a rigid"):
        load_candidates(tmp_path / "t.npz", GEO)


def test_dry_run_plans_without_connecting(tmp_path):
    np.save(tmp_path / "c.npy", box_cloud())
    lines: list[str] = []
    job = RobotGraspJob(robot=None, dxl=None, cloud=tmp_path / "c.npy", dry_run=True)
    plan = run_job(job, lines.append)
    assert isinstance(plan, GraspPlan)
    assert len(lines) == 8 and all(line.startswith("[dry run]") for line in lines)


def test_workspace_validation():
    with pytest.raises(PoseError):
        Workspace((0, 0, 0), (0, 1, 1))
