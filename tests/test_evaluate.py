"""Evaluation on a frozen suite (``mjcodesign evaluate``): every rollout under common random numbers,
success from the simulator, intervals recomputable from the rows, identical reruns, bad input refused.

A small suite: an in-domain YCB strawberry and an out-of-domain egad-like shape, two poses each.
"""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from mjcodesign.design.stiffness import Stiffness, read_design_file, write_design_file
from mjcodesign.errors import DesignError, StiffnessError
from mjcodesign.evaluation import (
    SuiteError,
    SuiteRun,
    analyse,
    build_suite,
    load_suite,
    parse_design_groups,
    record_suite_examples,
    run_suite,
    select_policy,
)
from mjcodesign.jobs import GraspJob, run_jobs
from mjcodesign.outputs import MARKER
from mjcodesign.scenarios.grasp import GraspScenario, paper_impulse
from mjcodesign.scenarios.perturb import Perturbation
from mjcodesign.sim.protocol import get_backend

_OBJECTS = ("012_strawberry", "egad-like:1")
_SHORT = GraspScenario(tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.05)
_DEFAULT_V1_SHA256 = "c9b61bd0f989bc323a09b153dc0af4bd3eaf5c04cfa21502bd914bdb2a86c73a"
_FILES = {"results.json", "summary.json", "table.md", "paired.md", "per_object.csv", "forest.png", MARKER}


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli.main", "evaluate", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )


def test_design_file_round_trip(tmp_path):
    d = Stiffness.random(3)
    p = write_design_file(tmp_path / "d.json", d, note="x")
    assert read_design_file(p) == d
    (tmp_path / "d.txt").write_text(",".join(str(v) for v in d.as_list()))
    assert read_design_file(tmp_path / "d.txt") == d
    (tmp_path / "bad.json").write_text('{"other": 1}')
    with pytest.raises(StiffnessError):
        read_design_file(tmp_path / "bad.json")
    with pytest.raises(StiffnessError):
        read_design_file(tmp_path / "missing.json")


@pytest.fixture(scope="module")
def suite_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("suite") / "suite.json"
    build_suite(_OBJECTS, poses_per_object=2, seed=0).save(path)
    return path


@pytest.fixture(scope="module")
def suite(suite_file):
    return load_suite(suite_file)


@pytest.fixture(scope="module")
def evaluated(suite, tmp_path_factory):
    root = tmp_path_factory.mktemp("designs")
    write_design_file(root / "joint.json", Stiffness.preset("paper-optimized"))
    (root / "ind").mkdir()
    write_design_file(root / "ind" / "012_strawberry.json", Stiffness.random(7))
    groups = parse_design_groups(f"soft,joint:{root / 'joint.json'},individual:{root / 'ind'}")
    run = SuiteRun(
        designs=groups,
        perturbations=2,
        impulses=(0.1, 0.4),
        pose_policies=("fixed", "oracle"),
        scenario=_SHORT,
    )
    return run, run_suite(suite, run)


def test_rows_cover_every_rollout_with_shared_draws(suite, evaluated):
    run, result = evaluated
    rows = result["rows"]
    keys = {(r["object"], r["impulse_paper_ns"], r["pose"], r["draw"], r["design"]) for r in rows}
    assert len(keys) == len(rows)
    for so in suite.objects:
        n_design = 3 if so.domain == "in-domain" else 2  # the individual design only on its object
        mine = [r for r in rows if r["object"] == so.name]
        assert len(mine) == len(so.poses) * 2 * 2 * n_design
    # Common random numbers: one draw per (object, pose, draw index), whatever the design or disturbance.
    draws: dict[tuple, dict] = {}
    for r in rows:
        assert draws.setdefault((r["object"], r["pose"], r["draw"]), r["perturbation"]) == r["perturbation"]
    assert len({json.dumps(p, sort_keys=True) for p in draws.values()}) == len(draws)  # all distinct
    assert all(np.isfinite(r["hold_force_n"]) and np.isfinite(r["slip_m"]) for r in rows)


