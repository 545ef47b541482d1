"""scripts/label_retest.py: the agreement of two labels, the poses it reruns, a whole run, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.data import DatagenConfig, generate, open_dataset, parse_density_spec
from mjcodesign.scenarios.grasp import GraspScenario
from mjcodesign.scenarios.perturb import PerturbationModel

_SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "label_retest.py"
_SCENARIO = GraspScenario(impulse=0.0, tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.02)
_WIDE = PerturbationModel(palm_position_m=0.01, palm_rotation_deg=8.0, mass=0.5, friction=0.8, tendon=0.6)


def test_retest_summary_counts_cells_and_ranks_poses(script_module):
    lr = script_module("label_retest")
    first = {(0, 0): {0: 0.0, 1: 0.5, 2: 1.0}, (0, 1): {0: 1.0, 1: 0.0, 2: 0.5}, (1, 0): {0: 0.2, 1: 0.4}}
    second = {(0, 0): {0: 0.0, 1: 0.5, 2: 1.0}, (0, 1): {0: 0.0, 1: 1.0, 2: 0.5}, (1, 0): {0: 1.0, 1: 1.0}}
    s = lr.retest_summary(first, second)
    assert s["cells"] == 8 and s["poses"] == 3
    # same success: pose (0,0) 3/3, (0,1) 1/3 (0.5 vs 0.5), (1,0) 0/2
    assert s["same_success"] == pytest.approx(4 / 8)
    assert s["within_0.1"] == pytest.approx(4 / 8)
    # Spearman +1, -1 and 0 (a constant replicate ranks nothing): median 0, no ceiling
    assert s["pose_spearman"]["median"] == pytest.approx(0.0) and s["ceiling"] == 0.0
    s = lr.retest_summary({k: first[k] for k in [(0, 0)]}, second)
    assert s["pose_spearman"]["median"] == pytest.approx(1.0) and s["ceiling"] == pytest.approx(1.0)


def test_varying_poses_need_enough_designs_and_a_spread(script_module):
    lr = script_module("label_retest")
    obj = np.array([0] * 8 + [0] * 8 + [1] * 3)
    pose = np.array([0] * 8 + [1] * 8 + [0] * 3)
    p = np.concatenate([np.linspace(0, 1, 8), np.ones(8), [0.0, 0.5, 1.0]])
    assert lr.varying_poses(obj, pose, p, 8) == [(0, 0)]


def test_shifted_matrix_moves_the_palm_along_its_own_axis(script_module):
    lr = script_module("label_retest")
    c, s = np.cos(0.3), np.sin(0.3)
    t = np.array([[c, -s, 0, 0.1], [s, c, 0, 0.2], [0, 0, 1, 0.3], [0, 0, 0, 1]], dtype=float)
    moved = np.reshape(lr.shifted_matrix(tuple(t.ravel()), 1, 0.005), (4, 4))
    np.testing.assert_array_equal(moved[:3, :3], t[:3, :3])
    np.testing.assert_allclose(moved[:3, 3], t[:3, 3] + 0.005 * np.array([-s, c, 0.0]), atol=1e-15)
    back = np.reshape(lr.shifted_matrix(tuple(moved.ravel()), 1, -0.005), (4, 4))
    np.testing.assert_allclose(back, t, atol=1e-15)


def test_shift_summary_pairs_moved_poses_with_the_unmoved_retest(script_module):
    lr = script_module("label_retest")
    up, down = {0: 0.0, 1: 0.3, 2: 0.6, 3: 1.0}, {0: 1.0, 1: 0.6, 2: 0.3, 3: 0.0}
    first = {(0, 0): up, (1, 0): up}
    retest = {(0, 0): up, (1, 0): up}  # the unmoved replicate ranks both poses as the first label: +1
    moved = {
        ("x", 2.0): {(0, 0): up, (1, 0): up},  # +x keeps the ranking
        ("x", -2.0): {(0, 0): down, (1, 0): up},  # -x reverses pose (0, 0)'s: its mean over the signs 0
        ("y", 2.0): {(0, 0): {0: 0.0, 1: 0.5}},  # a moved pose without every design does not count
        ("z", 2.0): {(0, 0): down, (1, 0): down},
        ("z", 5.0): {(0, 0): {k: 0.5 for k in up}},  # a constant moved label ranks nothing: 0
    }
    s = lr.shift_summary(first, retest, moved)
    assert s["x2mm"]["poses"] == 2 and s["x2mm"]["median"] == pytest.approx(0.5)
    assert s["x2mm"]["retest_median"] == pytest.approx(1.0)
    assert s["x2mm"]["paired_difference"]["mean"] == pytest.approx(-0.5)
    lo, hi = s["x2mm"]["paired_difference"]["ci95"]
    assert -1.0 <= lo <= -0.5 <= hi <= 0.0
    assert s["x2mm"]["retest_mean_abs_difference"] == 0.0
    # pose (0, 0) moved -x: |1-0|, |0.6-0.3| twice, |0-1| over 8 cells of the two signs
    assert s["x2mm"]["mean_abs_difference"] == pytest.approx((1 + 0.3 + 0.3 + 1) / 16)
    assert s["y2mm"] == {"poses": 0}
    assert s["z2mm"]["mean"] == pytest.approx(-1.0) and s["z2mm"]["paired_difference"][
        "mean"
    ] == pytest.approx(-2.0)
    # every axis pooled: pose (0, 0) has x+ 1, x- -1, z+ -1 -> -1/3; pose (1, 0) x+ 1, x- 1, z+ -1 -> 1/3
    assert s["all2mm"]["mean"] == pytest.approx(0.0) and s["all2mm"]["poses"] == 2
    assert s["z5mm"]["poses"] == 1 and s["z5mm"]["median"] == 0.0 and s["x5mm"] == {"poses": 0}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """One 50 mm box at 1500 kg/m³ (a marginal grasp: at 300-500 every cell holds), 2 poses x 8 designs,
    2 perturbed rollouts extended to 4 where they disagree."""
    import trimesh

    work = tmp_path_factory.mktemp("retest")
    box = work / "box50.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    config = DatagenConfig(
        objects=(str(box),),
        poses_per_object=2,
        designs_per_pose=8,
        density=parse_density_spec("1500"),
        scenario=_SCENARIO,
        tension=_SCENARIO.tension,
        perturbation=_WIDE,
        perturbations=2,
        perturbations_max=4,
    )
    assert generate(config, work / "data", cache_dir=work / "cache")["complete"]
    return work / "data"


def _script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(_SCRIPT), *args], capture_output=True, text=True, timeout=600)


def test_a_run_reruns_every_cell_of_the_varying_poses(dataset, tmp_path):
    s = open_dataset(dataset).samples().to_pydict()
    p = {}
    for o, q, v in zip(s["object_index"], s["pose_index"], s["success_p"], strict=True):
        p.setdefault((o, q), []).append(v)
    varying = [k for k, v in p.items() if len(v) >= 8 and np.ptp(v) > 0]
    assert varying, "the planted dataset must hold a varying pose"
    out = tmp_path / "retest.json"
    res = _script("--data", str(dataset), "--poses", "5", "--workers", "1", "--out", str(out))
    assert res.returncode == 0, res.stderr
    r = json.loads(out.read_text())
    assert r["candidate_poses"] == r["poses_rerun"] == r["poses"] == len(varying)
    assert r["cells"] == sum(len(p[k]) for k in varying)
    assert 2 * r["cells"] <= r["rollouts"] <= 4 * r["cells"]
    assert 0.0 <= r["same_success"] <= 1.0 and -1.0 <= r["pose_spearman"]["median"] <= 1.0
    assert r["provenance"]["command"].startswith("python3 scripts/label_retest.py")


def test_a_run_with_shifts_reruns_each_pose_moved_along_every_palm_axis(dataset, tmp_path):
    out = tmp_path / "shift.json"
    res = _script("--data", str(dataset), "--workers", "1", "--shift-mm", "3", "--out", str(out))
    assert res.returncode == 0, res.stderr
    r = json.loads(out.read_text())
    assert r["shift_mm"] == [3.0] and set(r["shifted"]) == {"x3mm", "y3mm", "z3mm", "all3mm"}
    for name, got in r["shifted"].items():
        assert 0 <= got["poses"] <= r["poses"], name
        if got["poses"]:
            assert -1.0 <= got["median"] <= 1.0 and -2.0 <= got["paired_difference"]["mean"] <= 2.0
    assert r["shifted"]["all3mm"]["poses"] >= max(r["shifted"][f"{a}3mm"]["poses"] for a in "xyz")
    moved = [ln for ln in res.stdout.splitlines() if ln.startswith("label_retest: shard") and "palm" in ln]
    assert len(moved) == 6 * r["poses_rerun"] and any("palm z -3 mm" in ln for ln in moved)
    assert "--shift-mm 3" in r["provenance"]["command"]


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--poses", "0"], "at least 1"),
        (["--replicate", "0"], "at least 1"),
        ([], "missing_dataset"),
        (["--shift-mm", "2,x"], "--shift-mm 2,x"),
        (["--shift-mm", "-1"], "> 0"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, args, says):
    out = tmp_path / "o.json"
    res = _script("--data", str(tmp_path / "missing_dataset"), "--out", str(out), *args)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in res.stderr
    assert not out.exists()
