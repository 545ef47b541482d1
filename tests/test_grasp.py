"""Grasp scenario on the chain model: static hold force, determinism, batched rollouts."""

import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import PoseError
from mjcodesign.models.types import FingerModel, GripperPose, SimOptions
from mjcodesign.objects import box_object
from mjcodesign.scenarios.drive import TendonForce
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene
from mjcodesign.sim import MujocoBackend, with_stiffness

_G = 9.81
_TOL_HOLD = 0.05  # issue: vertical finger force during the hold equals m g within 5%
_BOX = 0.05  # box side [m]
_RHO = 400.0  # heavy preset [kg/m³]: 50 g box


@pytest.fixture(scope="module")
def box_scene():
    obj = box_object((_BOX,) * 3, _RHO)
    design = FingerDesign()
    return build_scene(obj, design, Stiffness.preset("paper-optimized"), FingerModel.CHAIN, auto_pose(obj))


def test_hold_force_equals_weight(box_scene):
    # Static equilibrium of the lifted box with no ground contact (the palm does not touch it):
    #   sum_i F_z,i (finger contacts) = m g
    scenario = GraspScenario(tendon=TendonForce(tension=10.0), impulse=0.0, hold_s=0.3)
    out = MujocoBackend().run(box_scene, scenario)
    assert out.success, out.reason
    assert not out.ground_contact
    mg = box_scene.obj.mass * _G
    assert out.body_force[5] == pytest.approx(mg, rel=_TOL_HOLD)
    assert abs(out.body_force[3]) < _TOL_HOLD * mg  # no net push along the palm's x


def test_single_rollout_is_deterministic(box_scene):
    scenario = GraspScenario()
    a = MujocoBackend().run(box_scene, scenario)
    b = MujocoBackend().run(box_scene, scenario)
    assert_array_equal(a.body_force, b.body_force)
    assert_array_equal(a.displacement, b.displacement)
    assert a.reason == b.reason
    assert np.all(np.isfinite(a.body_force)) and np.all(np.isfinite(a.displacement))


@pytest.mark.parametrize("nthread", [1, 2])
def test_batched_rollout_equals_single_bitwise(box_scene, nthread):
    # nthread 1 replays the outcomes in this thread on the rollout's own data, 2 on a pool: both must
    # give what a fresh single rollout gives.
    scenario = GraspScenario(impulse=0.0, hold_s=0.1, post_hold_s=0.05)
    designs = [Stiffness.preset("paper-optimized"), Stiffness.preset("soft")]
    outs = MujocoBackend(nthread=nthread).run_batch(box_scene, scenario, designs)
    single = MujocoBackend().run(box_scene, scenario)
    assert_array_equal(outs[0].body_force, single.body_force)
    assert_array_equal(outs[0].displacement, single.displacement)
    soft_scene = build_scene(box_scene.obj, FingerDesign(), designs[1], FingerModel.CHAIN, box_scene.pose)
    soft = MujocoBackend().run(soft_scene, scenario)
    assert_array_equal(outs[1].body_force, soft.body_force)


_TOL_WRENCH = 1e-12  # relative: the same contact forces summed by another formula (round-off only)


def _reference_wrench(scene, d):
    """The fingers' wrench on the object, contact by contact through mj_contactForce and np.cross."""
    import mujoco

    m, ob = scene.model, scene.object_body
    torque, force, fingers, ground = np.zeros(3), np.zeros(3), 0, False
    for i in range(d.ncon):
        c = d.contact[i]
        bodies = [int(m.geom_bodyid[g]) if g >= 0 else -1 for g in c.geom]
        if ob not in bodies:
            continue
        side = 1 if bodies[0] == ob else 0
        g, b, f = int(c.geom[side]), bodies[side], int(c.flex[side])
        ground |= g == scene.ground_geom
        if f < 0 and (b < 0 or b not in scene.finger_bodies):
            continue
        f6 = np.zeros(6)
        mujoco.mj_contactForce(m, d, i, f6)
        frame = c.frame.reshape(3, 3)  # rows: the contact's axes in world
        sign = 1.0 if bodies[1] == ob else -1.0  # the force is geom 1's on geom 2
        fw, tw = sign * frame.T @ f6[:3], sign * frame.T @ f6[3:]
        force += fw
        torque += np.cross(c.pos - d.xipos[ob], fw) + tw
        fingers += 1
    return np.r_[torque, force], fingers, ground


