"""MuJoCo Warp (CPU) against MuJoCo C on the same designs and pose. Skips without mujoco_warp.

The first run compiles Warp kernels on the CPU (about 90 s here); Warp caches them.
"""

import numpy as np
import pytest

pytest.importorskip("mujoco_warp")

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models.types import FingerModel, GripperPose
from mjcodesign.objects import box_object
from mjcodesign.scenarios.drive import TendonForce
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene
from mjcodesign.sim import MujocoBackend
from mjcodesign.sim.mjwarp import MjwarpBackend

_TOL_PATH = 5e-4  # object COM path [m]: float32 MJWarp vs float64 MuJoCo C, 0.5 mm over ~0.4 s
_TOL_FORCE = 0.05  # relative, hold force along the palm z
# The palm height the parity was measured at (141 mm: the fingers' 136 mm plus 5 mm of clearance). The
# auto pose now uses the finger's exact length (136.35 mm) and sits 0.35 mm higher; there the box is
# held less firmly and float32 MJWarp parts from MuJoCo C by 9 mm in its final COM (a marginal grasp, as
# the second test's note says), so the parity tests keep the pose they were measured at.
_PALM_Z = 0.141


def _pose(obj):
    p = auto_pose(obj)
    return GripperPose((p.position[0], p.position[1], _PALM_Z), p.quat, p.openings)


@pytest.mark.slow
def test_mjwarp_matches_mujoco_c():
    obj = box_object((0.05,) * 3, 400.0)
    # With the tendon's lever held constant every design tried holds this box at 10 N (uniform
    # log E 13.5-17 and random:0..23, measured), so the failure branch runs at 3 N, where none grips it:
    # log E 15.0 never touches it ("zero finger force"), 16.0 touches it and leaves it on the ground
    # (paths 5e-8 and 6e-8 m apart, measured). Not used: 17.0 touches it marginally (1.1 mm apart in
    # float32), and at 13.5 MJWarp's untouched box slid 1.0 mm sideways as it settled where MuJoCo C's
    # stayed put, in batches of one or two worlds but not of five (not traced).
    scene = build_scene(
        obj, FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.CHAIN, _pose(obj)
    )
    # A short scenario: close, tighten, lift, hold; the impulse is left out to keep the CPU run short.
    short = dict(
        settle_s=0.05, close_s=0.1, tighten_s=0.1, lift_s=0.1, hold_s=0.06, impulse=0.0, post_hold_s=0.02
    )
    batches = (
        (GraspScenario(**short), [Stiffness.preset("paper-optimized"), Stiffness(np.full((2, 11), 14.0))]),
        (
            GraspScenario(tendon=TendonForce(tension=3.0), **short),
            [Stiffness(np.full((2, 11), v)) for v in (15.0, 16.0)],
        ),
    )
    for (scenario, designs), success in zip(batches, ([True, True], [False, False]), strict=True):
        ref = MujocoBackend().run_batch(scene, scenario, designs)
        got = MjwarpBackend("cpu").run_batch(scene, scenario, designs)
        assert [o.success for o in ref] == [o.success for o in got] == success
        for a, b in zip(ref, got, strict=True):
            # The kinds of failure; the reasons' numbers are rounded (-0.65 mm reads -0.7 or -0.6).
            assert a.failures == b.failures
            assert a.ground_contact == b.ground_contact and a.finger_contact == b.finger_contact
            np.testing.assert_allclose(b.object_path, a.object_path, atol=_TOL_PATH, rtol=0)
            np.testing.assert_allclose(b.displacement, a.displacement, atol=_TOL_PATH, rtol=0)
            if a.success:
                assert b.body_force[5] == pytest.approx(a.body_force[5], rel=_TOL_FORCE)
    assert ref[0].failures != ref[1].failures  # two different failures


