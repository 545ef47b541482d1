"""The real regime as every command's default: the regimes, the mass rule, what the outputs name."""

import json

import numpy as np
import pytest

from mjcodesign.errors import DesignError
from mjcodesign.objects import (
    YCB_IN_DOMAIN,
    YCB_MEDIAN_DENSITY,
    YCB_OOD,
    mass_table,
    parse_density,
    published_mass_or_none,
)
from mjcodesign.scenarios import (
    DEFAULT_REGIME,
    PAPER_DELTA_V,
    REAL_REGIME,
    REGIMES,
    GraspScenario,
    TendonForce,
    TendonPosition,
    at_paper_disturbance,
    get_regime,
    paper_impulse,
    regime_name,
)

# The median is taken over 63 densities: the preset is rounded to 10 kg/m³.
_MEDIAN_ROUNDING = 10.0  # [kg/m³]


def test_the_default_regime_is_the_real_one():
    assert DEFAULT_REGIME == "real"
    real, paper = REGIMES["real"], REGIMES["paper"]
    assert real.scenario == REAL_REGIME and isinstance(real.scenario.tendon, TendonPosition)
    assert real.mass == "auto" and parse_density(real.density) == YCB_MEDIAN_DENSITY
    assert paper.scenario == GraspScenario() and paper.scenario.tendon == TendonForce(tension=10.0)
    assert paper.mass == "density" and parse_density(paper.density) == 100.0
    with pytest.raises(DesignError, match="--regime"):
        get_regime("lab")


def test_ycb_median_density_is_the_median_of_the_published_masses_over_the_mesh_volumes():
    from mjcodesign.objects import load_object

    rho = []
    for name in YCB_IN_DOMAIN + YCB_OOD:
        found = published_mass_or_none(name)
        if found is None:
            continue
        obj = load_object(name, 100.0)
        rho.append(found.mass / (obj.mass / obj.density))
    assert len(rho) == sum(r["mass_kg"] is not None for r in mass_table()["objects"].values())
    assert abs(float(np.median(rho)) - YCB_MEDIAN_DENSITY) <= _MEDIAN_ROUNDING / 2


def test_the_mass_rule_of_a_regime_and_the_flags_that_replace_it():
    real = get_regime("real")
    assert real.masses(None, None) == ("ycb-median", "auto")
    assert real.masses("heavy", None) == ("heavy", "density")  # a density alone: every object from it
    assert real.masses(None, "real") == ("ycb-median", "real")
    assert get_regime("paper").masses(None, None) == ("light", "density")


def test_regime_name_names_the_two_regimes_and_nothing_else():
    assert regime_name(REAL_REGIME, "auto") == regime_name(REAL_REGIME, "real") == "real"
    assert regime_name(REAL_REGIME, "density") == "custom"
    assert regime_name(GraspScenario(), "density") == "paper"
    assert regime_name(GraspScenario(tendon=TendonForce(tension=5.0)), "density") == "custom"
    assert regime_name(GraspScenario(lift=0.05), "density") == "custom"


def test_the_papers_disturbance_sweep_scales_the_velocity_change_or_maps_the_impulse():
    assert at_paper_disturbance(REAL_REGIME, 0.1).delta_v == pytest.approx(PAPER_DELTA_V)
    assert at_paper_disturbance(REAL_REGIME, 0.4).delta_v == pytest.approx(4 * PAPER_DELTA_V)
    paper = at_paper_disturbance(GraspScenario(), 0.2)
    assert paper.delta_v is None and paper.impulse == pytest.approx(paper_impulse(0.2))
    with pytest.raises(DesignError):
        at_paper_disturbance(REAL_REGIME, float("nan"))


def test_grasp_runs_in_the_real_regime_unless_told(capsys):
    from mjcodesign.cli.main import main

    assert main(["grasp", "--object", "egad-like:0", "--design", "semi-rigid", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["regime"] == "real" and out["mass_mode"] == "density"  # no published mass: 680 kg/m³
    assert out["density_kg_m3"] == pytest.approx(YCB_MEDIAN_DENSITY)
    assert out["delta_v_m_s"] == pytest.approx(PAPER_DELTA_V)
    assert out["impulse_ns"] == pytest.approx(out["mass_kg"] * PAPER_DELTA_V)
    assert main(["grasp", "--object", "013_apple", "--design", "semi-rigid", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["regime"] == "real" and out["mass_mode"] == "real" and out["mass_kg"] == pytest.approx(0.068)
    args = ["grasp", "--object", "013_apple", "--design", "semi-rigid", "--regime", "paper", "--json"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["regime"] == "paper" and out["density_kg_m3"] == 100.0 and out["delta_v_m_s"] is None
    assert (
        main(["grasp", "--object", "013_apple", "--design", "semi-rigid", "--tendon", "force:10", "--json"])
        == 0
    )
    assert json.loads(capsys.readouterr().out)["regime"] == "custom"


def test_datagen_by_default_simulates_and_names_the_real_regime(tmp_path):
    from mjcodesign.cli.main import main
    from mjcodesign.data import DatagenConfig, open_dataset

    out = tmp_path / "ds"
    args = [
        "datagen",
        "--objects",
        "013_apple,egad-like:1",
        "--poses-per-object",
        "1",
        "--designs-per-pose",
        "1",
    ]
    assert main([*args, "--out", str(out)]) == 0
    ds = open_dataset(out)
    assert ds.manifest["regime"] == "real"
    config = DatagenConfig.from_dict(ds.manifest["config"])
    assert config.regime == "real" and config.mass == "auto" and config.scenario == REAL_REGIME
    poses = ds.poses().to_pydict()
    mass = dict(zip(poses["object"], poses["mass"], strict=True))
    density = dict(zip(poses["object"], poses["density"], strict=True))
    assert mass["013_apple"] == pytest.approx(0.068)
    assert density["egad-like-0-001"] == pytest.approx(YCB_MEDIAN_DENSITY)
    paper = tmp_path / "paper"
    assert main([*args, "--regime", "paper", "--out", str(paper)]) == 0
    assert open_dataset(paper).manifest["regime"] == "paper"
