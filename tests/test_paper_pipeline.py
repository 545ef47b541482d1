"""scripts/paper_pipeline.py: every step's command line is one the CLI accepts, at both scales.

The run itself (physics, minutes at the smallest scale) is recorded, not tested here: what a test can
keep true is that the documented sequence still parses when a flag changes, and that the groups
compare the designs the evaluation runs.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from mjcodesign.cli.main import build_parser

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "paper_pipeline.py"


@pytest.fixture(scope="module")
def pipeline(script_module):
    return script_module("paper_pipeline")


@pytest.mark.parametrize("scale", ["paper", "smoke"])
@pytest.mark.parametrize("oracle", [0, 40_000, "/somewhere/oracle.json"])
def test_every_step_parses_and_the_groups_compare_what_is_evaluated(pipeline, scale, oracle):
    s = pipeline.SCALES[scale]
    cmds = {**pipeline.first_commands(s, seed=0, resume=True),
            **pipeline.step_commands(s, seed=0, train=["013_apple", "014_lemon"], held=["017_orange"],
                                     hybrid_budget=8000, oracle=oracle)}  # fmt: skip
    parser = build_parser()
    for name, argv in cmds.items():
        if argv[0] == "mjcodesign":
            args = parser.parse_args(argv[1:])  # a flag the CLI no longer takes exits here
            assert callable(args.func), name
    assert ("oracle" in cmds) == bool(oracle) and "evaluate_oracle" not in cmds
    if isinstance(oracle, str):
        assert cmds["oracle"][-2:] == ["--adopt-oracle", oracle]
    assert (("suite" in cmds) == (scale == "smoke")) and "--resume" in cmds["datagen"]
    ev = cmds["evaluate"]
    designs = ev[ev.index("--designs") + 1].split(",")
    # one evaluation: the presets, the four co-designs and, with an oracle, the oracle on the same draws
    assert designs[:3] == list(pipeline.PRESETS) and len(designs) == 7 + bool(oracle)
    assert (pipeline.ORACLE in designs) == bool(oracle)
    impulses = s.impulses.split(",")
    groups = [n for n in cmds if n.startswith("groups_")]
    assert len(groups) == len(pipeline.POLICIES) * len(impulses)
    for name in groups:
        g = cmds[name]
        assert g[g.index("--impulse") + 1] in impulses and "--also" not in g
        pairs = {tuple(g[i + 1].split(",", 1)) for i, a in enumerate(g) if a == "--compare"}
        codesigned = [m for m in designs[3:] if m != pipeline.ORACLE]
        expected = {(m, p) for m in codesigned for p in pipeline.PRESETS}
        if oracle:
            expected |= {(pipeline.ORACLE, m) for m in designs if m != pipeline.ORACLE}
        assert pairs == expected
    # the hybrid starts from the success co-design the optimize step writes
    assert "joint:joint_success/design.txt" in cmds["hybrid"] and cmds["joint_success"][-1] == "joint_success"


def test_a_step_done_with_another_command_stops_the_run(pipeline, tmp_path, capsys):
    import json

    steps = tmp_path / "steps"
    steps.mkdir()
    old = [sys.executable, "/elsewhere/scripts/object_groups.py", "evaluation", "--also", "evaluation_oracle"]
    (steps / "groups_all.json").write_text(json.dumps({"command": pipeline.shlex.join(old), "exit_code": 0}))
    # the same step from another checkout and interpreter is done
    same = ["/usr/bin/python3", str(SCRIPT.with_name("object_groups.py")), *old[2:]]
    assert pipeline._run(tmp_path, "groups_all", same, False)["exit_code"] == 0
    assert "done before, skipped" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        pipeline._run(tmp_path, "groups_all", [*same[:3]], False)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "done with another command" in err[0] and "groups_all.json" in err[0]


@pytest.mark.slow
def test_the_smoke_scale_runs_end_to_end_and_resumes(tmp_path):
    # ~1 min on 2 cores: five objects, two poses, 2 epochs, tiny CMA-ES; then a rerun skips every step
    import json
    import subprocess

    rec = tmp_path / "record.json"
    oracle = tmp_path / "oracle.txt"  # an earlier oracle's design, as --oracle-design takes it
    oracle.write_text(",".join(["15.5"] * 22))
    cmd = [
        sys.executable,
        str(SCRIPT),
        "--work",
        str(tmp_path / "w"),
        "--scale",
        "smoke",
        "--record",
        str(rec),
        "--oracle-design",
        str(oracle),
    ]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    r = json.loads(rec.read_text())
    names = ["datagen", "train", "joint_lopt", "joint_success", "individual", "suite", "hybrid", "oracle",
             "evaluate", "groups_all", "groups_fixed", "groups_oracle", "limits"]  # fmt: skip
    assert list(r["steps"]) == names and all(s["exit_code"] == 0 for s in r["steps"].values())
    assert r["objects"]["held_out"] and set(r["objects"]["train"]).isdisjoint(r["objects"]["held_out"])
    assert json.loads((tmp_path / "w" / "oracle" / "design.json").read_text())["design"] == [15.5] * 22
    assert set(r["oracle_gaps"]["groups_all"]["train"]) == {"joint:joint_lopt/design.txt",
        "joint:joint_success/design.txt", "joint:hybrid/design.json", "individual:individual"}  # fmt: skip
    assert set(r["limits"]["splits"]) == {"in-domain", "out-of-domain"}
    for policy in ("all", "fixed", "oracle"):
        groups = r["groups"][f"groups_{policy}"]["groups"]
        assert {"train", "held-out", "in-domain", "out-of-domain"} <= set(groups)
        # three joint co-designs against three presets, the oracle against every other design; the
        # individual designs only on their own objects
        assert len(groups["held-out"]["paired"]) == 9 + 6 and len(groups["train"]["paired"]) == 12 + 7
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and again.stderr.count("done before, skipped") == len(names)
    # the co-designs on 2 object folds continue the run (~1 min): every in-domain object held out once
    krec = tmp_path / "kfold.json"
    kcmd = [sys.executable, str(SCRIPT.with_name("kfold_codesign.py")), "--work", str(tmp_path / "w"), "--scale",
            "smoke", "--record", str(krec)]  # fmt: skip
    k = subprocess.run(kcmd, capture_output=True, text=True, timeout=600)
    assert k.returncode == 0, k.stderr[-2000:]
    kr = json.loads(krec.read_text())
    assert all(s["exit_code"] == 0 for s in kr["steps"].values()) and len(kr["folds"]) == 2
    held = sorted(o for f in kr["folds"] for o in f["held_out"])
    assert held == sorted(r["objects"]["train"] + r["objects"]["held_out"])  # each in-domain object once
    assert kr["objects_per_design"] == {"joint_lopt": 5, "joint_success": 5, "hybrid": 5}
    g = kr["groups"]["kfold_groups_all"]["groups"]["in-domain"]
    assert (
        len(g["objects"]) == 5 and len(g["paired"]) == 3 * 3 + 3
    )  # each against each preset and its single split


def test_table_one_pairs_each_design_with_the_best_preset_of_each_column(pipeline):
    iv = lambda v: {"value": v, "low": v - 0.1, "high": v + 0.1, "n": 10}  # noqa: E731
    cols = {
        "train": {"soft": 0.5, "semi-rigid": 0.8, "paper-optimized": 0.7, "joint:j.txt": 0.9},
        "held-out": {"soft": 0.6, "semi-rigid": 0.6, "paper-optimized": 0.7, "joint:j.txt": 0.65},
        "out-of-domain": {"soft": 0.4, "semi-rigid": 0.5, "paper-optimized": 0.3, "joint:j.txt": 0.5},
    }
    groups = {
        c: {
            "designs": {d: iv(v) for d, v in vals.items()},
            "paired": [
                {"a": "joint:j.txt", "b": p, "difference": iv(vals["joint:j.txt"] - vals[p])}
                for p in pipeline.PRESETS
            ],
        }
        for c, vals in cols.items()
    }
    md = pipeline.table_markdown({"groups_all": {"policy": "all", "impulse_paper_ns": 0.1, "groups": groups}})
    row = next(line for line in md.splitlines() if line.startswith("| joint:j.txt") and " vs " in line)
    assert row.split(" | ")[1:] == ["+10.0 [+0.0, +20.0] vs semi-rigid", "-5.0 [-15.0, +5.0] vs paper-optimized",
                                    "+0.0 [-10.0, +10.0] vs semi-rigid |"]  # fmt: skip
    assert "| soft | 50.0 [40.0, 60.0] | 60.0 [50.0, 70.0] | 40.0 [30.0, 50.0] |" in md