def test_success_comes_from_the_simulator(suite, evaluated):
    run, result = evaluated
    from mjcodesign.jobs import load_grasp_object

    so = suite.objects[0]
    obj = load_grasp_object(so.source, "light")
    for r in [x for x in result["rows"] if x["object"] == so.name][:4]:
        g = next(g for g in run.designs if g.label == r["design"])
        scenario = GraspScenario(**{**_SHORT.__dict__, "impulse": paper_impulse(r["impulse_paper_ns"])})
        job = GraspJob(
            obj=obj,
            pose=so.poses[r["pose"]],
            design=g.for_object(so.name),
            scenario=scenario,
            density=r["density_kg_m3"],
            perturbation=Perturbation(**r["perturbation"]),
        )
        out = run_jobs([job], get_backend("mujoco"))[0]
        assert out.success == r["success"] and list(out.body_force) == r["body_force"]


def test_larger_impulse_never_helps(evaluated):
    _, result = evaluated
    by = {(r["object"], r["pose"], r["draw"], r["design"], r["impulse_paper_ns"]): r for r in result["rows"]}
    for (o, k, j, d, imp), r in by.items():
        if imp == 0.4 and not r["sample_error"]:
            small = by[(o, k, j, d, 0.1)]
            assert small["success"] or not r["success"], (o, k, j, d)


def test_intervals_are_recomputable_from_the_rows(suite, evaluated):
    run, result = evaluated
    labels = [g.label for g in run.designs]
    summary = analyse(result, labels, ["fixed", "oracle"])
    reg = next(r for r in summary["regimes"] if r["impulse_paper_ns"] == 0.1)
    fixed = [
        r for r in result["rows"] if r["impulse_paper_ns"] == 0.1 and r["pose"] == 0 and not r["sample_error"]
    ]
    for d in ("soft", labels[1]):
        for split, obj in ((o.domain, o.name) for o in suite.objects):
            mine = [r["success"] for r in fixed if r["design"] == d and r["object"] == obj]
            assert reg["policies"]["fixed"]["designs"][d][split]["value"] == pytest.approx(np.mean(mine))
    # The oracle's pose is each (object, design)'s best pose: never below the fixed pose.
    for d in labels:
        for split in ("in-domain", "out-of-domain"):
            f, o = (reg["policies"][p]["designs"][d][split] for p in ("fixed", "oracle"))
            if f is not None:
                assert o["value"] >= f["value"]


def test_planted_failure_is_found_at_its_size(evaluated):
    """A design that fails every rollout on a fixed object, else identical: the difference is that object's."""
    _, result = evaluated
    soft = [r for r in result["rows"] if r["design"] == "soft" and r["impulse_paper_ns"] == 0.1]
    planted = [
        dict(r, design="planted", success=False if r["object"] == "012_strawberry" else r["success"])
        for r in soft
    ]
    summary = analyse({"rows": soft + planted, "surrogate_choice": {}}, ["planted", "soft"], [])
    pair = next(p for p in summary["regimes"][0]["policies"]["all"]["paired"] if p["split"] == "in-domain")
    valid = [r["success"] for r in soft if r["object"] == "012_strawberry" and not r["sample_error"]]
    assert pair["difference"]["value"] == pytest.approx(-np.mean(valid))
    out = next(p for p in summary["regimes"][0]["policies"]["all"]["paired"] if p["split"] == "out-of-domain")
    assert out["difference"]["value"] == 0.0 and out["wins"] == out["losses"] == 0


def test_same_suite_and_seed_give_identical_rows(suite_file, evaluated):
    run, result = evaluated
    assert run_suite(load_suite(suite_file), run)["rows"] == result["rows"]


def test_oracle_picks_the_best_pose_then_the_first():
    rows = [
        {
            "density": "light",
            "impulse_paper_ns": 0.1,
            "design": "d",
            "object": "o",
            "pose": k,
            "draw": j,
            "success": s,
            "sample_error": False,
        }
        for k, outcomes in enumerate([(True, False), (True, True), (True, True)])
        for j, s in enumerate(outcomes)
    ]
    assert {r["pose"] for r in select_policy(rows, "oracle")} == {1}
    assert {r["pose"] for r in select_policy(rows, "fixed")} == {0}


