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
        objects=("013_apple", "063-a_marbles"),
        poses=1,
        designs=("soft",),
        sweep=False,
        densities=("real",),
        tendons=("force:10",),
    )
    assert "063-a_marbles" in res["skipped"] and "no published mass" in res["skipped"]["063-a_marbles"]
    (block,) = res["blocks"]
    assert block["mass"] == "real" and block["density_kg_m3"] is None
    assert block["mass_kg"] == {"013_apple": pytest.approx(0.068, rel=1e-12)}  # the YCB list's 68 g


def test_real_regime_analysis_counts_pairs_and_sides_on_known_outcomes():
    # Three objects, two poses, soft / semi-rigid / random:0; outcomes written by hand.
    from mjcodesign.bench.landscape_real import _analyse

    per_object = {
        "light": {"mass_kg": 0.05, "solidity": 0.6, "poses": 2},
        "mid": {"mass_kg": 0.2, "solidity": 0.8, "poses": 2},
        "heavy": {"mass_kg": 0.6, "solidity": 1.0, "poses": 2},
    }
    outcome = {
        "light": {"soft": "11", "semi-rigid": "1.", "random:0": "11"},  # favours soft; pose 1 mixed
        "mid": {"soft": "..", "semi-rigid": "..", "random:0": ".."},  # nothing holds: 2 'none' pairs
        "heavy": {"soft": "..", "semi-rigid": "11", "random:0": "1."},  # favours stiff; both pairs mixed
    }
    res = _analyse(outcome, per_object, ("soft", "semi-rigid", "random:0"))
    assert res["pairs"]["all"] == 1 and res["pairs"]["mixed"] == 3 and res["pairs"]["none"] == 2
    assert res["pairs"]["mixed_share"]["value"] == pytest.approx(3 / 6)
    assert res["success"]["soft"]["rollouts"]["value"] == pytest.approx(2 / 6)
    assert res["success"]["soft"]["objects"]["value"] == pytest.approx((1 + 0 + 0) / 3)
    assert res["success_all"] == pytest.approx(8 / 18)  # 5 + 0 + 3 of 18
    sides = res["soft_vs_stiff"]
    assert (
        sides["favour_soft"] == ["light"]
        and sides["favour_stiff"] == ["heavy"]
        and sides["neither"] == ["mid"]
    )
    assert sides["stiff_minus_soft"]["difference"]["value"] == pytest.approx((-0.5 + 0 + 1) / 3)
    assert sides["rank_correlation_with_mass"]["rho"] == pytest.approx(1.0)  # -0.5, 0, 1 rise with mass
    assert (
        res["by_mass"]["0-100 g"]["objects"] == 1 and res["by_mass"][">= 300 g"]["semi-rigid"]["value"] == 1.0
    )


def test_landscape_real_regime_ci_runs_every_setting_and_reports_consistent_counts():
    from mjcodesign.bench.landscape import bench_landscape
    from mjcodesign.bench.landscape_real import CI_REAL, SENSITIVITY

    res = bench_landscape(
        regime="real",
        objects=(*CI_REAL["objects"], "063-a_marbles"),  # the marbles have no published mass
        poses=CI_REAL["poses"],
        designs=CI_REAL["designs"],
    )
    assert "no published mass" in res["skipped"]["063-a_marbles"]
    (name,) = CI_REAL["objects"]
    n = CI_REAL["poses"] * len(CI_REAL["designs"])
    assert res["rollouts"] == n * (1 + len(SENSITIVITY))
    assert res["objects"][name]["mass_kg"] == pytest.approx(0.514)  # the YCB list's sugar box
    assert res["scenario"]["tendon"]["max_tension_n"] == pytest.approx(0.52 / 0.008)
    assert res["scenario"]["lift_m"] == 0.1
    outcomes = res["outcomes"][name]
    assert all(len(v) == CI_REAL["poses"] and set(v) <= {"1", "."} for v in outcomes.values())
    k = sum(v.count("1") for v in outcomes.values())
    assert res["success_all"] == pytest.approx(k / n)
    assert sum(res["pairs"][c] for c in ("all", "mixed", "none")) == CI_REAL["poses"]
    assert [(r["setting"], r["value"]) for r in res["sensitivity"]] == list(SENSITIVITY)
    assert len(res["sensitivity_outcomes"]) == len(SENSITIVITY)


def test_landscape_real_regime_refuses_the_paper_regimes_flags(capsys):
    from mjcodesign.cli.main import main

    assert main(["bench", "landscape", "--regime", "real", "--tendons", "force:10", "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--tendons" in err[0]
