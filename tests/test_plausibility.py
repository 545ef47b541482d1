"""Every grasp rollout is checked against physics: the energy bound, MuJoCo's instability warnings."""

import copy
import os

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models.simulate import captured_warnings
from mjcodesign.models.types import FingerModel
from mjcodesign.objects import box_object
from mjcodesign.scenarios import ENERGY_FLOOR, ENERGY_TOL, Failure, GraspScenario, energy_balance
from mjcodesign.scenarios.grasp import STATE_SPEC, auto_pose, build_scene, control_spec, phase_controls
from mjcodesign.sim import MujocoBackend, initial_state
from mjcodesign.sim.mujoco_c import scene_with_model

_BOX = 0.05  # box side [m]
_RHO = 400.0  # heavy preset [kg/m³]: 50 g box


@pytest.fixture(scope="module")
def box_scene():
    obj = box_object((_BOX,) * 3, _RHO)
    return build_scene(
        obj, FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.CHAIN, auto_pose(obj)
    )


def _rollout(scene, scenario):
    """States, sensors, controls and the initial state of one rollout stepped here."""
    m = scene.model
    ctrl, _ = phase_controls(scene, scenario)
    x0 = initial_state(scene)
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, x0, STATE_SPEC)
    states = np.empty((len(ctrl), x0.size))
    sensors = np.empty((len(ctrl), m.nsensordata))
    for t in range(len(ctrl)):
        mujoco.mj_setState(m, d, ctrl[t], control_spec())
        mujoco.mj_step(m, d)
        mujoco.mj_getState(m, d, states[t], STATE_SPEC)
        sensors[t] = d.sensordata
    return x0, states, ctrl, sensors


def test_ordinary_rollout_keeps_the_energy_bound(box_scene):
    # E(t) − E(0) ≤ W⁺_act(t) + W_impulse(t): a held box with the default disturbance
    scenario = GraspScenario()
    x0, states, ctrl, sensors = _rollout(box_scene, scenario)
    b = energy_balance(box_scene.model, box_scene.object_body, x0, states, ctrl, sensors)
    assert b.plausible, b
    assert b.total_work > 0.01  # the tendons and the lift did work (J)
    out = MujocoBackend().run(box_scene, scenario)
    assert Failure.IMPLAUSIBLE not in out.failures


def test_energy_made_from_nothing_is_implausible(box_scene):
    # The same rollout with a large impulse that the balance is not told about: the box gains
    # ½ m Δv² (Δv = J / m = 4 m/s: 0.4 J) that no actuator put in, and the bound must catch it.
    scenario = GraspScenario(impulse=0.2)
    x0, states, ctrl, sensors = _rollout(box_scene, scenario)
    told = energy_balance(box_scene.model, box_scene.object_body, x0, states, ctrl, sensors)
    assert told.plausible, told
    hidden = ctrl.copy()
    nu = box_scene.model.nu
    ob = box_scene.object_body
    hidden[:, nu + 6 * ob : nu + 6 * ob + 6] = 0.0
    b = energy_balance(box_scene.model, ob, x0, states, hidden, sensors)
    assert not b.plausible
    assert b.excess > 0.1  # J: most of the impulse's 0.4 J
    assert "implausible" in b.reason(box_scene.model.opt.timestep)


def test_tolerances_are_small_next_to_an_impulse():
    # The bound's slack must stay far below the energy of the paper's disturbance on a light object:
    # 0.0179 N s on a 5 g strawberry is 32 mJ, against a 0.1 mJ floor.
    assert ENERGY_FLOOR < 0.01 * 0.5 * 0.0179**2 / 0.005
    assert ENERGY_TOL <= 0.1


def test_instability_is_diverged_and_counted_not_printed(box_scene, tmp_path, capfd, monkeypatch):
    # A hinge 1e9 times too stiff for its 2 ms step blows up; MuJoCo's message is counted into the
    # outcome and neither printed nor logged to MUJOCO_LOG.TXT.
    monkeypatch.chdir(tmp_path)
    m = copy.copy(box_scene.model)
    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "A_hinge5")
    m.jnt_stiffness[jid] *= 1e9
    scene = scene_with_model(box_scene, m)
    outs = MujocoBackend(nthread=2).run_scenes([scene, scene], GraspScenario(hold_s=0.02, post_hold_s=0.02))
    single = MujocoBackend().run(scene, GraspScenario(hold_s=0.02, post_hold_s=0.02))
    for out in (*outs, single):
        assert out.failures == (Failure.DIVERGED,)
        assert "BADQACC" in out.reason or "QACC" in out.reason
        assert "warning(s)" in out.reason
    printed = capfd.readouterr()
    assert "WARNING" not in printed.out and "WARNING" not in printed.err
    assert not os.path.exists(tmp_path / "MUJOCO_LOG.TXT")