@pytest.mark.parametrize("cone", ["elliptic", "pyramidal"])
def test_finger_wrench_equals_contact_by_contact_sum(box_scene, cone):
    # finger_wrench reads elliptic contact forces from efc_force as arrays; pyramidal cones go through
    # mj_contactForce. Both equal the plain per-contact sum at every 10th step of tighten and hold.
    import copy

    import mujoco

    from mjcodesign.scenarios.grasp import STATE_SPEC, control_spec, phase_controls
    from mjcodesign.scenarios.outcome import finger_wrench
    from mjcodesign.sim.mujoco_c import initial_state

    scene = copy.copy(box_scene)
    scene.model = copy.copy(box_scene.model)
    scene.model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{cone.upper()}")
    m = scene.model
    ctrl, starts = phase_controls(scene, GraspScenario())
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, initial_state(scene), STATE_SPEC)
    checked = 0
    for t in range(starts["impulse"]):
        mujoco.mj_setState(m, d, ctrl[t], control_spec())
        mujoco.mj_step(m, d)
        if t % 10:
            continue
        mujoco.mj_forward(m, d)
        wrench, finger, ground = finger_wrench(scene, d)
        ref, fingers, ref_ground = _reference_wrench(scene, d)
        assert (finger, ground) == (fingers > 0, ref_ground)
        scale = max(np.abs(ref).max(), 1e-9)
        np.testing.assert_allclose(wrench, ref, rtol=0, atol=_TOL_WRENCH * scale)
        checked += fingers > 0
    assert checked >= 10, "too few states with the fingers on the box"


_ALTERNATING = ",".join(["14", "17"] * 11)  # soft segments, stiff flexures (and the reverse on finger B)


@pytest.mark.parametrize(
    "text", ["soft", "semi-rigid", "random:3", "random:11", _ALTERNATING, ",".join(["17", "14"] * 11)]
)
def test_with_stiffness_equals_recompile(box_scene, text):
    """Across the design space: presets, random designs, the extreme alternating ones."""
    design = Stiffness.parse(text)
    m = with_stiffness(box_scene, design)
    ref = build_scene(box_scene.obj, FingerDesign(), design, FingerModel.CHAIN, box_scene.pose).model
    for name in ("jnt_stiffness", "dof_damping", "geom_solref", "body_mass", "body_inertia"):
        assert_array_equal(getattr(m, name), getattr(ref, name), err_msg=name)


def test_with_stiffness_equals_recompile_with_two_hinges_per_block(box_scene):
    box_scene_njnt = box_scene.model.njnt
    obj, two = box_object((_BOX,) * 3, _RHO), SimOptions(hinges_per_block=2)
    pose = auto_pose(obj)
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("soft"), FingerModel.CHAIN, pose, options=two)
    for text in ("random:3", _ALTERNATING):
        design = Stiffness.parse(text)
        ref = build_scene(obj, FingerDesign(), design, FingerModel.CHAIN, pose, options=two).model
        m = with_stiffness(scene, design)
        assert m.njnt == ref.njnt == box_scene_njnt + 2 * 11  # a second hinge in each of 2 x 11 blocks
        for name in ("jnt_stiffness", "dof_damping", "geom_solref", "body_mass", "body_inertia"):
            assert_array_equal(getattr(m, name), getattr(ref, name), err_msg=name)


