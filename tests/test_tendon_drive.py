"""The tendon drive of a grasp: a fixed tension (the paper's simulator) or the XL330 position servo."""

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.models.types import FingerModel
from mjcodesign.objects import box_object
from mjcodesign.scenarios import (
    GraspScenario,
    TendonForce,
    TendonPosition,
    TendonSpecError,
    drive_scene,
    parse_tendon,
    phase_controls,
)
from mjcodesign.scenarios.grasp import STATE_SPEC, auto_pose, build_scene, control_spec
from mjcodesign.sim import MujocoBackend, initial_state

_G = 9.81
_TOL_HOLD = 0.05  # issue: vertical finger force during the hold equals m g within 5%


def test_parse_tendon_reads_both_modes_and_refuses_the_rest():
    assert parse_tendon("force:10") == TendonForce(tension=10.0)
    assert parse_tendon(" position:1000 ") == TendonPosition(ticks=1000.0)
    for bad in (
        "force",
        "force:",
        "pos:10",
        "position:x",
        "force:0",
        "force:-1",
        "force:nan",
        "position:inf",
        "position:0",
    ):
        with pytest.raises(TendonSpecError):
            parse_tendon(bad)
    assert issubclass(TendonSpecError, DesignError)  # the CLI's exit 2


def test_xl330_servo_numbers_follow_from_the_hardware():
    # T_max = τ_stall / r = 0.52 N m / 8 mm (the authors' horn); pull = r 2π ticks / 4096 = 12.3 mm at
    # the paper's 1000 ticks; v = ω₀ r with ω₀ = 103 rpm
    p = TendonPosition()
    assert p.spool_radius == 0.008 and p.ticks == 1000
    assert p.max_tension == pytest.approx(65.0)
    assert p.pull == pytest.approx(0.008 * 2 * math.pi * 1000 / 4096)
    assert p.pull_speed == pytest.approx(103 / 60 * 2 * math.pi * 0.008)
    # a lower current limit lowers the tension limit in proportion (torque ∝ current below stall)
    assert TendonPosition(current_limit=0.735).max_tension == pytest.approx(32.5)
    # the register holds 1 mA units and tops at the factory default 1750
    assert TendonPosition(current_limit=0.9).current_limit_register == 900
    with pytest.raises(DesignError):
        TendonPosition(current_limit=1.8)
    # b / k must exceed dt / 2 = 1 ms for the explicit servo spring to be stable (drive.apply_drive)
    assert p.damping / p.stiffness > 1e-3


def test_tension_reads_the_force_modes_tension():
    assert GraspScenario().tension == 10.0
    assert GraspScenario(tendon=TendonForce(tension=4.0)).tension == 4.0
    pos = GraspScenario(tendon=TendonPosition())
    assert pos.tension is None
    s = GraspScenario(tendon=TendonForce(tension=4.0))
    assert dataclasses.replace(s, tendon=TendonForce(tension=5.0)).tension == 5.0
    assert dataclasses.replace(s, tendon=TendonPosition()).tendon == TendonPosition()
    assert dataclasses.replace(pos, lift=0.02).tendon == TendonPosition()
    # the tendon is set in one place: no constructor shorthand, and the read property is read-only
    with pytest.raises(TypeError):
        GraspScenario(tension=3.0)
    with pytest.raises(AttributeError):
        s.tension = 3.0
    with pytest.raises(DesignError):
        GraspScenario(tendon=TendonForce(tension=60.0))  # above the tension motors' 50 N range


@pytest.fixture(scope="module")
def box():
    return box_object((0.05,) * 3, 400.0)  # the tests' 50 g box


def test_position_mode_needs_its_scene(box):
    scene = build_scene(
        box, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.CHAIN, auto_pose(box)
    )
    scenario = GraspScenario(tendon=TendonPosition())
    with pytest.raises(DesignError, match="drive_scene"):
        phase_controls(scene, scenario)
    assert drive_scene(scene, GraspScenario()) is scene  # force mode: the compiled actuators as they are


