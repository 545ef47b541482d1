"""The grasp's physical settings: the disturbance as a Δv of the object, the finger–object friction."""

import math

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.models.types import FingerModel, SimOptions
from mjcodesign.objects import box_object
from mjcodesign.scenarios.drive import TendonForce
from mjcodesign.scenarios.grasp import (
    DEFAULT_IMPULSE,
    PAPER_DELTA_V,
    REAL_REGIME,
    TAPE_FRICTION_RANGE,
    GraspScenario,
    auto_pose,
    build_scene,
    drive_scene,
    paper_delta_v,
    phase_controls,
    scene_options,
)
from mjcodesign.sim import MujocoBackend

_BOX = 0.05  # box side [m]


def _scene(rho: float, options: SimOptions | None = None):
    obj = box_object((_BOX,) * 3, rho)
    return build_scene(
        obj,
        FingerDesign(),
        Stiffness.preset("paper-optimized"),
        FingerModel.CHAIN,
        auto_pose(obj),
        options=options,
    )


def _impulse(scene, scenario) -> float:
    """The impulse the controls give the object [N s]: ∫ F_z dt over the rollout (one step of force)."""
    ctrl, _ = phase_controls(scene, scenario)
    m = scene.model
    xfrc = ctrl[:, m.nu :].reshape(len(ctrl), m.nbody, 6)
    return float(xfrc[:, scene.object_body, 2].sum() * m.opt.timestep)


def test_delta_v_gives_an_impulse_proportional_to_mass():
    # J = m Δv: the same velocity change for a 12.5 g and a 50 g box.
    scenario = GraspScenario(delta_v=0.5)
    light, heavy = _scene(100.0), _scene(400.0)
    for scene in (light, heavy):
        assert _impulse(scene, scenario) == pytest.approx(-scene.obj.mass * 0.5, rel=1e-12)
    assert _impulse(heavy, scenario) / _impulse(light, scenario) == pytest.approx(4.0, rel=1e-12)
    # An impulse in N s stays the same whatever the mass.
    fixed = GraspScenario(impulse=0.02)
    assert _impulse(light, fixed) == pytest.approx(_impulse(heavy, fixed), rel=1e-12)


def test_paper_delta_v_is_the_papers_impulse_over_its_object_mass_froude_scaled():
    # Δv = J_p / (s³ ρ_p V) / √s with s = 5, J_p = 0.1 N s, ρ_p = 2 (their light density).
    v = 3.54e-4
    assert paper_delta_v(v) == pytest.approx(0.1 / (125 * 2.0 * v) / math.sqrt(5.0), rel=1e-12)
    assert PAPER_DELTA_V == pytest.approx(0.505, abs=1e-3)
    assert paper_delta_v(v, density=8.0) == pytest.approx(PAPER_DELTA_V / 4.0, rel=1e-12)


def test_disturbance_is_an_impulse_or_a_delta_v_not_both():
    with pytest.raises(DesignError, match="not both"):
        GraspScenario(impulse=0.05, delta_v=0.5)
    with pytest.raises(DesignError):
        GraspScenario(delta_v=-1.0)
    assert GraspScenario(delta_v=0.5).impulse == DEFAULT_IMPULSE  # the impulse field is left as is


@pytest.mark.parametrize("mu", [0.6, 1.0, 1.5])
def test_friction_is_compiled_into_the_finger_geoms_alone(mu):
    scene = _scene(400.0, scene_options(GraspScenario(friction=mu)))
    m = scene.model
    finger = scene.finger_mask[m.geom_bodyid]
    obj = m.geom_bodyid == scene.object_body
    assert np.all(m.geom_friction[finger, 0] == mu)
    # MuJoCo takes the larger coefficient of a contact's two geoms: the object's minimum (mjMINMU)
    # leaves the finger's for a finger contact, and the ground's 1 for the object on the ground.
    assert np.all(m.geom_friction[obj, 0] == mujoco.mjMINMU)
    assert m.geom_friction[scene.ground_geom, 0] == 1.0


def test_friction_below_one_takes_effect():
    # A 50 g box needs 2 μ N >= m g: at μ = 0.01 a grip of 10 N tension cannot hold it (N >= 25 N),
    # at the paper's μ = 1 it holds. Before the object's own sliding friction was 0, MuJoCo's larger-
    # coefficient rule kept μ = 1 on every finger contact whatever the fingers carried.
    hold = GraspScenario(tendon=TendonForce(tension=10.0), impulse=0.0)
    slip = GraspScenario(tendon=TendonForce(tension=10.0), impulse=0.0, friction=0.01)
    held = MujocoBackend().run(_scene(400.0), hold)
    slid = MujocoBackend().run(_scene(400.0, scene_options(slip)), slip)
    assert held.success, held.reason
    assert not slid.success


def test_drive_scene_refuses_a_friction_the_scene_was_not_compiled_with():
    with pytest.raises(DesignError, match="friction"):
        drive_scene(_scene(400.0), GraspScenario(friction=0.6))


def test_real_regime_preset():
    assert REAL_REGIME.delta_v == PAPER_DELTA_V
    lo, hi = TAPE_FRICTION_RANGE
    assert lo <= REAL_REGIME.friction <= hi
    assert REAL_REGIME.tension is None  # the position servo, not a fixed force
    assert REAL_REGIME.tendon.ticks == 1000 and REAL_REGIME.tendon.spool_radius == 0.008  # the authors' horn
    # the paper's 10 cm lift at the arm's speed: smooth-step peak speed 1.5 h / T = 0.17 m/s (Franka 1.7 m/s
    # at the hardware's dynamics factor 0.1), peak acceleration 6 h / T² under its 1.3 m/s²
    assert REAL_REGIME.lift == 0.1
    assert 1.5 * REAL_REGIME.lift / REAL_REGIME.lift_s == pytest.approx(0.17, rel=1e-12)
    assert 6 * REAL_REGIME.lift / REAL_REGIME.lift_s**2 < 1.3


def test_grasp_cli_takes_the_disturbance_as_delta_v_and_the_friction(capsys):
    import json

    from mjcodesign.cli.main import main

    argv = [
        "grasp",
        "--object",
        "013_apple",
        "--mass",
        "real",
        "--delta-v",
        "paper",
        "--friction",
        "tape-min",
    ]
    assert main([*argv, "--design", "semi-rigid", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["delta_v_m_s"] == PAPER_DELTA_V and out["friction"] == TAPE_FRICTION_RANGE[0]
    assert out["impulse_ns"] == pytest.approx(0.068 * PAPER_DELTA_V, rel=1e-12)  # J = m dv, the apple's m
    assert main(["grasp", "--object", "013_apple", "--friction", "sticky", "--json"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