@pytest.mark.parametrize("hinges", [1, 2])
def test_compiled_hinges_follow_the_one_stiffness_rule(hinges):
    """Each hinge of a compiled chain carries joint_stiffness of its block: n k for n hinges in series
    (the block's compliance 1 / k kept) and Rayleigh damping damping_time · n k, as with_stiffness writes."""
    import mujoco

    from mjcodesign.models.chain import hinge_stiffness, joint_stiffness

    obj, opts = box_object((_BOX,) * 3, _RHO), SimOptions(hinges_per_block=hinges)
    design = Stiffness.parse(_ALTERNATING)
    scene = build_scene(obj, FingerDesign(), design, FingerModel.CHAIN, auto_pose(obj), options=opts)
    m = scene.model
    for h, young in zip(scene.built.fingers, design.young, strict=True):
        jids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in h.joints]
        blocks = np.array(h.joint_blocks)
        assert np.bincount(blocks).tolist() == [hinges] * 11
        k, damping = joint_stiffness(FingerDesign(), young, opts)
        assert_array_equal(m.jnt_stiffness[jids], k[blocks])
        assert_array_equal(m.dof_damping[m.jnt_dofadr[jids]], damping[blocks])
        # in series: 1 / k_block = sum over the block's hinges of 1 / k_hinge
        np.testing.assert_allclose(
            1.0 / np.bincount(blocks, weights=1.0 / m.jnt_stiffness[jids]),
            hinge_stiffness(FingerDesign(), young, opts.stiffness_model),
            rtol=1e-12,
        )
        np.testing.assert_allclose(
            m.dof_damping[m.jnt_dofadr[jids]], opts.damping_time * m.jnt_stiffness[jids]
        )


def test_pose_below_ground_is_refused(box_scene):
    pose = GripperPose((0.0, 0.0, 0.1), (1.0, 0.0, 0.0, 0.0), (0.02, 0.02))
    with pytest.raises(PoseError, match="below the ground"):
        build_scene(box_scene.obj, FingerDesign(), Stiffness.preset("soft"), FingerModel.CHAIN, pose)


def test_object_too_wide_is_refused():
    with pytest.raises(PoseError, match="too big"):
        auto_pose(box_object((0.05, 0.13, 0.05), _RHO))  # 130 mm along the closing axis


def test_impulse_is_one_step_of_force(box_scene):
    # xfrc_applied for one step of dt: ∫ F dt = -J ẑ on the object, nothing else pushed.
    from mjcodesign.scenarios.grasp import phase_controls

    scenario = GraspScenario(impulse=0.2)
    ctrl, starts = phase_controls(box_scene, scenario)
    m = box_scene.model
    xfrc = ctrl[:, m.nu :].reshape(len(ctrl), m.nbody, 6)
    assert xfrc.sum(axis=0)[box_scene.object_body, 2] * m.opt.timestep == pytest.approx(-0.2, rel=1e-12)
    assert np.count_nonzero(xfrc) == 1 and xfrc[starts["impulse"], box_scene.object_body, 2] != 0


def test_bench_grasp_smoke(tmp_path):
    import trimesh

    from mjcodesign.bench.grasp import bench_grasp

    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(path)
    res = bench_grasp("chain", str(path), rollouts=2, cache_dir=tmp_path)
    assert res["raw_rollouts_per_s"] > 0 and res["rollouts_per_s"] > 0 and res["rollouts"] == 2


def test_hold_force_is_measured_before_the_impulse(box_scene):
    # Everything before the impulse step is identical, so the hold-phase wrench must be bitwise equal.
    quiet = MujocoBackend().run(box_scene, GraspScenario(impulse=0.0))
    kicked = MujocoBackend().run(box_scene, GraspScenario(impulse=0.4))
    assert_array_equal(quiet.body_force, kicked.body_force)


@pytest.mark.slow
def test_flex_grasp_smoke():
    # Flex fingers are ~100x slower than the chain: a 0.2-s scenario only checks that it runs clean.
    obj = box_object((_BOX,) * 3, _RHO)
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.FLEX, auto_pose(obj))
    scenario = GraspScenario(
        settle_s=0.02, close_s=0.06, tighten_s=0.04, lift_s=0.04, hold_s=0.02, impulse=0.0, post_hold_s=0.02
    )
    out = MujocoBackend().run(scene, scenario)
    assert not out.reason.startswith("diverged"), out.reason
    assert np.all(np.isfinite(out.body_force)) and np.all(np.isfinite(out.displacement))


_TOL_POSE_MODEL = 1e-12  # relative: a moved model vs a recompile differ only by round-off at qpos0


