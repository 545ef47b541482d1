"""GraspJob / run_jobs: grouping into batches, job order, and bitwise equality with single runs."""

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, PoseError
from mjcodesign.jobs import GraspJob, run_jobs
from mjcodesign.models.types import FingerModel, GripperPose
from mjcodesign.objects import box_object
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose
from mjcodesign.scenarios.outcome import Failure
from mjcodesign.sim import MujocoBackend

_SCENARIO = GraspScenario(impulse=0.0, hold_s=0.06, post_hold_s=0.02, lift_s=0.1)  # short: a test
# A hold force equal to m g needs a settled hold: after a 0.1-s lift the box still swings in the 0.06-s
# hold (|F| 1.6 m g measured on the FEM-calibrated chain); a 0.2-s lift and a 0.1-s hold settle it.
_SETTLED = GraspScenario(impulse=0.0, hold_s=0.1, post_hold_s=0.02, lift_s=0.2)


class _Spy:
    """A simulator that forwards to MuJoCo C and records which batch call each group went to."""

    name = "spy"

    def __init__(self):
        self.inner = MujocoBackend(nthread=2)
        self.calls = []

    def run(self, scene, scenario, *, observer=None, label="grasp"):
        self.calls.append(("run", 1))
        return self.inner.run(scene, scenario, observer=observer, label=label)

    def run_batch(self, scene, scenario, stiffnesses, *, observer=None, labels=None):
        self.calls.append(("run_batch", len(stiffnesses)))
        return self.inner.run_batch(scene, scenario, stiffnesses, observer=observer, labels=labels)

    def run_poses(self, scene, scenario, poses, *, observer=None, labels=None):
        self.calls.append(("run_poses", len(poses)))
        return self.inner.run_poses(scene, scenario, poses, observer=observer, labels=labels)


@pytest.fixture(scope="module")
def box():
    return box_object((0.05, 0.05, 0.05), 400.0)


def _pose(box, dz=0.0, dx=0.0):
    p = auto_pose(box)
    return GripperPose((p.position[0] + dx, p.position[1], p.position[2] + dz), p.quat, p.openings)


def _assert_same(a, b):
    assert a.success == b.success and a.reason == b.reason and a.failures == b.failures
    assert_array_equal(a.body_force, b.body_force)
    assert_array_equal(a.displacement, b.displacement)
    assert a.lift_height == b.lift_height and a.ground_contact == b.ground_contact
    assert_array_equal(a.object_path, b.object_path)


def test_run_jobs_groups_batches_and_keeps_order_bitwise(box):
    soft, semi, paper = (Stiffness.preset(n) for n in ("soft", "semi-rigid", "paper-optimized"))
    rnd = Stiffness.random(3)
    p0, p1, p2, p3 = _pose(box), _pose(box, dz=0.004), _pose(box, dx=0.003), _pose(box, dx=-0.003)
    # p0: three designs -> one run_batch; rnd alone at p1 and p3 -> one run_poses; paper alone at p2 -> run
    spec = [(p0, soft), (p1, rnd), (p0, semi), (p2, paper), (p0, paper), (p3, rnd)]
    jobs = [GraspJob(obj=box, pose=p, design=d, scenario=_SCENARIO) for p, d in spec]
    spy = _Spy()
    outs = run_jobs(jobs, spy)
    assert spy.calls == [("run_batch", 3), ("run_poses", 2), ("run", 1)]
    assert len(outs) == len(jobs)
    for job, out in zip(jobs, outs, strict=True):
        alone = run_jobs([job], MujocoBackend(nthread=1))[0]
        _assert_same(out, alone)
    assert np.all([np.isfinite(o.body_force).all() for o in outs])
    assert any(o.success for o in outs)  # the short scenario still holds the box for some design


