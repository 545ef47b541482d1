"""Perturbed grasps: a draw written into a scene copy does exactly what it says, and nothing else."""

import mujoco
import numpy as np
import pytest
from numpy.testing import assert_array_equal

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.models.types import FingerModel, GripperPose
from mjcodesign.objects import box_object
from mjcodesign.scenarios.drive import TendonForce, TendonPosition
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene, drive_scene
from mjcodesign.scenarios.perturb import NOMINAL, Perturbation, perturbed_pose, perturbed_scene
from mjcodesign.sim import MujocoBackend

_G = 9.81
_TOL_HOLD = 0.05  # vertical finger force during the hold equals m g within 5% (as tests/test_grasp.py)
_TOL_ANGLE = 1e-12  # rad: a quaternion product, round-off only


@pytest.fixture(scope="module")
def box_scene():
    obj = box_object((0.05,) * 3, 400.0)
    return build_scene(
        obj, FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.CHAIN, auto_pose(obj)
    )


_ALTERNATING = ",".join(["14", "17"] * 11)  # soft segments, stiff flexures (the reverse on finger B)


@pytest.mark.parametrize("text", ["paper-optimized", "random:3", "random:11", _ALTERNATING])
def test_nominal_draw_is_the_unperturbed_rollout_bitwise(box_scene, text):
    """Across the design space: a draw that changes nothing leaves the rollout as it was, bit for bit."""
    from mjcodesign.sim.mujoco_c import scene_with_design

    scenario = GraspScenario(impulse=0.0, hold_s=0.1, post_hold_s=0.05)
    scene = scene_with_design(box_scene, Stiffness.parse(text))
    a = MujocoBackend().run(scene, scenario)
    b = MujocoBackend().run(perturbed_scene(scene, scenario, NOMINAL), scenario)
    assert_array_equal(a.body_force, b.body_force)
    assert_array_equal(a.displacement, b.displacement)


def test_palm_moves_and_turns_by_the_draw():
    pose = GripperPose((0.01, -0.02, 0.2), (np.cos(0.3), 0.0, np.sin(0.3), 0.0), (0.04, 0.03))
    p = Perturbation(palm_offset=(0.002, -0.001, 0.0005), palm_rotation=(0.0, 0.02, -0.02))
    moved = perturbed_pose(pose, p)
    np.testing.assert_allclose(np.subtract(moved.position, pose.position), p.palm_offset, atol=1e-15)
    # R' = R(rotvec) R: the relative rotation R' R^T has the draw's angle |rotvec| and axis rotvec/|rotvec|.
    rel = moved.matrix()[:3, :3] @ pose.matrix()[:3, :3].T
    angle = np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))
    assert angle == pytest.approx(np.linalg.norm(p.palm_rotation), abs=_TOL_ANGLE)
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]]) / (
        2 * np.sin(angle)
    )
    np.testing.assert_allclose(axis, np.asarray(p.palm_rotation) / np.linalg.norm(p.palm_rotation), atol=1e-9)
    assert moved.openings == pose.openings


@pytest.mark.parametrize("scale", [0.9, 1.1])
def test_hold_force_follows_the_scaled_mass(box_scene, scale):
    # Static hold of the lifted box: sum F_z (finger contacts) = (scale m) g
    scenario = GraspScenario(tendon=TendonForce(tension=10.0), impulse=0.0, hold_s=0.3)
    scene = perturbed_scene(box_scene, scenario, Perturbation(mass_scale=scale))
    assert scene.model.body_mass[scene.object_body] == pytest.approx(scale * box_scene.obj.mass, rel=1e-12)
    out = MujocoBackend().run(scene, scenario)
    assert out.success, out.reason
    assert out.body_force[5] == pytest.approx(scale * box_scene.obj.mass * _G, rel=_TOL_HOLD)


def test_friction_scales_the_finger_object_pair_only(box_scene):
    scenario = GraspScenario()
    m0 = box_scene.model
    m = perturbed_scene(box_scene, scenario, Perturbation(friction_scale=0.8)).model
    obj = m.geom_bodyid == box_scene.object_body
    finger = box_scene.finger_mask[m.geom_bodyid]
    np.testing.assert_allclose(m.geom_friction[finger, 0], 0.8 * m0.geom_friction[finger, 0])
    assert_array_equal(m.geom_friction[~finger], m0.geom_friction[~finger])
    assert_array_equal(m.geom_friction[:, 1:], m0.geom_friction[:, 1:])  # torsional, rolling unchanged
    # The pair's coefficient is the larger one, the fingers': the object's is MuJoCo's minimum.
    assert np.all(m.geom_friction[obj, 0] == mujoco.mjMINMU)
    assert np.all(m.geom_friction[finger, 0] > m.geom_friction[obj, 0])


def _actuators(scene):
    m = scene.model
    return [
        mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        for h in scene.built.fingers
        for a in h.actuators
    ]


