"""scripts/kfold_codesign.py: its commands parse and pair what they evaluate; folds map objects to designs.

The run itself (minutes at the smoke scale, hours at paper scale) is recorded, not tested here.
"""

from __future__ import annotations

import hashlib
import json

import pytest

from mjcodesign.cli.main import build_parser
from mjcodesign.design.stiffness import read_design_file


@pytest.fixture(scope="module")
def kfold(script_module):
    return script_module("kfold_codesign")


@pytest.mark.parametrize("scale", ["paper", "smoke"])
def test_every_step_parses_and_the_groups_pair_each_fold_design(kfold, scale):
    pp = kfold._pipeline()
    s = pp.SCALES[scale]
    suite = [] if s.eval_objects == "suite" else ["--suite", "suite.json"]
    cmds = {"folds": kfold.folds_command(s, seed=0, k=5)}
    cmds |= kfold.fold_commands(s, seed=0, fold=3, ckpt="folds/fold3", train=["013_apple", "014_lemon"],
                                hybrid_budget=800, suite=suite)  # fmt: skip
    pipe = pp.step_commands(s, seed=0, train=["013_apple"], held=["014_lemon"], hybrid_budget=800, oracle=0)
    cmds |= kfold.evaluate_commands(pipe, s.impulses)
    parser = build_parser()
    for name, argv in cmds.items():
        if argv[0] == "mjcodesign":
            assert callable(parser.parse_args(argv[1:]).func), name
    folds = cmds["folds"]
    assert folds[folds.index("--folds") + 1] == "5" and folds[folds.index("--out") + 1] == "folds"
    assert "--efficiency" not in folds and "--smoothness-poses" not in folds  # train --folds refuses them
    assert folds[folds.index("--epochs") + 1] == str(s.epochs)
    assert list(cmds)[1:4] == ["fold3_joint_lopt", "fold3_joint_success", "fold3_hybrid"]
    assert (
        "folds/fold3" in cmds["fold3_joint_success"]
        and "joint:fold3_joint_success/design.txt" in cmds["fold3_hybrid"]
    )
    ev, ours = pipe["evaluate"], cmds["evaluate_kfold"]
    assert ours[: ours.index("--designs")] == ev[: ev.index("--designs")]  # the same suite, seed and draws
    designs = ours[ours.index("--designs") + 1].split(",")
    assert designs == ["semi-rigid", *(kfold.label(n) for n in kfold.CODESIGNS)]
    groups = [n for n in cmds if n.startswith("kfold_groups_")]
    assert len(groups) == len(pp.POLICIES) * len(s.impulses.split(","))
    for name in groups:
        g = cmds[name]
        pairs = {tuple(g[i + 1].split(",", 1)) for i, a in enumerate(g) if a == "--compare"}
        expected = {(kfold.label(n), p) for n in kfold.CODESIGNS for p in pp.PRESETS}
        expected |= {(kfold.label(n), kfold.SINGLE[n]) for n in kfold.CODESIGNS}
        assert pairs == expected and g[g.index("--also") + 1] == "evaluation_kfold"
        # the single-split designs are the pipeline's evaluation's labels
        assert {kfold.SINGLE[n] for n in kfold.CODESIGNS} <= set(ev[ev.index("--designs") + 1].split(","))


def test_without_drops_each_flag_with_its_value(kfold):
    argv = ["train", "--out", "x", "--epochs", "3", "--efficiency", "0", "--json"]
    assert kfold._without(argv, ("--out", "--efficiency")) == ["train", "--epochs", "3", "--json"]


