"""scripts/ranking_sources.py: the pose distance, the neighbouring-pose transfer on planted data, bad input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

_SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "ranking_sources.py"


def _palm(x: float, angle: float) -> np.ndarray:
    """A palm at (x, 0, 0) turned by ``angle`` about z."""
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    m[0, 3] = x
    return m


def test_pose_distance_adds_the_position_step_and_the_scaled_angle(script_module):
    rs = script_module("ranking_sources")
    palms = np.stack([_palm(0.0, 0.0), _palm(0.03, 0.0), _palm(0.0, 0.5), _palm(0.03, -0.5)])
    d = rs.pose_distances(palms, 0, np.array([1, 2, 3]))
    np.testing.assert_allclose(d, [0.03, rs.ANGLE_SCALE * 0.5, 0.03 + rs.ANGLE_SCALE * 0.5], atol=1e-12)
    assert rs.pose_distances(palms, 3, np.array([3]))[0] == pytest.approx(0.0, abs=1e-7)


def test_the_nearest_pose_transfers_its_ranking_and_the_farthest_its_own(script_module):
    """Object a: poses 0 and 1 (1 cm apart) prefer a stiff block 0, pose 2 (20 cm away) a soft one."""
    rs = script_module("ranking_sources")
    rng = np.random.default_rng(0)
    n = 8
    log_e = np.full((3 * n, 22), 15.25)  # only block 0 varies: 8 designs identify its effect
    log_e[:, 0] = rng.uniform(13.5, 17.0, size=3 * n)
    stiff = (log_e[:, 0] - 13.5) / 3.5
    p = np.concatenate([stiff[:n], stiff[n : 2 * n], 1.0 - stiff[2 * n :]])
    data = SimpleNamespace(
        palm=np.stack([_palm(0.0, 0.0), _palm(0.01, 0.0), _palm(0.2, 0.0)]),
        pose=np.repeat([0, 1, 2], n),
        log_e=log_e,
        success_p=p,
        success=p >= 0.5,
    )
    groups = [np.arange(n), np.arange(n, 2 * n), np.arange(2 * n, 3 * n)]
    out = rs.neighbouring_poses(data, groups, [0, 1, 2], np.array(["a", "a", "a"]), [1])
    # pose 0 <- pose 1 (+1), pose 1 <- pose 0 (+1), pose 2 <- pose 1 (-1): median +1
    assert out["nearest_1"]["median"] == pytest.approx(1.0) and out["nearest_1"]["positive"] == 2
    # pose 0 <- pose 2 (-1), pose 1 <- pose 2 (-1), pose 2 <- pose 0 (-1)
    assert out["farthest_1"]["median"] == pytest.approx(-1.0) and out["farthest_1"]["positive"] == 0
    assert out["nearest_distance_m"]["median"] == pytest.approx(0.01)


@pytest.mark.parametrize(
    ("args", "says"),
    [(["--nearest", "0"], "--nearest '0'"), (["--nearest", "x"], "--nearest 'x'"), ([], "missing_dataset")],
)
def test_bad_input_exits_2_with_one_line(tmp_path, args, says):
    cmd = [
        sys.executable,
        str(_SCRIPT),
        "--data",
        str(tmp_path / "missing_dataset"),
        "--out",
        str(tmp_path / "o.json"),
    ]
    res = subprocess.run(cmd + args, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in res.stderr
    assert not (tmp_path / "o.json").exists()
