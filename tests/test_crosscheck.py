"""The FEM behind the simulator interface, and the cross-simulator comparison as a library call."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError


def test_fem_backend_is_a_simulator_that_refuses_bad_input():
    # The FEM runs the grasp (tests/test_fem_grasp.py); what it refuses is typed: a scene or
    # scenario of the wrong type, and an observer (it has no MuJoCo states to replay)
    from mjcodesign.errors import MjcodesignError
    from mjcodesign.models.types import FingerModel
    from mjcodesign.objects import box_object
    from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene
    from mjcodesign.sim.fem import FemBackend
    from mjcodesign.sim.protocol import Simulator, get_backend

    backend = get_backend("fem")
    assert isinstance(backend, FemBackend)
    assert isinstance(backend, Simulator)
    assert backend.name == "fem"
    for method, args in [("run", ()), ("run_batch", ([],)), ("run_poses", ([],))]:
        with pytest.raises(MjcodesignError, match="runs a GraspScene, not NoneType") as info:
            getattr(backend, method)(None, GraspScenario(), *args)
        assert "\n" not in str(info.value)
    obj = box_object((0.05,) * 3, 100.0)
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("soft"), FingerModel.CHAIN, auto_pose(obj))
    with pytest.raises(MjcodesignError, match="runs a GraspScenario, not dict"):
        backend.run(scene, {"tension": 5})
    with pytest.raises(UnsupportedError, match="no MuJoCo states") as info:
        backend.run(scene, GraspScenario(), observer=object())
    assert "\n" not in str(info.value)
    assert (
        backend.run_batch(scene, GraspScenario(), []) == []
        and backend.run_poses(scene, GraspScenario(), []) == []
    )


def test_fem_results_are_frozen_records():
    from mjcodesign.sim.fem import FemCantilever, FemContactRun, FemCurl, FemPress

    for cls in (FemCantilever, FemCurl, FemPress, FemContactRun):
        assert dataclasses.is_dataclass(cls)
        assert cls.__dataclass_params__.frozen
    press = FemPress(0.02, 0.7, 0.75, 12, 1e-5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        press.total_force_n = 1.0
    assert dataclasses.asdict(press)["n_contacts"] == 12


def test_fem_backend_cantilever_matches_the_finger():
    pytest.importorskip("warp")
    from mjcodesign.sim.fem import FemBackend, FemCantilever, FemFinger, FemOptions

    options = FemOptions(h=4e-3, spine_layers=2)
    design, stiffness = FingerDesign(), Stiffness.preset("paper-optimized")
    r = FemBackend(options).cantilever(design, stiffness)
    assert isinstance(r, FemCantilever)
    direct = FemFinger(design, stiffness, options=options).cantilever()
    assert r.tip_deflection_m == direct.tip_deflection_m  # same mesh, same solve: bit for bit
    np.testing.assert_array_equal(r.positions, direct.positions)
    assert r.rel_error == pytest.approx(abs(r.tip_deflection_m - r.analytic_m) / r.analytic_m)


def test_crosscheck_rejects_unknown_names_before_simulating():
    from mjcodesign.crosscheck import crosscheck

    with pytest.raises(DesignError, match="unknown scenario"):
        crosscheck("twist", ["chain"], "paper-optimized")
    with pytest.raises(DesignError, match="unknown model"):
        crosscheck("curl", ["chain", "rigid"], "paper-optimized")


def test_crosscheck_cantilever_rows_without_the_fem():
    from mjcodesign.crosscheck import TOL_CROSS, crosscheck

    rows, curves = crosscheck("cantilever", ["chain"], "soft")
    assert curves == {}
    assert [r["model"] for r in rows] == ["chain"]
    r = rows[0]
    assert set(r) == {"scenario", "model", "design", "metric", "value", "reference", "rel_diff"}
    assert (r["scenario"], r["design"], r["metric"]) == ("cantilever", "soft", "tip_deflection_m")
    assert r["rel_diff"] == pytest.approx(abs(r["value"] - r["reference"]) / r["reference"])
    assert r["rel_diff"] < TOL_CROSS


def test_tensions_scale_with_the_design():
    from mjcodesign.crosscheck import default_tensions, press_tension

    soft = default_tensions(Stiffness.preset("soft"))
    assert soft == pytest.approx([0.02, 0.04, 0.08])
    assert press_tension(Stiffness.preset("soft")) == pytest.approx(0.04)
    assert press_tension(Stiffness.preset("paper-optimized")) == pytest.approx(0.2138, rel=1e-3)


def test_crosscheck_design_sweep_ends_with_a_summary_per_model():
    # `random:A..B`: every seed's rows in turn, then per model the worst and median |rel_diff| of them
    # (the parsing and the summary arithmetic alone: tests/test_landscape.py)
    from mjcodesign.crosscheck import crosscheck

    rows, curves = crosscheck("cantilever", ["chain"], "random:3..5")
    assert curves == {}
    per_design = [r for r in rows if not r["metric"].startswith("summary:")]
    assert [r["design"] for r in per_design] == ["random:3", "random:4", "random:5"]
    summary = {r["metric"]: r for r in rows if r["metric"].startswith("summary:")}
    assert set(summary) == {"summary:worst_rel_diff", "summary:median_rel_diff"}
    diffs = [r["rel_diff"] for r in per_design]
    assert summary["summary:worst_rel_diff"]["value"] == pytest.approx(max(diffs))
    assert summary["summary:median_rel_diff"]["value"] == pytest.approx(float(np.median(diffs)))
    assert all(r["design"] == "random:3..5" and r["model"] == "chain" for r in summary.values())


def test_crosscheck_cli_refuses_a_reversed_sweep(capsys):
    from mjcodesign.cli.main import main

    assert main(["crosscheck", "cantilever", "--models", "chain", "--design", "random:5..3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "below the first" in err[0]


_TOL_NATIVE_VS_POINT_RAD = 1e-4  # frictionless point forces equal the spatial tendon (tests/test_tendon.py)


def test_crosscheck_curl_runs_the_chain_the_grasps_run():
    # The curl comparison's chain is the grasps' (native tendon, the default constant lever), and
    # --tendon-lever path gives the spatial tendon's, which the point forces equal (tests/test_tendon.py).
    from mjcodesign.cli.crosscheck import _TENDON_LEVERS
    from mjcodesign.crosscheck.run import model_curl
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models.types import TENDON_LEVERS, SimOptions, TendonMode
    from mjcodesign.scenarios.static import curl

    assert _TENDON_LEVERS == TENDON_LEVERS
    design, s = FingerDesign(), Stiffness.parse("random:0")
    default = model_curl(design, s, "chain", 0.17)
    assert default["bend_angle_rad"] == curl(design, s, "chain", 0.17)["bend_angle_rad"]
    path = model_curl(design, s, "chain", 0.17, chain=SimOptions(tendon_lever="path"))
    point = curl(design, s, "chain", 0.17, tendon_mode=TendonMode.POINT_FORCE)
    assert path["bend_angle_rad"] == pytest.approx(point["bend_angle_rad"], abs=_TOL_NATIVE_VS_POINT_RAD)
    assert default["bend_angle_rad"] > 1.1 * path["bend_angle_rad"]  # 1.25 against 1.05 rad (FEM 1.30)


def test_grasp_study_case_selection():
    from mjcodesign.cli.crosscheck import select_cases
    from mjcodesign.crosscheck import GRASP_CASES

    assert select_cases(GRASP_CASES, "3") == GRASP_CASES[:3]
    assert select_cases(GRASP_CASES, "12:24") == GRASP_CASES[12:]
    assert select_cases(GRASP_CASES, "20,2") == (GRASP_CASES[20], GRASP_CASES[2])
    for bad in ("x", "1,99", "5:5", "-1,2", "1:b"):
        with pytest.raises(DesignError):
            select_cases(GRASP_CASES, bad)


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--cases", "1,99"], "--cases indices"),
        (["--cases", "two"], "--cases takes"),
        (["--fem-contact-ke", "-5"], "--fem-contact-ke"),
        (["--tendon-lever", "path"], "unrecognized arguments: --tendon-lever"),
        (["--hinges-per-block", "2"], "unrecognized arguments: --hinges-per-block"),
        (["--fem-order", "2"], "unrecognized arguments: --fem-order"),  # the grasp's tets are linear
        (["--routing", "straight"], "argument --routing: invalid choice"),
        (["--routing", "printed", "--fem-tendon-law", "paper"], "frictionless tendon law only"),
        (["--routing", "printed", "--authors-case"], "--routing printed: the authors' case"),
    ],
)
def test_grasp_study_cli_refuses_bad_selection_before_simulating(capsys, argv, says):
    from mjcodesign.cli.main import main

    try:
        code = main(["crosscheck", "grasp", "--models", "chain,fem", *argv])
    except SystemExit as exc:  # argparse's own refusal
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err


_AUTHORS_POSES = Path(__file__).resolve().parents[2] / "shared/reference/codesign-soft-gripper/pose_info"


@pytest.mark.skipif(not _AUTHORS_POSES.is_dir(), reason="the authors' reference data is not on this machine")
def test_authors_case_starts_at_the_refined_openings_or_sweeps_in():
    from mjcodesign.crosscheck.authors_case import AUTHORS_RESULT, authors_case

    pose_file = _AUTHORS_POSES / "006_mustard_bottle.npz"
    refined = authors_case(("chain",), pose_file=pose_file, start="refined")
    sweep = authors_case(("chain",), pose_file=pose_file, start="sweep")
    assert [r["log_e"] for r in refined] == list(AUTHORS_RESULT)
    for a, b in zip(refined, sweep, strict=True):
        assert a["start"] == "refined" and b["start"] == "sweep" and a["openings"] == b["openings"]
        assert a["chain"]["class"] in ("lifts", "slips", "no contact")
        assert np.all(np.isfinite(a["chain"]["displacement"]))
    # Starting at the refined openings changes the rollout (the carriages no longer sweep in)
    assert any(
        a["chain"]["displacement"] != b["chain"]["displacement"] for a, b in zip(refined, sweep, strict=True)
    )
    with pytest.raises(DesignError, match="unknown start"):
        authors_case(("chain",), pose_file=pose_file, start="nowhere")


# Every flag of the single crosscheck parser before it had a subcommand per scenario (less --scenario,
# now the deprecated alias, and --authors-row, retired): each is still taken by some scenario.
_FLAT_FLAGS = """--models --design --tensions --plot --cases --short --out --fem-h-flexure --hinges-per-block
--tendon-lever --authors-case --authors-start --fem-dt --fem-locking-correction --fem-tendon-law
--fem-contact-ke --fem-contact-damping-ratio --fem-h --fem-layers --fem-order --rrd --spawn --viewer-port
--json""".split()


def _scenario_flags() -> dict[str, set[str]]:
    import argparse

    from mjcodesign.cli.main import build_parser

    def subs(parser):
        return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices

    crosscheck = subs(build_parser())["crosscheck"]
    return {
        name: {o for a in sub._actions for o in a.option_strings if o.startswith("--") and o != "--help"}
        for name, sub in subs(crosscheck).items()
    }


def test_each_scenario_takes_only_its_own_flags():
    from mjcodesign.cli.crosscheck import _SCENARIO_HELP
    from mjcodesign.crosscheck import SCENARIOS

    assert tuple(_SCENARIO_HELP) == (*SCENARIOS, "grasp")
    flags = _scenario_flags()
    assert set(flags) == set(_SCENARIO_HELP)
    assert sorted(set(_FLAT_FLAGS) - set().union(*flags.values())) == []
    grasp_only = {"--cases", "--short", "--out", "--authors-case", "--authors-start", "--fem-tendon-law"}
    grasp_only |= {"--authors-poses"}
    grasp_only |= {"--fem-locking-correction", "--fem-dt", "--fem-h-flexure", "--fem-contact-ke"}
    assert grasp_only <= flags["grasp"]
    assert not grasp_only & (flags["cantilever"] | flags["curl"] | flags["press"])
    assert {"--tendon-lever", "--plot"} <= flags["curl"]
    assert not {"--tendon-lever", "--plot", "--tensions"} & flags["cantilever"]
    assert "--hinges-per-block" in flags["cantilever"] and "--hinges-per-block" not in flags["press"]
    assert not {"--design", "--rrd", "--fem-order", "--hinges-per-block", "--plot"} & flags["grasp"]
    assert "--authors-row" not in set().union(*flags.values())


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["crosscheck", "curl", "--models", "chain", "--fem-locking-correction"], "--fem-locking-correction"),
        (["crosscheck", "--scenario", "curl", "--fem-tendon-law", "paper"], "--fem-tendon-law"),
        (["crosscheck", "--scenario", "grasp", "--authors-case", "--authors-row", "1"], "--authors-row"),
        (["crosscheck"], "needs a scenario"),
        (["crosscheck", "--scenario", "bend"], "choose from cantilever, curl, press, grasp, got 'bend'"),
        (["crosscheck", "grasp", "--models", "flex"], "unknown model"),
    ],
)
def test_a_flag_of_another_scenario_is_refused_in_one_line(capsys, argv, says):
    from mjcodesign.cli.main import main

    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own refusal
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and "deprecated" not in err[0], err


def test_the_scenario_flag_is_a_deprecated_alias_of_the_subcommand(capsys):
    import json

    from mjcodesign.cli.main import main

    rest = ["--models", "chain", "--design", "soft", "--json"]
    assert main(["crosscheck", "cantilever", *rest]) == 0
    new = capsys.readouterr()
    assert main(["crosscheck", "--scenario", "cantilever", *rest]) == 0
    old = capsys.readouterr()
    assert json.loads(old.out) == json.loads(new.out) and json.loads(new.out)
    assert "deprecated" not in new.err
    notes = [line for line in old.err.splitlines() if "deprecated" in line]
    assert notes == ["note: 'crosscheck --scenario cantilever' is deprecated; run 'crosscheck cantilever'"]


def test_chain_margin_moves_the_palm_a_millimetre_each_way():
    from mjcodesign.crosscheck.grasp import MARGIN_SHIFT, chain_margin
    from mjcodesign.models.types import FingerModel
    from mjcodesign.objects import box_object
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene
    from mjcodesign.sim.mujoco_c import MujocoBackend

    obj = box_object((0.04, 0.04, 0.06), 100.0)
    design = FingerDesign()
    scene = build_scene(
        obj, design, Stiffness.preset("semi-rigid"), FingerModel.CHAIN, auto_pose(obj, design)
    )
    phases = dict(settle_s=0.004, close_s=0.03, tighten_s=0.05, lift_s=0.05, hold_s=0.03, post_hold_s=0.01)
    scenario = GraspScenario(**phases, tendon=TendonForce(tension=4.0), lift=0.01)
    nominal = MujocoBackend(nthread=1).run(scene, scenario)
    # Unmoved, the six rollouts are the nominal one (deterministic, and the scene is rebuilt faithfully).
    still = chain_margin(scene, scenario, shift=0.0)
    assert still["same"] == still["of"] == 6 and still["success"] == bool(nominal.success)
    assert still["rises_m"] == [nominal.lift_height] * 6
    moved = chain_margin(scene, scenario)
    assert moved["shift_m"] == MARGIN_SHIFT and moved["of"] == 6 and 0 <= moved["same"] <= 6
    assert len(set(moved["rises_m"])) > 1  # the palm did move: the six rollouts differ


def test_grasp_study_runs_at_the_tension_given(capsys, tmp_path, monkeypatch):
    """``crosscheck grasp --tensions T``: every case's rollouts run at T (the CI version's phases kept)."""
    import dataclasses
    import json

    from mjcodesign.cli.main import main
    from mjcodesign.crosscheck import grasp_study, short_settings
    from mjcodesign.scenarios.drive import TendonForce

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    argv = ["crosscheck", "grasp", "--short", "--models", "chain", "--json"]
    assert main([*argv, "--tensions", "2"]) == 0
    at_2 = json.loads(capsys.readouterr().out)["cases"]
    assert main(argv) == 0
    at_4 = json.loads(capsys.readouterr().out)["cases"]
    assert [c["tension"] for c in at_2] == [2.0, 2.0] and [c["tension"] for c in at_4] == [4.0, 4.0]
    settings = short_settings()
    settings["scenario"] = dataclasses.replace(settings["scenario"], tendon=TendonForce(tension=2.0))
    direct, _ = grasp_study(models=("chain",), cache_dir=tmp_path / "mjcodesign", **settings)
    for cli, lib, four in zip(at_2, direct, at_4, strict=True):
        assert cli["chain"]["body_force"] == list(lib["chain"]["body_force"])  # the same rollout
        assert cli["chain"]["body_force"] != four["chain"]["body_force"]  # and the tension reached it


def test_grasp_study_routing_reaches_both_simulators(capsys, tmp_path, monkeypatch):
    """``crosscheck grasp --routing printed``: the chain's and the FEM's routing, recorded in every case."""
    import json

    import mjcodesign.crosscheck.grasp as study
    from mjcodesign.cli.crosscheck import _ROUTINGS
    from mjcodesign.cli.main import main
    from mjcodesign.crosscheck import grasp_study, short_settings
    from mjcodesign.models.types import ROUTINGS
    from mjcodesign.sim.fem import FemOptions

    assert _ROUTINGS == ROUTINGS
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    seen = []
    runners = study.model_runners

    def spy(models, fem_options=None, fem_dynamics=None):
        seen.append(fem_options)
        return runners(models, fem_options, fem_dynamics)

    monkeypatch.setattr(study, "model_runners", spy)
    argv = ["crosscheck", "grasp", "--short", "--models", "chain", "--json"]
    assert main([*argv, "--routing", "printed"]) == 0
    printed = json.loads(capsys.readouterr().out)["cases"]
    assert main(argv) == 0
    guided = json.loads(capsys.readouterr().out)["cases"]
    assert [c["routing"] for c in printed + guided] == ["printed"] * 2 + ["guided"] * 2
    assert [o.routing for o in seen] == ["printed", "guided"]  # the FEM's options (the CI mesh) follow it
    for p, g in zip(printed, guided, strict=True):
        assert p["chain"]["body_force"] != g["chain"]["body_force"]  # the chain ran the printed tendon
    cases = short_settings()["cases"]
    with pytest.raises(DesignError, match="printed routing on both sides"):
        grasp_study(models=("chain",), routing="printed", fem_options=FemOptions(), cases=cases)