def test_density_override_scales_mass_only(box):
    light = dataclasses.replace(box, hulls=list(box.hulls))
    job = GraspJob(obj=light, pose=_pose(box), design=Stiffness.preset("paper-optimized"), scenario=_SETTLED)
    heavy = dataclasses.replace(job, density=2 * box.density)
    assert heavy.rho == 2 * box.density and job.rho == box.density
    a, b = run_jobs([job, heavy], MujocoBackend(nthread=2))
    # A held object: the vertical finger force is m g, so doubling the density doubles it (within the
    # hold-force tolerance of tests/test_grasp.py, 5%).
    assert a.success and b.success, (a.reason, b.reason)
    if a.success and b.success:
        assert b.body_force[5] == pytest.approx(2 * a.body_force[5], rel=0.05)
    assert a.body_force != b.body_force


def test_bad_pose_is_an_outcome_or_raises_when_strict(box):
    good = _pose(box)
    below = GripperPose((0.0, 0.0, 0.05), good.quat, good.openings)  # fingertips under the ground
    jobs = [GraspJob(obj=box, pose=p, design=Stiffness.preset("soft"), scenario=_SCENARIO) for p in (below, good)]
    outs = run_jobs(jobs, MujocoBackend(nthread=1))
    assert outs[0].failures == (Failure.BAD_POSE,) and not outs[0].success
    assert outs[0].failure.is_sample_error and "below the ground" in outs[0].reason
    assert outs[1].failure is not Failure.BAD_POSE
    with pytest.raises(PoseError, match="below the ground"):
        run_jobs(jobs, MujocoBackend(nthread=1), strict=True)


def test_job_validation(box):
    p = _pose(box)
    with pytest.raises(DesignError):
        GraspJob(obj=box, pose=p, design=Stiffness.preset("soft"), density=float("nan"))
    with pytest.raises(DesignError):
        GraspJob(obj=box, pose=p, design=Stiffness.preset("soft"), seed=-1)
    with pytest.raises(DesignError):
        GraspJob(obj=box, pose=p, design="soft")
    job = GraspJob(obj=box, pose=p, design=Stiffness.preset("soft"), finger_model="chain")
    assert job.finger_model is FingerModel.CHAIN
    with pytest.raises(dataclasses.FrozenInstanceError):
        job.seed = 3


def test_an_outcome_does_not_depend_on_the_rollout_before_it(box):
    """The same design alone and after another in one batch on one thread (one reused MjData): the same
    outcome, energy bound included. MuJoCo's kinetic-energy sensor lags a step and at step 0 reads what
    the data last held, which once made the soft design IMPLAUSIBLE alone and not after log E 14."""
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.models.types import FingerModel
    from mjcodesign.scenarios.grasp import build_scene

    soft, other = Stiffness.preset("soft"), Stiffness(np.full(22, 14.0))
    scene = build_scene(box, FingerDesign(), soft, FingerModel.CHAIN, _pose(box))
    sim = MujocoBackend(nthread=1)
    alone = sim.run_batch(scene, _SCENARIO, [soft])[0]
    after = sim.run_batch(scene, _SCENARIO, [other, soft])[1]
    _assert_same(alone, after)


class _ScenesOnly:
    """MuJoCo C without ``run_scene_chunks``: perturbed jobs go through ``run_scenes``, one call."""

    name = "scenes-only"

    def __init__(self):
        self.inner = MujocoBackend(nthread=2)

    def run(self, scene, scenario, *, observer=None, label="grasp"):
        return self.inner.run(scene, scenario, observer=observer, label=label)

    def run_scenes(self, scenes, scenario, *, observer=None, labels=None):
        return self.inner.run_scenes(scenes, scenario, observer=observer, labels=labels)


def _perturbed_jobs(box, n_draws=3):
    from mjcodesign.scenarios.perturb import PerturbationModel

    model, rng = PerturbationModel(), np.random.default_rng(5)
    designs = [Stiffness.preset("soft"), Stiffness.preset("semi-rigid"), Stiffness.random(4)]
    return [
        GraspJob(obj=box, pose=pose, design=d, scenario=_SCENARIO, perturbation=p)
        for pose in (_pose(box), _pose(box, dx=0.003))
        for p in [model.draw(rng) for _ in range(n_draws)]
        for d in designs
    ]