def _blow_up() -> None:
    """One step of a slider pushed with 1e300 N: MuJoCo warns BADQACC (once per fresh data)."""
    m = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint type="slide"/><geom size=".1" mass="1"/></body></worldbody></mujoco>'
    )
    d = mujoco.MjData(m)
    d.qfrc_applied[0] = 1e300
    mujoco.mj_step(m, d)


def test_captured_warnings_nest_and_restore_the_previous_handler(capfd):
    before = mujoco.get_mju_user_warning()
    with captured_warnings() as outer:
        with captured_warnings() as inner:
            _blow_up()
        _blow_up()
    assert mujoco.get_mju_user_warning() is before
    assert len(inner) == 1 and len(outer) == 2 and "QACC" in inner[0]
    assert "WARNING" not in capfd.readouterr().out


def test_a_tiny_object_flung_by_the_impulse_is_implausible():
    # The paper's 0.0179 N s on a 1 mm cube (0.1 mg) drives it 4.8 km/s into the ground and MuJoCo's
    # contact throws it 17 m up: the impulse's credited work (J·v̄ ≈ 43 J) covers that energy, so
    # only the motion bounds see it: speed·dt far above its 1 mm size, and a rise far above the lift.
    scene = build_scene(
        box_object((0.001,) * 3, 100.0),
        FingerDesign(),
        Stiffness.preset("paper-optimized"),
        FingerModel.CHAIN,
        auto_pose(box_object((0.001,) * 3, 100.0)),
    )
    out = MujocoBackend().run(scene, GraspScenario())
    assert out.failure is Failure.IMPLAUSIBLE, out.reason
    assert "m/s" in out.reason and "rose" in out.reason


def test_motion_bounds_each_hold_and_break():
    from mjcodesign.scenarios.motion import motion_bound

    ext = np.array([0.05, 0.04, 0.06])
    ok = motion_bound(
        np.array([0.0, 0.5, 3.6]), np.array([0.03, 0.05]), 0.03, dt=0.002, extents=ext, lift=0.03
    )
    assert ok.plausible, ok.reason
    fast = motion_bound(np.array([0.0, 20.5]), np.array([0.03]), 0.03, dt=0.002, extents=ext, lift=0.03)
    assert not fast.plausible and "m/s" in fast.reason  # 20.5 m/s × 2 ms = 41 mm > 40 mm
    sunk = motion_bound(np.zeros(3), np.array([0.03, -0.001]), 0.03, dt=0.002, extents=ext, lift=0.03)
    assert not sunk.plausible and "below the ground" in sunk.reason
    high = motion_bound(np.zeros(3), np.array([0.03 + 0.091]), 0.03, dt=0.002, extents=ext, lift=0.03)
    assert not high.plausible and "rose" in high.reason  # 91 mm > 30 mm lift + 60 mm size


def test_a_capture_takes_its_own_threads_warnings_not_another_python_threads(capfd):
    """A warning raised in another Python thread (a scene built, an outcome replayed beside a rollout)
    does not reach this thread's capture: it is printed on stderr, named as outside a checked rollout.
    MuJoCo's own threads (``mujoco.rollout``'s pool) do reach the capture of the thread that started it."""
    import threading

    from mujoco import rollout as mj_rollout

    with captured_warnings() as mine:
        other = threading.Thread(target=_blow_up)
        other.start()
        other.join()
    assert mine == []
    err = capfd.readouterr().err
    assert "MuJoCo warning outside a checked rollout" in err and "QACC" in err

    m = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint type="slide"/><geom size=".1" mass="1"/></body></worldbody></mujoco>'
    )
    datas = [mujoco.MjData(m) for _ in range(2)]
    x0 = np.zeros(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    ctrl = np.zeros((4, 3, m.nv))
    ctrl[..., 0] = 1e300  # qfrc_applied, every step of every rollout
    with captured_warnings() as pooled:
        mj_rollout.rollout(
            [m] * 4, datas, x0[None], ctrl, control_spec=mujoco.mjtState.mjSTATE_QFRC_APPLIED
        )
    assert pooled and all("QACC" in w for w in pooled)