def test_scene_at_pose_equals_recompile(box_scene):
    from mjcodesign.scenarios.grasp import scene_at_pose

    p0 = box_scene.pose
    half = 0.15  # half of a 0.3 rad yaw
    pose = GripperPose(
        (0.003, -0.002, p0.position[2] + 0.01), (np.cos(half), 0.0, 0.0, np.sin(half)), (0.02, 0.021)
    )
    moved = scene_at_pose(box_scene, pose).model
    ref = build_scene(box_scene.obj, FingerDesign(), box_scene.built.stiffness, FingerModel.CHAIN, pose).model
    compared = 0
    for name in dir(ref):
        value = getattr(ref, name, None)
        if name.startswith("_") or name == "light_poscom0" or not isinstance(value, np.ndarray):
            continue  # light_poscom0 only places lights
        np.testing.assert_allclose(getattr(moved, name), value, rtol=_TOL_POSE_MODEL, atol=0, err_msg=name)
        compared += 1
    assert compared > 100


def test_pose_batch_equals_single_bitwise(box_scene):
    from mjcodesign.scenarios.grasp import scene_at_pose

    scenario = GraspScenario(hold_s=0.05, post_hold_s=0.05)
    p0 = box_scene.pose
    poses = [p0, GripperPose((0.002, 0.0, p0.position[2]), p0.quat, (p0.openings[0] + 0.002, p0.openings[1]))]
    outs = MujocoBackend(nthread=2).run_poses(box_scene, scenario, poses)
    for pose, out in zip(poses, outs, strict=True):
        single = MujocoBackend().run(scene_at_pose(box_scene, pose), scenario)
        assert_array_equal(out.body_force, single.body_force)
        assert_array_equal(out.displacement, single.displacement)
        assert out.reason == single.reason
    assert not np.array_equal(outs[0].object_path, outs[1].object_path)


def test_both_batching_backends_share_run_poses(box_scene):
    """run_poses is one method of the scene-batching base: the posed scenes through run_scenes, each
    handed to the observer as pose{i}."""
    from mjcodesign.scenarios.grasp import scene_at_pose
    from mjcodesign.sim import MjwarpBackend, SceneBatchSimulator

    assert MujocoBackend.run_poses is MjwarpBackend.run_poses is SceneBatchSimulator.run_poses

    class Labels:
        def __init__(self):
            self.seen = []

        def rollout(self, r):
            self.seen.append(r.label)

    scenario = GraspScenario(
        impulse=0.0, settle_s=0.0, close_s=0.02, tighten_s=0.02, lift_s=0.02, hold_s=0.02
    )
    p0 = box_scene.pose
    poses = [p0, GripperPose((0.002, 0.0, p0.position[2]), p0.quat, p0.openings)]
    spy = Labels()
    outs = MujocoBackend(nthread=1).run_poses(box_scene, scenario, poses, observer=spy)
    ref = MujocoBackend(nthread=1).run_scenes([scene_at_pose(box_scene, p) for p in poses], scenario)
    assert spy.seen == ["pose0", "pose1"]
    for a, b in zip(outs, ref, strict=True):
        assert_array_equal(a.object_path, b.object_path)


def test_batch_flags_a_diverged_rollout(box_scene):
    # An undamped hinge 1e6 times too stiff blows up the explicit spring; MuJoCo then resets that
    # rollout's data (its clock restarts), which the batch must report, not average into outcomes.
    # One thread: the good rollout that follows on the same MjData clears the bad one's warning.
    from mjcodesign.sim.mujoco_c import scene_with_model

    bad = with_stiffness(box_scene, Stiffness.preset("soft"))
    bad.jnt_stiffness[:] *= 1e6
    bad.dof_damping[:] = 0.0
    scenario = GraspScenario(hold_s=0.02, post_hold_s=0.02)
    outs = MujocoBackend(nthread=1).run_scenes([scene_with_model(box_scene, bad), box_scene], scenario)
    assert outs[0].reason.startswith("diverged") and not outs[0].success
    assert not outs[1].reason.startswith("diverged")
    # Re-run alone, step by step after the unchecked pass saw the warning: the first bad step is named.
    assert re.fullmatch(r"diverged: step \d+: MuJoCo warning \w+ at t=.*", outs[0].reason), outs[0].reason


