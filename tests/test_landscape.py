"""The grasp landscape benchmark (short CI version) and the cross-check's design sweep."""

import numpy as np
import pytest

from mjcodesign.errors import DesignError


def test_landscape_ci_flags_every_rollout_and_counts_its_failures():
    from mjcodesign.bench.landscape import CI, bench_landscape

    res = bench_landscape(
        objects=CI["objects"], poses=CI["poses"], designs=CI["designs"], sweep=False, densities=("light",)
    )
    assert [b["tendon"] for b in res["blocks"]] == ["force:10", "position:1000"]
    n_pairs = sum(res["poses_per_object"].values())
    for b in res["blocks"]:
        assert b["rollouts"] == n_pairs * len(CI["designs"])
        assert b["nan"] == 0
        assert sum(b["pairs"].values()) == n_pairs
        assert set(b["success"]) <= {"soft", "semi-rigid", "random"}
        assert all(0.0 <= v <= 1.0 for v in b["success"].values())
        # every failure kind is counted; a sample error is never also a success
        assert b["implausible"] == b["failures"].get("implausible", 0)
        assert 0 <= b["far_implausible"] <= min(b["far"], b["implausible"])
        summed = {}
        for kinds in b["failures_by_group"].values():
            for k, v in kinds.items():
                summed[k] = summed.get(k, 0) + v
        assert summed == b["failures"]
        assert b["cpu_s_per_rollout"] > 0


def test_design_sweep_names_and_summary_rows():
    from mjcodesign.crosscheck import parse_sweep, summary_rows
    from mjcodesign.crosscheck.rows import row

    assert parse_sweep("random:3..5") == ["random:3", "random:4", "random:5"]
    assert parse_sweep("random:3") is None and parse_sweep("soft") is None
    with pytest.raises(DesignError):
        parse_sweep("random:5..3")
    rows = [
        row("cantilever", "fem", "random:0", "tip_deflection_m", 1.0, 1.1),
        row("cantilever", "chain", "random:0", "tip_deflection_m", 1.02, 1.0),
        row("cantilever", "chain", "random:1", "tip_deflection_m", 0.9, 1.0),
        row("cantilever", "chain", "random:2", "tip_deflection_m", 1.01, 1.0),
    ]
    summary = summary_rows("cantilever", "random:0..2", rows)
    assert [(r["model"], r["metric"]) for r in summary] == [
        ("chain", "summary:worst_rel_diff"),
        ("chain", "summary:median_rel_diff"),
    ]
    assert summary[0]["value"] == pytest.approx(0.1)
    assert summary[1]["value"] == pytest.approx(float(np.median([0.02, 0.1, 0.01])))
    assert set(summary[0]) == set(rows[0])  # the same columns as every other row


def test_landscape_at_real_masses_uses_the_published_masses_and_skips_the_rest():
    from mjcodesign.bench.landscape import bench_landscape

    res = bench_landscape(
        objects=("013_apple", "063-a_marbles"), poses=1, designs=("soft",), sweep=False, densities=("real",),
        tendons=("force:10",),
    )
    assert "063-a_marbles" in res["skipped"] and "no published mass" in res["skipped"]["063-a_marbles"]
    (block,) = res["blocks"]
    assert block["mass"] == "real" and block["density_kg_m3"] is None
    assert block["mass_kg"] == {"013_apple": pytest.approx(0.068, rel=1e-12)}  # the YCB list's 68 g
