"""scripts/object_groups.py: a later evaluation's designs pair with an earlier one's only when they can."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def groups(script_module):
    return script_module("object_groups")


SUMMARY = {
    "suite": {"digest": "x"},
    "seed": 0,
    "perturbations": 2,
    "regime": "real",
    "scenario": {"lift": 0.1},
}


def _rows(design: str, outcome, objects=("a", "b", "c")) -> list[dict]:
    rows = []
    for i, o in enumerate(objects):
        for pose in range(2):
            for draw in range(2):
                rows.append(
                    {
                        "object": o,
                        "pose": pose,
                        "draw": draw,
                        "density": "real",
                        "impulse_paper_ns": 0.1,
                        "design": design,
                        "domain": "in-domain",
                        "fold": 0,
                        "perturbation": {"mass_scale": 1.0 + 0.01 * (pose + 2 * draw)},
                        "success": bool(outcome(i, pose, draw)),
                        "sample_error": False,
                        "failures": [],
                        "hold_force_n": 1.0,
                        "slip_m": 0.0,
                        "lift_margin_m": 0.01,
                    }
                )
    return rows


def test_a_later_design_pairs_with_the_first_evaluation(groups):
    first = _rows("soft", lambda i, p, d: 0) + _rows("semi-rigid", lambda i, p, d: p)
    later = _rows("semi-rigid", lambda i, p, d: p) + _rows("joint:oracle.json", lambda i, p, d: 1)
    rows = groups.merge_evaluations(first, SUMMARY, later, dict(SUMMARY))
    assert {r["design"] for r in rows} == {"soft", "semi-rigid", "joint:oracle.json"}
    assert len(rows) == len(first) + len(later) // 2
    out = groups.groups_summary(
        rows, {"all": {"a", "b", "c"}}, [("joint:oracle.json", "semi-rigid")], "all", 0
    )
    (pair,) = out["all"]["paired"]
    assert pair["difference"]["value"] == pytest.approx(0.5) and pair["wins"] == 3


def test_evaluations_that_do_not_pair_are_refused(groups):
    first = _rows("semi-rigid", lambda i, p, d: p)
    changed = _rows("semi-rigid", lambda i, p, d: 1 - p) + _rows("joint:x.txt", lambda i, p, d: 1)
    with pytest.raises(ValueError, match="not pairable"):
        groups.merge_evaluations(first, SUMMARY, changed, dict(SUMMARY))
    with pytest.raises(ValueError, match="'seed'"):
        groups.merge_evaluations(
            first, SUMMARY, _rows("joint:x.txt", lambda i, p, d: 1), {**SUMMARY, "seed": 1}
        )