@pytest.mark.slow
def test_mjwarp_pose_batch_matches_mujoco_c():
    # Two poses of one design as two worlds (batched body_pos/body_quat, per-world state and controls).
    obj = box_object((0.05,) * 3, 400.0)
    p0 = _pose(obj)
    # The second pose sits 13 mm off the object's centre along the palm's x: another contact patch and
    # a path 0.87 mm from the first pose's on the FEM-calibrated chain (measured; 3 mm off, the offset
    # used before, now parts by only 0.14 mm, 10 mm by 0.60 mm, so the poses would not differ beyond the
    # path tolerance). MuJoCo C and MJWarp part by 2.4 µm there. (Poses where the grasp is marginal, e.g.
    # 3 mm off along the closing axis or 5 mm higher, differed by 0.65 mm or in success between float32
    # and float64.)
    poses = [p0, GripperPose((0.013, 0.0, p0.position[2]), p0.quat, p0.openings)]
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.CHAIN, p0)
    scenario = GraspScenario(
        settle_s=0.05, close_s=0.1, tighten_s=0.1, lift_s=0.1, hold_s=0.06, impulse=0.0, post_hold_s=0.02
    )
    ref = MujocoBackend().run_poses(scene, scenario, poses)
    got = MjwarpBackend("cpu").run_poses(scene, scenario, poses)
    assert not np.allclose(ref[0].object_path, ref[1].object_path, atol=_TOL_PATH, rtol=0)  # poses differ
    for a, b in zip(ref, got, strict=True):
        assert a.reason == b.reason and a.success == b.success
        np.testing.assert_allclose(b.object_path, a.object_path, atol=_TOL_PATH, rtol=0)
        np.testing.assert_allclose(b.displacement, a.displacement, atol=_TOL_PATH, rtol=0)


def test_mjwarp_refuses_mixed_flex_designs_in_one_batch():
    from mjcodesign.errors import UnsupportedError

    obj = box_object((0.05,) * 3, 400.0)
    scenes = [
        build_scene(obj, FingerDesign(), Stiffness.preset(p), FingerModel.FLEX, auto_pose(obj))
        for p in ("semi-rigid", "soft")
    ]
    with pytest.raises(UnsupportedError, match="flex stiffness"):
        MjwarpBackend("cpu").run_scenes(scenes, GraspScenario())


_FLEX_STEPS = 2  # steps per phase: settle, close, tighten, lift, hold (13 steps with the first state)
_TOL_FLEX_PATH = 5e-4  # flex node and object positions [m] after 13 steps, as the chain's path tolerance


@pytest.fixture(scope="module")
def flex_runs():
    """MuJoCo C and MJWarp (CPU, 2 poses as 2 worlds) on the trilinear flex, a 13-step horizon.

    A whole flex rollout takes ~20 min on Warp's CPU device; the first steps (28 s with compiled kernels)
    already show the difference below.
    """
    from mjcodesign.models.types import GripperPose
    from mjcodesign.scenarios.grasp import scene_at_pose

    obj = box_object((0.05,) * 3, 400.0)
    p0 = auto_pose(obj)
    poses = [p0, GripperPose((0.003, 0.0, p0.position[2]), p0.quat, p0.openings)]
    scene = build_scene(obj, FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.FLEX, p0)
    n = _FLEX_STEPS * scene.model.opt.timestep
    scenario = GraspScenario(
        settle_s=n, close_s=n, tighten_s=n, lift_s=n, hold_s=n, impulse=0.0, post_hold_s=0.0
    )
    scenes = [scene_at_pose(scene, p) for p in poses]
    ref, got = _Keep(), _Keep()
    MujocoBackend().run_scenes(scenes, scenario, observer=ref)
    MjwarpBackend("cpu").run_scenes(scenes, scenario, observer=got)
    return scene, ref.rollouts, got.rollouts


