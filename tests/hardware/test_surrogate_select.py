"""``hw grasp --surrogate``: the candidates scored for one design, infeasible ones dropped with a reason,
the best predicted one planned; the frames agree with the simulator's partial cloud."""

import json

import numpy as np
import pytest

from mjcodesign.data.cloud import fingers_box, to_gripper
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.hardware.camera import GripperGeometry, crop_to_gripper, load_point_cloud, save_point_cloud
from mjcodesign.hardware.selftest import BOX_CENTRE, BOX_SIZE, sample_box_surface
from mjcodesign.hardware.surrogate_select import palm_frame, score_candidates

_GEO = GripperGeometry()
# The hardware box and the simulator's differ by the fingers' length (136 mm vs 136.35 mm): points
# within 0.35 mm of the box's top may fall on either side.
_TOL_CROP = 0.02


def _tip_pose(x: float, y: float, z: float, yaw: float = 0.0) -> np.ndarray:
    """A top-down hardware pose: origin at the fingertips, z down, y closing."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    y_axis = np.array([-s, c, 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    T[:3, :3] = np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis])
    T[:3, 3] = (x, y, z)
    return T


def test_palm_frame_maps_the_fingers_box_onto_the_simulators():
    """The same points inside both boxes: the hardware crop in the tip frame and the simulator's in
    the palm frame of :func:`palm_frame`."""
    cloud = sample_box_surface(BOX_SIZE, BOX_CENTRE, 20000)
    for yaw in (0.0, 0.4, np.pi / 2):
        T = _tip_pose(BOX_CENTRE[0], BOX_CENTRE[1], 0.015, yaw)
        hw = crop_to_gripper(cloud, T, _GEO, 0.03, 0.025)
        P = palm_frame(T, _GEO.finger_length)
        assert np.allclose(P[:3, :3].T @ P[:3, :3], np.eye(3)) and np.linalg.det(P[:3, :3]) > 0
        local = to_gripper(P, cloud)
        lo, hi = fingers_box((0.03, 0.025))
        sim = local[np.all((local >= lo) & (local <= hi), axis=1)]
        assert len(hw) > 500
        assert abs(len(sim) - len(hw)) <= _TOL_CROP * len(hw), (yaw, len(sim), len(hw))
        # The palm is one finger length behind the tips, above them for a top-down grasp.
        assert P[2, 3] == pytest.approx(T[2, 3] + _GEO.finger_length)


def test_scores_pick_the_best_feasible_candidate(tiny_checkpoint, tmp_path, capsys):
    from mjcodesign.cli.main import main

    cloud = sample_box_surface(BOX_SIZE, BOX_CENTRE, 4000)
    poses = [
        _tip_pose(BOX_CENTRE[0], BOX_CENTRE[1], 0.015),
        _tip_pose(BOX_CENTRE[0] + 0.01, BOX_CENTRE[1], 0.02, 0.2),
        _tip_pose(BOX_CENTRE[0], BOX_CENTRE[1] + 0.005, 0.012, -0.3),
        _tip_pose(BOX_CENTRE[0], BOX_CENTRE[1], 2.0),  # far above: outside the workspace
        _tip_pose(BOX_CENTRE[0] + 0.3, BOX_CENTRE[1], 0.015),  # beside the box: no points in its box
    ]
    openings = np.full((len(poses), 2), 0.03)
    np.savez(tmp_path / "cands.npz", poses=np.stack(poses), openings=openings)
    save_point_cloud(tmp_path / "cloud.ply", cloud)
    from mjcodesign.hardware.pipeline import load_candidates

    design = Stiffness.preset("soft")
    cands = load_candidates(tmp_path / "cands.npz", _GEO)
    # The points the command will read: the PLY stores float32, and a score near zero (here ~-0.011)
    # moves by 1e-5 of itself between the float64 cloud and its float32 copy.
    read_back = load_point_cloud(tmp_path / "cloud.ply")
    scores, est = score_candidates(tiny_checkpoint, design, 100.0, read_back, cands, _GEO)
    assert [s.index for s in scores] == list(range(len(poses)))
    for s in scores[3:]:  # no measured point in their fingers' box
        assert s.success_score is None and "points" in s.reason
    assert all(np.isfinite(s.success_score) for s in scores[:3])
    assert est["volume_m3_convex_hull"] == pytest.approx(np.prod(BOX_SIZE), rel=0.05)
    code = main(
        [
            "hw", "grasp", "--dry-run", "--json", "--cloud", str(tmp_path / "cloud.ply"),
            "--pose", str(tmp_path / "cands.npz"), "--surrogate", str(tiny_checkpoint), "--design", "soft",
            "--density", "100",  # the tiny checkpoint's training density (the default, 680, is outside it)
        ]
    )  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    rows = {r["index"]: r for r in out["candidates"]}
    assert not rows[3]["feasible"] and "workspace" in rows[3]["reason"]
    feasible = [i for i, r in rows.items() if r["feasible"] and r.get("success_score") is not None]
    best = max(feasible, key=lambda i: rows[i]["success_score"])
    assert out["selected"] == best
    assert rows[best]["success_score"] == pytest.approx(scores[best].success_score)
    # Without --density the surrogate assumes the real regime's 680 kg/m³: outside this checkpoint's range.
    args = ["hw", "grasp", "--dry-run", "--json", "--cloud", str(tmp_path / "cloud.ply"), "--pose"]
    assert (
        main([*args, str(tmp_path / "cands.npz"), "--surrogate", str(tiny_checkpoint), "--design", "soft"])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "680" in err[0], err


def test_surrogate_needs_a_design(tmp_path, capsys):
    from mjcodesign.cli.main import main

    save_point_cloud(tmp_path / "cloud.ply", sample_box_surface(BOX_SIZE, BOX_CENTRE, 500))
    code = main(
        ["hw", "grasp", "--dry-run", "--cloud", str(tmp_path / "cloud.ply"), "--surrogate", str(tmp_path)]
    )
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--design" in err


def test_clouds_of_two_cameras_are_merged_in_the_base_frame(tmp_path, capsys):
    """Two cameras each see half the box; the merged cloud plans like the whole one."""
    from mjcodesign.cli.main import main
    from mjcodesign.hardware.camera import transform_points

    cloud = sample_box_surface(BOX_SIZE, BOX_CENTRE, 3000, seed=5)
    halves = (cloud[cloud[:, 1] >= BOX_CENTRE[1]], cloud[cloud[:, 1] < BOX_CENTRE[1]])
    args = []
    for k, (half, yaw) in enumerate(zip(halves, (0.3, -1.2), strict=True)):
        T = _tip_pose(0.3, 0.2 * k, 0.7, yaw)  # camera k looking down from 0.7 m
        save_point_cloud(tmp_path / f"c{k}.ply", transform_points(half, np.linalg.inv(T)))
        (tmp_path / f"c{k}.json").write_text(json.dumps({"T_base_camera": T.tolist()}))
    save_point_cloud(tmp_path / "all.ply", cloud)
    clouds = f"{tmp_path / 'c0.ply'},{tmp_path / 'c1.ply'}"
    calibs = f"{tmp_path / 'c0.json'},{tmp_path / 'c1.json'}"
    assert main(["hw", "grasp", "--dry-run", "--json", "--cloud", clouds, "--calib", calibs]) == 0
    merged = json.loads(capsys.readouterr().out)["plan"]
    assert main(["hw", "grasp", "--dry-run", "--json", "--cloud", str(tmp_path / "all.ply")]) == 0
    whole = json.loads(capsys.readouterr().out)["plan"]
    assert merged == whole
    args = ["hw", "grasp", "--dry-run", "--cloud", clouds, "--calib", f"{calibs},{tmp_path / 'c0.json'}"]
    assert main(args) == 2 and "calibration" in capsys.readouterr().err