def test_position_servo_tracks_its_target_and_saturates_at_the_current_limit(box):
    # The tendon length follows ℓ* = ℓ₀ − min(v t, r 2π ticks / 4096); the tension is k (ℓ − ℓ*) while
    # below T_max, and T_max once the box blocks the fingers.
    scene = build_scene(
        box, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.CHAIN, auto_pose(box)
    )
    drive = TendonPosition()
    scenario = GraspScenario(tendon=drive, impulse=0.0)
    scene = drive_scene(scene, scenario)
    m = scene.model
    ctrl, starts = phase_controls(scene, scenario)
    acts = [
        mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        for h in scene.built.fingers
        for a in h.actuators
    ]
    tendons = m.actuator_trnid[acts, 0]
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, initial_state(scene), STATE_SPEC)
    tension = []
    for t in range(starts["hold"]):
        mujoco.mj_setState(m, d, ctrl[t], control_spec())
        mujoco.mj_step(m, d)
        target = -ctrl[t, acts]
        k_err = drive.stiffness * (d.ten_length[tendons] - target)
        expected = np.clip(k_err, 0.0, drive.max_tension)
        np.testing.assert_allclose(d.actuator_force[acts], expected, rtol=1e-9, atol=1e-9)
        tension.append(d.actuator_force[acts].copy())
    wound = m.tendon_length0[tendons] + ctrl[starts["hold"] - 1, acts]
    np.testing.assert_allclose(wound, drive.pull, rtol=1e-12)  # the whole pull is commanded by the hold
    assert np.max(tension) == pytest.approx(drive.max_tension)  # the box stops the fingers: saturated


def test_position_mode_holds_the_box_with_its_weight(box):
    # Static equilibrium of the lifted box: Σ F_z (finger contacts) = m g. Semi-rigid: softer designs
    # wrap their free distal half under the box at 52 N and push it up (docs/benchmarks.md), no static hold.
    scene = build_scene(
        box, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.CHAIN, auto_pose(box)
    )
    out = MujocoBackend().run(scene, GraspScenario(tendon=TendonPosition(), impulse=0.0, hold_s=0.3))
    assert out.success, out.reason
    assert out.body_force[5] == pytest.approx(box.mass * _G, rel=_TOL_HOLD)


def test_datagen_config_takes_either_drive():
    # a dataset's tendon: the force shorthand keeps its fingerprint; position mode reaches the scenario
    from mjcodesign.data import DatagenConfig, parse_density_spec
    from mjcodesign.data import parse_tendon as data_tendon

    common = dict(objects=("egad-like:1",), poses_per_object=1, designs_per_pose=2)
    density = parse_density_spec("light")
    short = DatagenConfig(**common, density=density, tension=10.0)
    force = DatagenConfig(**common, density=density, tendon=data_tendon("force:10"))
    assert force.fingerprint() == short.fingerprint() and force.tension == 10.0
    assert short.as_dict()["tendon"] == {"mode": "force", "tension_n": 10.0}
    pos = DatagenConfig(**common, density=density, tendon=data_tendon("position:1000"))
    assert pos.scenario.tendon == TendonPosition(ticks=1000) and pos.tension is None
    d = pos.as_dict()["tendon"]
    assert d["mode"] == "position" and d["ticks"] == 1000 and d["max_tension_n"] == pytest.approx(65.0)
    assert pos.fingerprint() != force.fingerprint()
    with pytest.raises(DesignError, match="tendon drive"):
        DatagenConfig(**common, density=density, tension=None)