def test_assemble_gives_each_held_out_object_its_fold_design(kfold, tmp_path):
    folds = [{"path": "fold0", "held_out": ["a", "b"]}, {"path": "fold1", "held_out": ["c"]}]
    for k, value in enumerate((14.0, 16.0)):
        for name in kfold.CODESIGNS:
            f = tmp_path / kfold.design_file(k, name)
            f.parent.mkdir(parents=True, exist_ok=True)
            v = value + (0.5 if name == "hybrid" else 0.0)
            f.write_text(json.dumps({"design": [v] * 22}) if f.suffix == ".json" else ",".join([str(v)] * 22))
    made = kfold.assemble(tmp_path, folds)
    assert made == {n: {"a": "fold0", "b": "fold0", "c": "fold1"} for n in kfold.CODESIGNS}
    assert read_design_file(tmp_path / "kfold_joint_lopt" / "b.json").as_list() == [14.0] * 22
    assert read_design_file(tmp_path / "kfold_hybrid" / "c.json").as_list() == [16.5] * 22
    assert sorted(p.name for p in (tmp_path / "kfold_joint_success").iterdir()) == [
        "a.json",
        "b.json",
        "c.json",
    ]


def _manifest(folder, **extra):
    folder.mkdir(parents=True, exist_ok=True)
    body = {
        "fingerprint": "f",
        "shards": [1, 2],
        "counts": {"samples": 2},
        "runs": [],
        "updated": "t0",
        **extra,
    }
    (folder / "manifest.json").write_text(json.dumps(body))
    return {
        "path": str(folder),
        "manifest_sha256": hashlib.sha256((folder / "manifest.json").read_bytes()).hexdigest(),
    }


def test_same_dataset_accepts_a_resumed_copy_only(kfold, tmp_path):
    trained_on = _manifest(tmp_path / "orig")
    assert kfold.same_dataset(tmp_path / "orig", trained_on) is None
    _manifest(
        tmp_path / "copy", runs=[{"command": "again"}], updated="t1"
    )  # a datagen that found it complete
    assert kfold.same_dataset(tmp_path / "copy", trained_on) is None
    _manifest(tmp_path / "other", shards=[1, 3])
    assert "shards" in kfold.same_dataset(tmp_path / "other", trained_on)
    (tmp_path / "orig" / "manifest.json").write_text("{}")  # the folds' dataset changed since
    assert "changed" in kfold.same_dataset(tmp_path / "copy", trained_on)


def test_adopt_folds_refuses_another_k_and_links_the_right_one(kfold, tmp_path):
    trained_on = _manifest(tmp_path / "work" / "data")
    src = tmp_path / "folds_run"
    src.mkdir()
    (src / "folds.json").write_text(
        json.dumps({"folds": [{}, {}], "dataset": trained_on, "train": {"seed": 0}})
    )
    assert "2 folds, not 5" in kfold.adopt_folds(tmp_path / "work", src, 5)
    assert kfold.adopt_folds(tmp_path / "work", src, 2) is None
    assert (tmp_path / "work" / "folds").resolve() == src.resolve()
    step = json.loads((tmp_path / "work" / "steps" / "folds.json").read_text())
    assert step["exit_code"] == 0 and str(src) in step["command"]


def test_table_pairs_each_fold_design_with_the_best_preset_and_its_single_split(kfold):
    iv = lambda v: {"value": v, "low": v - 0.1, "high": v + 0.1, "n": 46}  # noqa: E731
    lab = kfold.label("joint_success")
    designs = {"soft": iv(0.5), "semi-rigid": iv(0.8), "paper-optimized": iv(0.7), lab: iv(0.75),
               "joint:joint_success/design.txt": iv(0.78)}  # fmt: skip
    paired = [{"a": lab, "b": b, "difference": iv(0.75 - designs[b]["value"])}
              for b in ("soft", "semi-rigid", "paper-optimized", "joint:joint_success/design.txt")]  # fmt: skip
    groups = {"kfold_groups_all": {"policy": "all", "impulse_paper_ns": 0.1,
                                   "groups": {"in-domain": {"objects": ["x"] * 46, "designs": designs, "paired": paired}}}}  # fmt: skip
    md = kfold.table_markdown(groups)
    row = next(line for line in md.splitlines() if line.startswith(f"| {lab}"))
    assert row == f"| {lab} | 75.0 [65.0, 85.0] | -5.0 [-15.0, +5.0] vs semi-rigid | -3.0 [-13.0, +7.0] |"
    assert "joint:joint_success/design.txt |" not in md  # the single split saw some of these objects
