"""scripts/ranking_contact.py: the contact numbers of a cloud, the folds, the paired interval, a planted run, bad input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

_SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "ranking_contact.py"
_SPANS = np.array([(0.0, 0.02), (0.02, 0.04), (0.04, 0.06)])  # three blocks of 2 cm


def test_contact_features_count_the_points_at_each_block_on_each_side(script_module):
    rc = script_module("ranking_contact")
    # finger A (+y): two points at block 1's height reaching 1 and 3 cm; finger B (-y): one at block 2
    cloud = np.array([[[0.0, 0.01, -0.03], [0.0, 0.03, -0.025], [0.0, -0.02, -0.05], [0.0, 0.0, -0.01]]])
    f = rc.contact_features(cloud, _SPANS)
    np.testing.assert_allclose(f[0, :3], [0.0, 0.5, 0.0])  # presence, finger A (y = 0 is on neither side)
    np.testing.assert_allclose(f[0, 3:6], [0.0, 0.0, 0.25])  # presence, finger B
    np.testing.assert_allclose(f[0, 6:9], [0.0, 0.03, 0.0])  # reach towards A
    np.testing.assert_allclose(f[0, 9:12], [0.0, 0.0, 0.02])  # reach towards B


def test_contact_inputs_weight_each_finger_by_where_the_object_is(script_module):
    rc = script_module("ranking_contact")
    log_e = np.array([[14.0, 16.0, 15.0, 13.5, 17.0, 15.0]])
    contact = np.concatenate([[[0.0, 0.5, 0.0, 0.0, 0.0, 0.25]], np.zeros((1, 6))], axis=1)
    x = rc.contact_inputs(np.zeros((1, 2)), log_e, contact, np.array([[0.03, 0.04]]))
    assert x.shape == (1, 2 + 12 + 2 + 6 + 2)
    np.testing.assert_allclose(x[0, -2:], [16.0, 15.0])  # finger A's block 1, finger B's block 2
    np.testing.assert_allclose(x[0, 16:22], [0.0, 8.0, 0.0, 0.0, 0.0, 3.75])


def test_object_folds_hold_each_object_out_once_in_even_folds(script_module):
    rc = script_module("ranking_contact")
    names = [f"o{i}" for i in range(11)]
    folds = rc.object_folds(names, 3, seed=4)
    assert sorted(folds) == sorted(names) and sorted(np.bincount(list(folds.values()))) == [3, 4, 4]
    assert folds == rc.object_folds(list(reversed(names)), 3, seed=4)


def test_paired_interval_resamples_objects_not_poses(script_module):
    rc = script_module("ranking_contact")
    # object a: 9 poses at +0.5; object b: one pose at -0.5. By pose the mean is +0.4, by object a draw
    # of b twice gives -0.5, so the interval reaches below zero.
    a = np.array([0.5] * 9 + [-0.5])
    objects = np.array(["a"] * 9 + ["b"])
    out = rc.paired(a, np.zeros(10), objects, seed=0)
    assert out["mean"] == pytest.approx(0.4) and out["positive"] == 9 and out["objects"] == 2
    assert out["low"] == pytest.approx(-0.5) and out["high"] == pytest.approx(0.5)


def test_a_planted_block_effect_is_ranked_by_the_contact_model(script_module):
    """Success rises with the stiffness of the block the object sits at, which moves from pose to pose."""
    rc = script_module("ranking_contact")
    from mjcodesign.design.finger import FingerDesign

    spans = np.array([(b.x0, b.x1) for b in FingerDesign().blocks()])
    rng = np.random.default_rng(0)
    n_obj, poses, designs = 6, 8, 10
    P = n_obj * poses
    block = rng.integers(0, 11, P)  # the block each pose's object sits at
    clouds = np.zeros((P, 64, 3))
    mid = spans[block].mean(axis=1)
    clouds[:, :, 2] = -mid[:, None] + rng.uniform(-0.003, 0.003, (P, 64))
    clouds[:, :, 1] = np.where(np.arange(64) % 2, 1.0, -1.0) * rng.uniform(0.01, 0.03, (P, 64))
    clouds[:, :, 0] = rng.uniform(-0.01, 0.01, (P, 64))
    pose = np.repeat(np.arange(P), designs)
    log_e = rng.uniform(13.5, 17.0, (P * designs, 22))
    z = log_e[np.arange(P * designs), block[pose]] - 15.25
    p = 1.0 / (1.0 + np.exp(-2.0 * z))
    data = SimpleNamespace(
        pose=pose,
        log_e=log_e,
        success_p=p,
        success=p >= 0.5,
        clouds=clouds,
        openings=np.full((P, 2), 0.03),
        objects=np.repeat([f"o{i}" for i in range(n_obj)], poses).astype(object),
        com=np.zeros((P, 3)),
        up=np.tile([0.0, 0.0, 1.0], (P, 1)),
        density=np.full(P * designs, 400.0),
    )
    out = rc.evaluate(data, rc.object_folds([f"o{i}" for i in range(n_obj)], 3, seed=0), seed=0)
    assert out["poses_ranked"] == P and out["rows"] == P * designs
    assert out["spearman"]["contact"]["median"] > 0.5
    assert out["contact_minus_base"]["low"] > 0.0


@pytest.mark.parametrize(
    ("args", "says"),
    [(["--folds", "1"], "--folds '1'"), (["--seed", "x"], "--seed 'x'"), ([], "missing_dataset")],
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