def test_cli_writes_the_report_and_reruns_bitwise(tmp_path, suite_file):
    a, b = tmp_path / "a", tmp_path / "b"
    # The paper's regime: its own column of Table 1 stands beside ours only there.
    args = ("--suite", str(suite_file), "--designs", "soft,semi-rigid", "--perturbations", "2", "--json")
    args += ("--regime", "paper")
    p = _cli(*args, "--out", str(a), "--rrd", str(tmp_path / "ex.rrd"), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert {f.name for f in a.iterdir()} == _FILES
    assert summary["suite"]["digest"] == load_suite(suite_file).digest
    assert summary["recorded"] and (tmp_path / "ex.rrd").stat().st_size > 0
    table = (a / "table.md").read_text()
    assert "69.6" in table  # the paper's own soft figure, in its own column
    assert "| paper, in-domain (their Table 1) |" in table
    q = _cli(*args, "--out", str(b), cwd=tmp_path)
    assert q.returncode == 0, q.stderr
    assert (a / "results.json").read_bytes() == (b / "results.json").read_bytes()
    assert "evaluate: rollouts by object 2/2" in q.stderr  # one plain line per object in a log


_LIFT_CHANGE_M = 1e-3  # a lift margin that moves by over 1 mm came from another tendon drive


def test_tendon_drive_reaches_the_rollouts(tmp_path, suite_file, monkeypatch, capsys):
    from mjcodesign.cli.main import main

    monkeypatch.chdir(tmp_path)
    base = ["evaluate", "--suite", str(suite_file), "--designs", "soft", "--perturbations", "1"]
    base += ["--pose-sampling", "fixed", "--json"]
    runs = {}
    for tendon in ("force:10", "position:1000"):
        out = tmp_path / tendon.replace(":", "_")
        assert main([*base, "--tendon", tendon, "--out", str(out)]) == 0
        summary = json.loads(capsys.readouterr().out)
        results = json.loads((out / "results.json").read_text())
        assert summary["tendon"] == results["run"]["tendon"] == tendon
        runs[tendon] = {(r["object"], r["pose"]): r for r in results["rows"]}
    force, position = runs["force:10"], runs["position:1000"]
    assert force.keys() == position.keys()
    # The same draws under the two drives: the servo's pull changes how the objects rise.
    moved = [
        k for k in force if abs(force[k]["lift_margin_m"] - position[k]["lift_margin_m"]) > _LIFT_CHANGE_M
    ]
    assert moved, {k: (force[k]["lift_margin_m"], position[k]["lift_margin_m"]) for k in force}
    assert main([*base, "--out", str(tmp_path / "default")]) == 0  # no --tendon: the regime's own
    default = json.loads(capsys.readouterr().out)
    assert default["tendon"] == "position:1000" and default["regime"] == "real"
    assert main([*base, "--regime", "paper", "--out", str(tmp_path / "paper")]) == 0
    paper = json.loads(capsys.readouterr().out)
    assert paper["tendon"] == "force:10" and paper["regime"] == "paper"
    assert main([*base, "--tendon", "force:10", "--out", str(tmp_path / "mixed")]) == 0
    assert json.loads(capsys.readouterr().out)["regime"] == "custom"


@pytest.mark.parametrize(
    "args",
    [
        ("--designs", "soft,nope"),
        ("--designs", "joint:BADLEN"),
        ("--designs", "soft,soft"),
        ("--density", "medium"),
        ("--pose-sampling", "psychic"),
        ("--impulse", "nan"),
        ("--perturbations", "0"),
        ("--suite", "VERSION99"),
        ("--suite", "/nonexistent/suite.json"),
        ("--suite", "default", "--objects", "012_strawberry"),
        ("--quick", "--objects", "012_strawberry"),
        ("--objects", "no_such_object"),
        ("--candidates", "0"),
        ("--anygrasp", "/nonexistent"),
        ("--rrd", "/nonexistent/x.rrd"),
        ("--mass", "real"),  # the quick suite's egad-like shapes have no published mass
        ("--objects", "012_strawberry", "--mass", "real", "--density", "heavy"),
        ("--objects", "MESH", "--mass", "real"),
        ("--egad-like", "-1"),
        ("--tendon", "position:abc"),
        ("--tendon", "torque:3"),
        ("--friction", "slippery"),
        ("--routing", "under"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, args, monkeypatch, capsys):
    from mjcodesign.cli.main import main

    monkeypatch.chdir(tmp_path)
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    (inputs / "short.txt").write_text("14.0,15.0,16.0")
    (inputs / "v99.json").write_text(json.dumps({"format": "mjcodesign-eval-suite", "version": 99}))
    (inputs / "box.stl").write_bytes(trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(file_type="stl"))
    args = tuple(
        a.replace("BADLEN", str(inputs / "short.txt"))
        .replace("VERSION99", str(inputs / "v99.json"))
        .replace("MESH", str(inputs / "box.stl"))
        for a in args
    )
    out = tmp_path / "out"
    argv = ["evaluate", "--quick", *args, "--out", str(out)]
    if "--suite" in args or "--objects" in args:
        argv.remove("--quick")
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's refusals
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["inputs"], list(tmp_path.iterdir())


def test_suite_file_round_trip_and_refusals(suite_file, tmp_path):
    built = build_suite(_OBJECTS[:1], poses_per_object=2, seed=0)
    again = load_suite(built.save(tmp_path / "s.json") and tmp_path / "s.json")
    assert [o.poses for o in again.objects] == [o.poses for o in built.objects]
    assert again.perturbation == built.perturbation and again.digest == built.digest
    bad = json.loads(Path(suite_file).read_text())
    bad["objects"][0]["poses"][0]["quat"] = [2.0, 0.0, 0.0, 0.0]
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(SuiteError):
        load_suite(tmp_path / "bad.json")
    with pytest.raises(DesignError):
        SuiteRun(designs=parse_design_groups("soft"), perturbations=0)


def test_recorded_examples_are_the_best_and_worst_per_design(suite, evaluated):
    run, result = evaluated

    class Seen:
        def __init__(self):
            self.labels = []

        def rollout(self, r):
            self.labels.append(r.label)

        def snapshot(self, s):
            pass

        def close(self):
            pass

    seen = Seen()
    labels = record_suite_examples(suite, run, result["rows"], seen, per_design=1)
    assert sorted(seen.labels) == sorted(labels)
    first = [r for r in result["rows"] if r["impulse_paper_ns"] == 0.1 and not r["sample_error"]]
    for g in run.designs:
        mine = [r for r in first if r["design"] == g.label]
        tags = {lab[len(g.label) + 1 :].split("/")[0] for lab in labels if lab.startswith(g.label + "/")}
        assert ("best" in tags) == any(r["success"] for r in mine)
        assert ("worst" in tags) == (not all(r["success"] for r in mine))


def test_surrogate_policy_takes_the_best_predicted_pose(tiny_checkpoint, suite):
    from mjcodesign.evaluation import ObjectCandidates, predict_candidates
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.surrogate import load_surrogate

    sur = load_surrogate(tiny_checkpoint)
    run = SuiteRun(
        designs=parse_design_groups("soft,semi-rigid"),
        perturbations=1,
        pose_policies=("fixed", "surrogate"),
        scenario=_SHORT,
    )
    result = run_suite(suite, run, surrogate=sur, n_points=256)
    for so in suite.objects:
        obj = load_grasp_object(so.source, "light")
        c = ObjectCandidates(
            obj, so.poses, np.stack([p.matrix() for p in so.poses]), so.pose_source, np.arange(len(so.poses))
        ).with_clouds(256, 0)
        for g in run.designs:
            scores, _ = predict_candidates(sur, c, g.design, 100.0)
            best = int(c.source_index[int(np.argmax(scores))])
            assert result["surrogate_choice"][so.name]["light"][g.label]["pose"] == best
    picked = select_policy(result["rows"], "surrogate", result["surrogate_choice"])
    assert {(r["object"], r["design"]) for r in picked} == {
        (o.name, g.label) for o in suite.objects for g in run.designs
    }


def test_anygrasp_fixed_pose_is_the_authors_first_surviving_row(reference_dir):
    from mjcodesign.evaluation import object_candidates
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.objects import load_mesh
    from mjcodesign.poses import import_anygrasp, load_external

    obj = load_grasp_object("012_strawberry", "light")
    path = reference_dir / "pose_info" / "012_strawberry.npz"
    c = object_candidates(obj, 3, anygrasp=reference_dir / "pose_info")
    assert c.source == path.name
    every = import_anygrasp(obj, load_external(path), load_mesh("012_strawberry").vertices, source=path.name)
    assert list(c.source_index) == sorted(every.source_index)[:3]  # the authors' order, not the ranking


def test_the_shipped_default_suite():
    from mjcodesign.objects import YCB_IN_DOMAIN

    s = load_suite("default")
    inside = [o for o in s.objects if o.domain == "in-domain"]
    assert sorted(o.name for o in inside) == sorted(YCB_IN_DOMAIN)
    assert sorted({o.fold for o in inside}) == list(range(s.folds))  # every in-domain object in a fold
    assert all(o.fold is None for o in s.objects if o.domain == "out-of-domain")
    short = [o for o in s.objects if len(o.poses) < s.poses_per_object]
    assert s.poses_per_object == 10 and all(o.note for o in short)  # fewer poses only with the reason
    assert s.digest == _DEFAULT_V1_SHA256  # frozen: its recorded results name this file


def test_real_mass_runs_each_object_at_its_published_mass(suite):
    from dataclasses import replace

    from mjcodesign.errors import MeshError
    from mjcodesign.jobs import load_grasp_object

    ycb = replace(suite, objects=tuple(o for o in suite.objects if o.domain == "in-domain"))
    run = SuiteRun(designs=parse_design_groups("soft"), perturbations=1, mass="real", scenario=_SHORT)
    rows = run_suite(ycb, run)["rows"]
    real = load_grasp_object(ycb.objects[0].source, mass="real")
    assert rows and all(r["density"] == "real" for r in rows)
    assert all(r["density_kg_m3"] == pytest.approx(real.density, rel=1e-9) for r in rows)
    with pytest.raises(MeshError, match="egad-like"):
        run_suite(suite, run)  # refused before any rollout: the egad-like shape has no published mass
    with pytest.raises(DesignError):
        SuiteRun(designs=parse_design_groups("soft"), mass="measured")


def test_egad_like_objects_join_the_out_of_domain_split(suite):
    from mjcodesign.evaluation.suite import add_objects, egad_sources

    assert egad_sources(3, ["013_apple", "egad-like:9", "egad-like:2"]) == tuple(
        f"egad-like:{i}" for i in (10, 11, 12)
    )
    assert egad_sources(2) == ("egad-like:0", "egad-like:1") and egad_sources(0) == ()
    more = add_objects(suite, egad_sources(1, [o.source for o in suite.objects]), label="egad-like:1")
    assert more.name == f"{suite.name}+egad-like:1" and more.objects[: len(suite.objects)] == suite.objects
    new = more.objects[-1]
    assert new.source == "egad-like:2" and new.domain == "out-of-domain" and new.fold is None and new.poses
    assert more.digest and more.digest != suite.digest
    with pytest.raises(SuiteError, match="already holds"):
        add_objects(suite, [suite.objects[0].source], label="again")


def test_objects_take_mesh_files_and_folders(tmp_path):
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(meshes / "box.stl")
    trimesh.creation.icosphere(radius=0.03).export(tmp_path / "ball.stl")
    p = _cli("--objects", f"{meshes},{tmp_path / 'ball.stl'}", "--poses-per-object", "1", "--perturbations", "1",
             "--designs", "soft", "--egad-like", "1", "--save-suite", str(tmp_path / "s.json"), "--out",
             str(tmp_path / "out"), "--json", cwd=tmp_path)  # fmt: skip
    assert p.returncode == 0, p.stderr
    s = load_suite(tmp_path / "s.json")
    assert [(o.name, o.source, o.domain) for o in s.objects] == [
        ("box", str(meshes / "box.stl"), "out-of-domain"),
        ("ball", str(tmp_path / "ball.stl"), "out-of-domain"),
        ("egad-like-0-000", "egad-like:0", "out-of-domain"),
    ]
    rows = json.loads((tmp_path / "out" / "results.json").read_text())["rows"]
    assert {r["object"] for r in rows} == {"box", "ball", "egad-like-0-000"}


def test_bench_evaluate_times_the_same_rollouts():
    from mjcodesign.bench import run_benchmark

    res = run_benchmark(
        "evaluate",
        objects=("egad-like:1",),
        poses_per_object=1,
        perturbations=2,
        designs="soft,semi-rigid",
        repeats=1,
    )
    assert res["rollouts"] == res["raw_rollouts"] == 4
    assert len(res["pipeline_vs_raw"]) == 1 and 0 < res["pipeline_vs_raw"][0] < 2
    assert res["provenance"]["benchmark"] == "evaluate"


def test_routing_reaches_every_rollout(suite):
    from mjcodesign.evaluation.rollouts import object_jobs, prepare_object
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.models.types import SimOptions

    so = suite.objects[0]
    obj = load_grasp_object(so.source, "light", seed=suite.seed)
    runs = {
        r: SuiteRun(
            designs=parse_design_groups("soft"),
            perturbations=1,
            scenario=_SHORT,
            options=None if r == "guided" else SimOptions(routing=r),
        )
        for r in ("guided", "printed")
    }
    hold = {}
    for r, run in runs.items():
        prep = prepare_object(suite, run, so, obj, [("light", 100.0)])
        jobs, _ = object_jobs(prep, so, run, run.designs)
        assert jobs and all((j.options or SimOptions()).routing == r for j in jobs)
        hold[r] = [o.body_force for o in run_jobs(jobs[:1], get_backend("mujoco"))]
    assert not np.allclose(hold["guided"], hold["printed"])  # a soft finger under the printed path differs


@pytest.mark.parametrize("friction, expected", [(None, 1.0), ("tape-min", 0.6), ("0.8", 0.8)])
def test_friction_and_routing_reach_the_run(friction, expected):
    from mjcodesign.cli import evaluate as cli_evaluate
    from mjcodesign.cli.main import build_parser

    argv = ["evaluate", "--out", "o", "--routing", "printed"] + (
        [] if friction is None else ["--friction", friction]
    )
    run = cli_evaluate._run_config(build_parser().parse_args(argv))
    assert run.scenario.friction == expected and run.options.routing == "printed"


def test_each_accepted_draw_is_built_once(suite, monkeypatch):
    """The scene a draw's start check built is the one rolled out: ``run_jobs`` builds none again
    (with one disturbance; a second disturbance is another compiled scene and builds its own)."""
    import mjcodesign.jobs as jobs_module

    built = []
    real = jobs_module.perturbed_scene
    monkeypatch.setattr(jobs_module, "perturbed_scene", lambda *a, **k: built.append(1) or real(*a, **k))
    run = SuiteRun(designs=parse_design_groups("soft,semi-rigid"), perturbations=2, scenario=_SHORT)
    rows = run_suite(suite, run)["rows"]
    assert rows and built == []
    run2 = dataclasses.replace(run, impulses=(0.1, 0.4))
    rows2 = run_suite(suite, run2)["rows"]
    draws = {(r["object"], r["pose"], r["draw"]) for r in rows2 if r["impulse_paper_ns"] == 0.4}
    assert len(built) == len(draws)
    assert [r for r in rows2 if r["impulse_paper_ns"] == 0.1] == rows


def test_draw_scenes_are_kept_only_where_a_rollout_takes_them(suite):
    """The oracle prepares every object before rolling any out and keeps no draw's scene; a run whose
    disturbances all compile other scenes keeps none either (they would never be taken)."""
    from mjcodesign.evaluation.rollouts import prepare_object
    from mjcodesign.jobs import load_grasp_object

    so = suite.objects[0]
    obj = load_grasp_object(so.source, "light", seed=suite.seed)
    run = SuiteRun(designs=parse_design_groups("soft"), perturbations=2, scenario=_SHORT)
    dens = [("light", 100.0)]
    assert len(prepare_object(suite, run, so, obj, dens).scenes._perturbed) == 2 * len(so.poses)
    assert len(prepare_object(suite, run, so, obj, dens, keep_scenes=False).scenes._perturbed) == 0
    other = dataclasses.replace(run, impulses=(0.4,))
    assert len(prepare_object(suite, other, so, obj, dens).scenes._perturbed) == 0


def test_the_object_ahead_hands_its_error_to_the_caller():
    from mjcodesign.evaluation.rollouts import _Ahead

    def boom(x):
        raise KeyError(x)

    with pytest.raises(KeyError, match="q"):
        _Ahead(boom, "q").result()
    assert _Ahead(lambda x: x + 1, 1).result() == 2


def test_rows_equal_one_object_at_a_time(suite, evaluated):
    """``run_suite`` (the next object prepared on its own thread, chunks pipelined) gives the rows of the
    plain loop: each object prepared, its jobs run in one ``run_jobs`` call on a backend without
    ``run_scene_chunks``, one after another."""
    from mjcodesign.evaluation.rollouts import object_jobs, outcome_rows, prepare_object
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.objects import parse_density

    run, result = evaluated
    backend = get_backend("mujoco")

    class Plain:  # run_scenes only: one rollout call per chunk of up to 256 scenes, nothing overlapped
        name = "plain"

        def run(self, *a, **k):
            return backend.run(*a, **k)

        def run_scenes(self, *a, **k):
            return backend.run_scenes(*a, **k)

    rows = []
    dens = [(str(d), parse_density(d)) for d in run.densities]
    for so in suite.objects:
        obj = load_grasp_object(so.source, "light", seed=suite.seed)
        prep = prepare_object(suite, run, so, obj, dens, keep_scenes=False)
        jobs, meta = object_jobs(prep, so, run, run.designs)
        rows += outcome_rows(so, meta, run_jobs(jobs, Plain(), scenes=prep.scenes))
    assert json.dumps(rows, sort_keys=True) == json.dumps(result["rows"], sort_keys=True)