def test_grasp_cli_takes_the_tendon_drive(tmp_path, capsys):
    # `grasp --tendon position:TICKS`: the semi-rigid chain holds the 50 g box, vertical force = m g
    import json

    import trimesh

    from mjcodesign.cli.main import main

    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    base = ["grasp", "--object", str(box), "--design", "semi-rigid", "--density", "heavy", "--impulse", "0"]
    assert main([*base, "--tendon", "position:1000", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["success"], out["reason"]
    assert out["body_force"][5] == pytest.approx(out["mass_kg"] * _G, rel=_TOL_HOLD)
    for bad, match in (
        (["--tendon", "position:abc"], "not a number"),
        (["--tendon", "force:5", "--tension", "5"], "not both"),
    ):
        assert main([*base, *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and match in err[0], err


def _finger_tensions(box, design: str, drive: TendonPosition, **scenario):
    """Each finger's tendon tension [N] at every step of a grasp rollout, and the phase starts."""
    scene = build_scene(box, FingerDesign(), Stiffness.parse(design), FingerModel.CHAIN, auto_pose(box))
    sc = GraspScenario(tendon=drive, **scenario)
    scene = drive_scene(scene, sc)
    m = scene.model
    ctrl, starts = phase_controls(scene, sc)
    acts = [
        [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in h.actuators]
        for h in scene.built.fingers
    ]
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, initial_state(scene), STATE_SPEC)
    out = np.full((len(ctrl), len(acts)), np.nan)
    for t in range(len(ctrl)):
        mujoco.mj_setState(m, d, ctrl[t], control_spec())
        mujoco.mj_step(m, d)
        out[t] = [d.actuator_force[a].sum() for a in acts]
    return out, starts


_STALL_TENSION = 0.52 / 0.008  # XL330-M288-T stall torque at 5 V [N m] over the 8 mm horn [m] = 65 N


@pytest.mark.parametrize(("design", "current"), [("soft", 1.75), ("semi-rigid", 1.75), ("semi-rigid", 0.735)])
def test_servo_tension_never_exceeds_the_stall_tension_or_the_current_limits_share(box, design, current):
    # T ≤ τ_stall / r, and T ≤ τ_stall (I_limit / I_stall) / r below the 1.47 A stall current: through the
    # whole grasp (pull, 10 cm lift, disturbance), at the paper's 1000 ticks, where the box blocks the fingers.
    drive = TendonPosition(current_limit=current)
    limit = _STALL_TENSION * min(current, 1.47) / 1.47
    tension, starts = _finger_tensions(box, design, drive, lift=0.1, lift_s=0.88, delta_v=0.5)
    assert np.all(np.isfinite(tension))
    assert tension.max() <= limit * (1 + 1e-9)
    assert tension.min() >= 0.0  # a tendon only pulls
    assert tension[starts["lift"] - 1].min() == pytest.approx(limit, rel=1e-6)  # blocked: saturated


def test_a_stiffer_finger_meets_a_higher_tension_at_the_same_goal(box):
    # At a goal the fingers can follow (100 ticks, 1.2 mm of tendon), the servo's tension is k (ℓ − ℓ*):
    # a stiffer finger shortens its tendon less under the same pull, so the error, and the tension, are
    # larger. Order soft < paper-optimized < semi-rigid (ln E of the flexures 14 < mixed < 17), all
    # below the 65 N limit.
    drive = TendonPosition(ticks=100)
    end = {}
    for design in ("soft", "paper-optimized", "semi-rigid"):
        tension, starts = _finger_tensions(box, design, drive, impulse=0.0)
        end[design] = float(tension[starts["lift"] - 1].mean())
    assert end["soft"] < end["paper-optimized"] < end["semi-rigid"] < drive.max_tension
    assert end["semi-rigid"] > 2 * end["soft"]


def _object_contact_forces(rollout, step: int) -> dict[str, np.ndarray]:
    """World force [N] on the object at ``step`` from the fingers, the palm (and mount) and the ground."""
    m, sc = rollout.model, rollout.scene
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, rollout.states[step], STATE_SPEC)
    mujoco.mj_setState(m, d, rollout.ctrl[step + 1], control_spec())  # the controls of the next step
    mujoco.mj_forward(m, d)
    out = {"fingers": np.zeros(3), "palm": np.zeros(3), "ground": np.zeros(3)}
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = (int(m.geom_bodyid[g]) if g >= 0 else -1 for g in (c.geom1, c.geom2))
        if sc.object_body not in (b1, b2):
            continue
        mujoco.mj_contactForce(m, d, i, f6)  # geom1 on geom2, in the contact frame
        force = (1.0 if b2 == sc.object_body else -1.0) * (c.frame.reshape(3, 3).T @ f6[:3])
        other = b1 if b2 == sc.object_body else b2
        key = (
            "ground"
            if sc.ground_geom in (c.geom1, c.geom2)
            else "fingers"
            if sc.finger_mask[other]
            else "palm"
        )
        out[key] += force
    return out


class _KeepRollout:
    """An observer that keeps the last rollout it is handed (in ``kept``)."""

    def __init__(self) -> None:
        self.kept = None

    def rollout(self, r) -> None:
        self.kept = r

    def snapshot(self, s) -> None:
        pass

    def close(self) -> None:
        pass


def test_in_the_real_regime_fingers_and_palm_together_carry_the_weight():
    # The servo pulls the can into the palm: the fingers' wrench (Outcome.body_force) then exceeds m g,
    # and the palm pushes back; fingers and palm together carry the weight during the hold.
    from mjcodesign.cli.common import user_cache_dir
    from mjcodesign.jobs import GraspJob, load_grasp_object, resolve_pose, run_jobs
    from mjcodesign.scenarios import REGIMES

    real = REGIMES["real"]
    can = load_grasp_object("010_potted_meat_can", real.density, mass=real.mass, cache_dir=user_cache_dir())
    pose = resolve_pose("best", can, cache_dir=user_cache_dir())
    job = GraspJob(obj=can, pose=pose, design=Stiffness.preset("semi-rigid"), scenario=real.scenario)
    keep = _KeepRollout()
    out = run_jobs([job], MujocoBackend(), keep)[0]
    assert out.success, out.reason
    r = keep.kept
    forces = _object_contact_forces(r, r.starts["impulse"] - 5)  # the end of the hold
    weight = can.mass * _G
    assert np.linalg.norm(forces["ground"]) == 0.0
    assert forces["fingers"][2] + forces["palm"][2] == pytest.approx(weight, rel=_TOL_HOLD)
    assert forces["palm"][2] < -0.1 * weight  # the palm pushes down: the fingers pull the can up into it
    assert out.body_force[5] > 2 * weight  # so the fingers' wrench alone is not the hold force here