def test_pipelined_chunks_give_the_outcomes_of_one_call(box, monkeypatch):
    """Chunks of 4 (a draw's designs split across chunks, the rollout of one chunk overlapping the
    next chunk's build and the last chunk's outcomes) against every scene in one ``run_scenes`` call."""
    import mjcodesign.jobs as jobs_module

    jobs = _perturbed_jobs(box)
    one_call = run_jobs(jobs, _ScenesOnly())
    monkeypatch.setattr(jobs_module, "_PIPELINE_CHUNK", 4)
    backend = MujocoBackend(nthread=2)
    chunks = []
    inner = backend.run_scene_chunks

    def counted(stream, scenario, *, observer=None):
        for out in inner(stream, scenario, observer=observer):
            chunks.append(len(out))
            yield out

    monkeypatch.setattr(backend, "run_scene_chunks", counted)
    piped = run_jobs(jobs, backend)
    assert chunks == [4, 4, 4, 4, 2]
    for a, b in zip(piped, one_call, strict=True):
        _assert_same(a, b)


def test_a_kept_perturbed_scene_is_rolled_out_not_built_again(box, monkeypatch):
    import mjcodesign.jobs as jobs_module
    from mjcodesign.jobs import SceneCache
    from mjcodesign.scenarios.perturb import perturbed_scene

    jobs = _perturbed_jobs(box, n_draws=1)[:3]  # one (pose, draw), three designs
    fresh = run_jobs(jobs, MujocoBackend(nthread=2))
    cache = SceneCache()
    base = cache.scene(jobs[0])
    job = jobs[0]
    kept = perturbed_scene(base, job.scenario, job.perturbation, pose=job.pose)
    cache.keep_perturbed(base, job.scenario, job.pose, job.perturbation, kept)

    def refuse(*args, **kwargs):
        raise AssertionError("the kept scene was built again")

    monkeypatch.setattr(jobs_module, "perturbed_scene", refuse)
    again = run_jobs(jobs, MujocoBackend(nthread=2), scenes=cache)
    for a, b in zip(again, fresh, strict=True):
        _assert_same(a, b)
    with pytest.raises(AssertionError, match="built again"):  # taken once: the next run builds it
        run_jobs(jobs, MujocoBackend(nthread=2), scenes=cache)


def test_a_rerun_waits_for_the_rollout_in_flight(box, monkeypatch):
    """A chunk whose rollout must be rerun step by step (here: its first scene marked diverged) reruns
    only once the next chunk's rollout has ended, so that no other rollout's MuJoCo warning can reach the
    rerun's; the outcomes are still those of one call."""
    import mjcodesign.jobs as jobs_module
    import mjcodesign.sim.mujoco_c as mc

    jobs = _perturbed_jobs(box, n_draws=2)
    one_call = run_jobs(jobs, _ScenesOnly())
    monkeypatch.setattr(jobs_module, "_PIPELINE_CHUNK", 4)
    in_flight, calls, seen = [0], [0], []
    real_rollout, real_diverged = mc.mj_rollout.rollout, mc._diverged

    def counted(*args, **kwargs):
        in_flight[0] += 1
        try:
            return real_rollout(*args, **kwargs)
        finally:
            in_flight[0] -= 1

    def first_call_first_scene(states, x0, dt):
        bad = real_diverged(states, x0, dt)
        calls[0] += 1
        if calls[0] == 1:
            bad[0] = True
        return bad

    class Watched(MujocoBackend):
        def run(self, scene, scenario, *, observer=None, label="grasp"):
            seen.append(in_flight[0])
            return super().run(scene, scenario, observer=observer, label=label)

    monkeypatch.setattr(mc.mj_rollout, "rollout", counted)
    monkeypatch.setattr(mc, "_diverged", first_call_first_scene)
    piped = run_jobs(jobs, Watched(nthread=2))
    assert seen == [0]  # one rerun, with no rollout in flight
    for a, b in zip(piped, one_call, strict=True):
        _assert_same(a, b)