def test_force_mode_tension_scales(box_scene):
    # Force mode: tendon force = gear * control, so the applied tension is scale * the commanded one.
    scenario = GraspScenario(tendon=TendonForce(tension=10.0))
    scene = perturbed_scene(box_scene, scenario, Perturbation(tendon_scale=1.05))
    ids = _actuators(box_scene)
    np.testing.assert_allclose(
        scene.model.actuator_gear[ids, 0], 1.05 * box_scene.model.actuator_gear[ids, 0]
    )
    d = mujoco.MjData(scene.model)
    d.ctrl[ids] = 10.0
    mujoco.mj_forward(scene.model, d)
    moment = d.actuator_force[ids] / d.ctrl[ids]
    np.testing.assert_allclose(moment, 1.0)  # the actuator force is the control; the gear carries the scale


def test_position_mode_servo_scales_and_the_backend_keeps_it(box_scene):
    scenario = GraspScenario(tendon=TendonPosition())
    ref = drive_scene(box_scene, scenario).model
    scene = perturbed_scene(box_scene, scenario, Perturbation(tendon_scale=0.95))
    ids = _actuators(box_scene)
    np.testing.assert_allclose(scene.model.actuator_gainprm[ids, 0], 0.95 * ref.actuator_gainprm[ids, 0])
    np.testing.assert_allclose(scene.model.actuator_forcerange[ids], 0.95 * ref.actuator_forcerange[ids])
    assert drive_scene(scene, scenario) is scene  # the backend's drive step leaves the scaled servo


def test_bad_draws_are_refused():
    with pytest.raises(DesignError):
        Perturbation(mass_scale=0.0)
    with pytest.raises(DesignError):
        Perturbation(palm_offset=(0.0, np.nan, 0.0))
    with pytest.raises(DesignError):
        Perturbation(tendon_scale=float("inf"))


def test_perturbed_jobs_batch_bitwise_like_single_rollouts(box_scene):
    """run_jobs batches perturbed jobs through run_scenes; each equals its own single rollout bitwise."""
    from mjcodesign.jobs import GraspJob, run_jobs

    scenario = GraspScenario(impulse=0.0, hold_s=0.1, post_hold_s=0.05)
    draws = [
        NOMINAL,
        Perturbation(palm_offset=(0.001, 0.0, 0.0005), mass_scale=1.08),
        Perturbation(palm_rotation=(0.0, 0.0, 0.03), friction_scale=0.85, tendon_scale=1.04),
    ]
    designs = [Stiffness.preset("paper-optimized"), Stiffness.preset("soft")]
    jobs = [
        GraspJob(obj=box_scene.obj, pose=box_scene.pose, design=d, scenario=scenario, perturbation=p)
        for p in draws
        for d in designs
    ]
    outs = run_jobs(jobs, MujocoBackend(nthread=2))
    for job, out in zip(jobs, outs, strict=True):
        scene = build_scene(box_scene.obj, FingerDesign(), job.design, FingerModel.CHAIN, box_scene.pose)
        ref = MujocoBackend().run(perturbed_scene(scene, scenario, job.perturbation), scenario)
        assert_array_equal(out.body_force, ref.body_force)
        assert_array_equal(out.displacement, ref.displacement)
    plain = run_jobs(
        [GraspJob(obj=box_scene.obj, pose=box_scene.pose, design=designs[0], scenario=scenario)],
        MujocoBackend(),
    )[0]
    assert_array_equal(plain.body_force, outs[0].body_force)  # the nominal draw is the plain job


def test_start_penetration_grows_with_the_palm_error():
    """A palm draw that pushes the open fingers into an object: the overlap grows as the error does."""
    from mjcodesign.evaluation.candidates import object_candidates
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.scenarios.perturb import start_penetration

    obj = load_grasp_object("egad-like:3", "light")
    cands = object_candidates(obj, 10)
    base = build_scene(obj, FingerDesign(), Stiffness.preset("soft"), FingerModel.CHAIN, cands.poses[0])
    scenario = GraspScenario()
    rng = np.random.default_rng(0)

    def depth(pose, offset, rotation, s):
        p = Perturbation(palm_offset=tuple(s * offset), palm_rotation=tuple(s * rotation))
        return start_penetration(perturbed_scene(base, scenario, p, pose=pose))

    for _ in range(200):
        pose = cands.poses[int(rng.integers(len(cands)))]
        off, rot = rng.uniform(-0.002, 0.002, 3), np.deg2rad(rng.uniform(-2, 2, 3))
        if depth(pose, off, rot, 0.0) == 0.0 and depth(pose, off, rot, 1.0) > 0.0005:
            break
    else:
        pytest.fail("no palm draw of ±2 mm, ±2° overlapped the object in 200 tries")
    assert depth(pose, off, rot, 1.5) > depth(pose, off, rot, 1.0) > depth(pose, off, rot, 0.5)