@pytest.mark.slow
def test_mjwarp_flex_batches_poses(flex_runs):
    scene, ref, got = flex_runs
    m = scene.model
    assert len(got) == 2
    adr = m.jnt_qposadr[m.body_jntadr[scene.object_body]]
    for a, b in zip(ref, got, strict=True):
        assert b.states.shape == a.states.shape and np.all(np.isfinite(b.states))
        # The object rests on the ground, untouched yet: its position agrees in both backends.
        obj = slice(1 + adr, 1 + adr + 3)
        np.testing.assert_allclose(b.states[:, obj], a.states[:, obj], atol=_TOL_FLEX_PATH)
    # Two poses, two worlds: the palm sits 3 mm apart, so the fingers' states differ between worlds.
    assert not np.allclose(got[0].states, got[1].states)


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="measured (MJWarp 4.0 on Warp's CPU device vs MuJoCo C 4.0, discrete integrator): flex node "
    "positions differ by 0.056 mm after 6 steps and 0.70 mm after 13, growing ~2.5x a step at first; "
    "MuJoCo C itself is not that sensitive (a 1e-7 m perturbation, or rounding the state to float32 "
    "every step, moves it by <= 3 um over the same steps)",
)
def test_mjwarp_flex_matches_mujoco_c(flex_runs):
    scene, ref, got = flex_runs
    m = scene.model
    for a, b in zip(ref, got, strict=True):
        np.testing.assert_allclose(b.states[:, 1 : 1 + m.nq], a.states[:, 1 : 1 + m.nq], atol=_TOL_FLEX_PATH)


class _Keep:
    """An observer that keeps what it is handed (no Rerun needed)."""

    def __init__(self):
        self.rollouts = []

    def rollout(self, rollout):
        self.rollouts.append(rollout)

    def close(self):
        pass


@pytest.mark.slow
def test_mjwarp_hands_every_step_to_an_observer():
    import mujoco

    from mjcodesign.scenarios.grasp import STATE_SPEC

    obj = box_object((0.05,) * 3, 400.0)
    scene = build_scene(
        obj, FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.CHAIN, auto_pose(obj)
    )
    scenario = GraspScenario(
        settle_s=0.02, close_s=0.05, tighten_s=0.05, lift_s=0.05, hold_s=0.02, impulse=0.0, post_hold_s=0.01
    )
    keep = _Keep()
    out = MjwarpBackend("cpu").run(scene, scenario, observer=keep, label="mjwarp")
    (r,) = keep.rollouts
    assert r.label == "mjwarp" and r.outcome is out
    assert r.states.shape == (len(r.ctrl), r.x0.size) and np.all(np.isfinite(r.states))
    np.testing.assert_allclose(r.states[:, 0], scene.model.opt.timestep * np.arange(1, len(r.ctrl) + 1))
    # The handed-over states are the ones the outcome read: the object's last COM is the path's last.
    d = mujoco.MjData(scene.model)
    mujoco.mj_setState(scene.model, d, r.states[-1], STATE_SPEC)
    mujoco.mj_forward(scene.model, d)
    np.testing.assert_array_equal(d.xipos[scene.object_body], out.object_path[-1])


@pytest.mark.slow
def test_grasp_cli_runs_backends_side_by_side(tmp_path):
    import json
    import subprocess
    import sys

    import trimesh

    box = tmp_path / "box.stl"
    trimesh.creation.box((0.05, 0.05, 0.05)).export(box)
    rrd = tmp_path / "b.rrd"
    args = ["--object", str(box), "--backend", "mujoco,mjwarp", "--impulse", "0", "--json", "--rrd", str(rrd)]
    r = subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", "grasp", *args], capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stderr
    ref, got = json.loads(r.stdout)  # stdout is JSON only: Warp's module-load log stays off it
    assert (ref["backend"], got["backend"]) == ("mujoco", "mjwarp")
    assert ref["success"] == got["success"] and ref["reason"] == got["reason"]
    np.testing.assert_allclose(got["displacement"], ref["displacement"], atol=_TOL_PATH, rtol=0)
    rr = pytest.importorskip("rerun")
    roots = {
        "/".join(str(c.entity_path).split("/")[:3]) for c in rr.chunk.RrdReader(rrd).stream().to_chunks()
    }
    assert {"/designs/paper-optimized_mujoco", "/designs/paper-optimized_mjwarp"} <= roots