def test_default_impulse_is_the_papers_at_real_scale():
    # J = J_paper / (s³/50 · √s): the authors' 0.1 N s on a 5x scene at 1/50 of our density, Froude-scaled.
    from mjcodesign.scenarios.grasp import DEFAULT_IMPULSE, paper_impulse

    assert DEFAULT_IMPULSE == pytest.approx(0.1 / (125 / 50 * 5**0.5), rel=1e-12)
    assert GraspScenario().impulse == DEFAULT_IMPULSE
    assert paper_impulse(0.4) == pytest.approx(4 * DEFAULT_IMPULSE, rel=1e-12)


@pytest.mark.slow
def test_flex_contacts_count_as_finger_contacts():
    # A contact on a flex has geom -1 on the flex side; it must count as a finger touching the object
    # (geom_bodyid[-1] would name the object itself). Step until the closing fingers touch the box.
    import mujoco

    from mjcodesign.scenarios.grasp import STATE_SPEC, control_spec, phase_controls
    from mjcodesign.scenarios.outcome import finger_wrench
    from mjcodesign.sim.mujoco_c import initial_state

    obj = box_object((_BOX,) * 3, _RHO)
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.FLEX, auto_pose(obj))
    m = scene.model
    ctrl, starts = phase_controls(scene, GraspScenario())
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, initial_state(scene), STATE_SPEC)
    for t in range(starts["lift"]):
        mujoco.mj_setState(m, d, ctrl[t], control_spec())
        mujoco.mj_step(m, d)
        if np.any(np.asarray(d.contact.flex) >= 0):
            break
    flex_on_object = [
        i
        for i in range(d.ncon)
        if max(d.contact.flex[i]) >= 0
        and scene.object_body in m.geom_bodyid[d.contact.geom[i][d.contact.geom[i] >= 0]]
    ]
    assert flex_on_object, "the flex fingers never touched the box"
    wrench, finger, _ = finger_wrench(scene, d)
    assert finger and np.linalg.norm(wrench[3:]) > 0


_TOL_FLEX_RECORD = 1e-12  # relative: a rescaled flex stiffness record vs a recompile (round-off only)


def test_flex_with_stiffness_equals_recompile():
    obj = box_object((_BOX,) * 3, _RHO)
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.FLEX, auto_pose(obj))
    other = Stiffness.preset("paper-optimized")
    m = with_stiffness(scene, other)
    ref = build_scene(obj, FingerDesign(), other, FingerModel.FLEX, scene.pose).model
    assert not np.allclose(m.flex_stiffness, scene.model.flex_stiffness, rtol=0.1)  # the design changed
    np.testing.assert_allclose(m.flex_stiffness, ref.flex_stiffness, rtol=_TOL_FLEX_RECORD, atol=0)
    for name in ("flex_damping", "body_mass", "jnt_stiffness", "geom_solref"):
        assert_array_equal(getattr(m, name), getattr(ref, name), err_msg=name)


_TOL_JACOBIAN = 0.01  # hold force vs m g: sparse and dense Jacobians differ by round-off only (≤ 0.09% on
# 12 designs, docs/benchmarks.md), which contact events may amplify over a rollout


def test_grasp_scene_is_sparse_and_matches_dense(box_scene):
    import copy

    import mujoco

    from mjcodesign.sim.mujoco_c import scene_with_model

    assert box_scene.model.opt.jacobian == mujoco.mjtJacobian.mjJAC_SPARSE
    dense = copy.copy(box_scene.model)
    dense.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    scenario = GraspScenario(impulse=0.0)
    a = MujocoBackend().run(box_scene, scenario)
    b = MujocoBackend().run(scene_with_model(box_scene, dense), scenario)
    mg = box_scene.obj.mass * _G
    assert a.success and b.success
    np.testing.assert_allclose(a.body_force[3:], b.body_force[3:], rtol=0, atol=_TOL_JACOBIAN * mg)
