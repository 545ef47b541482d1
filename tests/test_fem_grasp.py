"""The Warp FEM's two-finger grasp of a free object (`mjcodesign.sim.fem.gripper_grasp`).

Physics against closed forms (a held object's weight), the schedule against MuJoCo's own servos, the
recorded forward pass against the taped one (bitwise), the L_opt gradient against central differences,
the simulator protocol, and the CI version of the grasp agreement study.
"""

import dataclasses

import numpy as np
import pytest

pytest.importorskip("warp")

from mjcodesign.design.finger import FingerDesign  # noqa: E402
from mjcodesign.design.stiffness import Stiffness  # noqa: E402
from mjcodesign.models.types import FingerModel  # noqa: E402
from mjcodesign.objects import box_object  # noqa: E402
from mjcodesign.scenarios.drive import TendonForce  # noqa: E402
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene  # noqa: E402
from mjcodesign.scenarios.outcome import Failure  # noqa: E402

_G = 9.81
_TOL_WEIGHT = 0.05
"""The target: a held object's vertical finger force equals m·g within 5% (measured 0.2–0.7%)."""
_TOL_LATERAL = 0.05
"""Horizontal finger force on the held box as a fraction of m·g (closed form 0; measured < 1%)."""
_TOL_SERVO = 2e-4
"""[m] Finger base against MuJoCo's carriage before tightening: the schedule solves the opening servo's
linear response exactly; MuJoCo also swings the chain's hinges on the carriage (measured ≤ 0.1 mm)."""
_TOL_GRAD = 1e-4
"""Adjoint vs central differences with a ln E step of 1e-5 (relative). Measured ≤ 1e-6 on all 22 ln E;
a step of 1e-4 is too coarse here (its differences move by up to 0.7% from the 1e-5 ones: the penalty
contact's kinks, a vertex entering contact between the perturbed runs)."""
_TOL_SERVO_LAW = 1e-3
"""Position-mode tension at the last substep against the servo law at the length that substep read
(relative): the final length less ℓ̇·dt, to first order in dt (measured 9e-6 with it; 1.1e-3 without,
at the 8 mm horn's stiffer servo, where the tendon still moves at 13 mm/s at the end)."""
_BOX = (0.04, 0.04, 0.06)
"""The test box [m]; at the light density it weighs 9.6 g."""
_BRIEF = dict(settle_s=0.0, close_s=0.002, tighten_s=0.004, lift_s=0.004, hold_s=0.008, post_hold_s=0.002)
"""Phases [s] of a 20 ms grasp that starts in contact: every phase, at 2,200 substeps of 10 µs."""


def _coarse(**kw):
    from mjcodesign.sim.fem import FemOptions

    # 10 mm cells, 8 mm in flexures: 396 vertices a finger, about as coarse as the authors' mesh.
    return FemOptions(h=10e-3, h_flexure=8e-3, spine_layers=2, waypoint_layers=False, **kw)


def _box_scene(design: str, start: float):
    obj = box_object(_BOX, 100.0)
    d = FingerDesign()
    scene = build_scene(obj, d, Stiffness.preset(design), FingerModel.CHAIN, auto_pose(obj, d))
    # Start the fingers close to the box (2 mm out from its side at the base) to keep the test short.
    return dataclasses.replace(scene, start_openings=(start, start))


@pytest.fixture(scope="module")
def held():
    """Semi-rigid fingers close on the 9.6 g box at 2 N, lift it 1 cm and hold it 0.3 s."""
    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    scene = _box_scene("semi-rigid", 0.022)
    phases = dict(settle_s=0.004, close_s=0.03, tighten_s=0.05, lift_s=0.05, hold_s=0.3, post_hold_s=0.0)
    scenario = GraspScenario(**phases, tendon=TendonForce(tension=2.0), lift=0.01, impulse=0.0)
    # 10 µs with selective mass scaling: the weight balance is a static law, whatever the finger's inertia.
    grasp = FemGrasp(scene, scenario, options=_coarse(), dynamics=FemDynamics(dt=1e-5))
    return grasp, grasp.run()


def test_held_box_vertical_force_equals_its_weight(held):
    grasp, run = held
    out = run.outcome
    assert out.success, out.reason
    assert not out.ground_contact
    m = grasp.object.mass
    # Closed form: the box at rest in the grip, off the ground: Σ F_z(fingers) = m·g, Σ F_x,y = 0.
    f = np.asarray(out.body_force[3:])  # palm frame; the auto pose's palm is level (palm z = world z)
    assert abs(f[2] / (m * _G) - 1.0) < _TOL_WEIGHT, f[2] / (m * _G)
    assert np.linalg.norm(f[:2]) < _TOL_LATERAL * m * _G, f
    assert np.isfinite(run.frames.pos).all() and np.isfinite(run.final_x).all()
    assert run.energy.plausible and run.energy.total_work > 0.0, run.energy


@pytest.mark.parametrize(("start", "plausible"), [(0.0152, True), (0.008, False)])
def test_energy_bound_flags_fingers_started_inside_the_object(start, plausible):
    """Fingers that start deep inside the box get pushed out by the penalty with no work to pay for it.

    At 15.2 mm from the box's axis the fingers start outside it; at 8 mm (the box is 40 mm wide) their
    inner faces start up to ~5 mm deep, and the penalty's stored energy (ke·d²/2 over the contact patches,
    tens of mJ) is released as the box and the fingers fly apart, where the drivers put in far less.
    """
    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    scene = _box_scene("semi-rigid", start)
    grasp = FemGrasp(
        scene,
        GraspScenario(**_BRIEF, tendon=TendonForce(tension=2.0)),
        options=_coarse(),
        dynamics=FemDynamics(dt=1e-5),
    )
    run = grasp.run()
    assert run.energy.plausible is plausible, run.energy
    assert (Failure.IMPLAUSIBLE in run.outcome.failures[:1]) is not plausible, run.outcome.reason
    assert np.isfinite(run.outcome.body_force).all() and np.isfinite(run.outcome.displacement).all()


def test_critically_damped_contact_still_holds_the_weight(held):
    """``contact_damping_ratio``: the held box with ζ = 1 per vertex in place of the paper's kd.

    At 4 µs (added mass 1%), the grasp study's step: at the 10 µs of ``held`` (added mass 151%) the
    critically damped grip lets the box slide out during the hold (measured; the paper's kd, 10–20×
    critical, hides what mass scaling does to the contact's dynamics), so ζ needs the true inertia.
    """
    from mjcodesign.errors import DesignError
    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    with pytest.raises(DesignError):
        FemDynamics(contact_damping_ratio=-1.0)
    grasp0, run0 = held
    scenario = dataclasses.replace(grasp0.scenario, hold_s=0.15)
    grasp = FemGrasp(
        grasp0.scene, scenario, options=_coarse(), dynamics=FemDynamics(dt=4e-6, contact_damping_ratio=1.0)
    )
    run = grasp.run()
    out = run.outcome
    assert out.success, out.reason
    assert run.added_mass_fraction < 0.02
    m = grasp.object.mass
    f = np.asarray(out.body_force[3:])
    assert abs(f[2] / (m * _G) - 1.0) < _TOL_WEIGHT, f[2] / (m * _G)  # a static law: damping must not move it
    assert np.linalg.norm(f[:2]) < _TOL_LATERAL * m * _G, f


def test_outcome_is_computed_like_mujocos(held):
    grasp, run = held
    out = run.outcome
    sch = grasp.schedule
    J = sch.per_step
    # Displacement: the COM relative to the palm, from the end of tightening to the end.
    palm = [grasp.palm(s) for s in (sch.grasp_step, sch.n_steps)]
    rel = [run.frames.pos[s // J] - p for s, p in zip((sch.grasp_step, sch.n_steps), palm, strict=True)]
    np.testing.assert_allclose(out.displacement, rel[1] - rel[0], atol=1e-12)
    assert out.lift_height == pytest.approx(run.frames.pos[-1, 2] - run.frames.pos[0, 2])
    assert out.finger_contact and (run.final_depth > 0).any()
    assert len(out.object_path) == len(sch.samples)


def test_schedule_follows_mujocos_servos():
    from mjcodesign.sim.fem.schedule import grasp_schedule
    from mjcodesign.sim.mujoco_c import MujocoBackend

    obj = box_object(_BOX, 100.0)
    d = FingerDesign()
    scene = build_scene(obj, d, Stiffness.preset("semi-rigid"), FingerModel.CHAIN, auto_pose(obj, d))
    scenario = GraspScenario()

    class Keep:
        def rollout(self, r):
            self.r = r

        def snapshot(self, s):
            pass

        def close(self):
            pass

    keep = Keep()
    MujocoBackend(nthread=1).run(scene, scenario, observer=keep)
    m = scene.model
    sch = grasp_schedule(scene, scenario, 2.5e-6)
    import mujoco

    adr = [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{c}_slide")] for c in "AB"]
    steps = np.arange(sch.starts["tighten"])  # no contact and no tendon yet: the servos' own response
    mj = keep.r.states[steps][:, [1 + a for a in adr]]
    fem = sch.openings[(steps + 1) * sch.per_step]
    assert np.abs(mj - fem).max() < _TOL_SERVO
    assert np.ptp(fem[:, 0]) > 0.005  # the carriages did move (most of their 19 mm of closing)


@pytest.mark.parametrize("order", [1, 2], ids=["linear", "quadratic"])
def test_recorded_forward_equals_taped_steps(order):
    """The fast forward (recorded launches, reused buffers) and the taped step give bitwise the same states."""
    import warp as wp

    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    scene = _box_scene("paper-optimized", 0.0152)  # touching the box's top edge from the start
    scenario = GraspScenario(**_BRIEF, tendon=TendonForce(tension=2.0), lift=0.002, impulse=0.0)
    grasp = FemGrasp(scene, scenario, options=_coarse(order=order), dynamics=FemDynamics(dt=1e-5))
    s0, n = 400, 200
    full = grasp.run(checkpoints=(s0, s0 + n))
    assert full.frames.n_inside.max() > 0  # contact is exercised
    *arrays, load = full.checkpoints[s0]
    st = grasp.state_from(arrays)
    prev = wp.array([load], dtype=wp.float64)
    for s in range(s0, s0 + n):
        st, buf = grasp.taped_step(st, s, prev)
        prev = buf.load
    for a, b in zip(st, full.checkpoints[s0 + n][:6], strict=True):
        np.testing.assert_array_equal(a.numpy().reshape(b.shape), b)


@pytest.mark.parametrize("locking", [False, True], ids=["plain", "locking-corrected"])
def test_l_opt_gradient_matches_central_differences(locking):
    from mjcodesign.sim.fem import FemDynamics, fem_grasp_loss_and_grad
    from mjcodesign.sim.fem.grasp_outcome import paper_loss
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    scene = _box_scene("paper-optimized", 0.0152)
    scenario = GraspScenario(**_BRIEF, tendon=TendonForce(tension=2.0), lift=0.002, impulse=0.0)
    # kd = 0: the paper's contact damping kd·v switches on with a jump when a vertex enters contact,
    # which moves the trajectory by an amount the adjoint (contact set held fixed) cannot see.
    dyn = FemDynamics(dt=1e-5, contact_kd=0.0)
    # With the locking correction the moduli are ln E plus a constant shift: the gradient passes through it.
    mesh = _coarse(locking_correction=locking)
    grasp = FemGrasp(scene, scenario, options=mesh, dynamics=dyn)
    # The library entry point (the co-design's baseline) from the design, object and pose, on the same mesh.
    loss, grad, out, _ = fem_grasp_loss_and_grad(
        scene.built.stiffness,
        scene.obj,
        scene.pose,
        scenario=scenario,
        options=mesh,
        dynamics=dyn,
        start_openings=scene.start_openings,
        segment=300,
        gripper=grasp.gripper,
    )
    assert np.isfinite(grad).all() and np.abs(grad).max() > 0
    assert grad.shape == (22,) and out is not None
    le0 = scene.built.stiffness.log_e.ravel().copy()

    def loss_at(le):
        grasp.gripper.set_log_e(le, rescale_mass=False)  # the adjoint holds the masses fixed too
        r = grasp.run()
        return paper_loss(r.outcome.body_force, r.outcome.displacement, r.ground_points)[0]

    assert loss_at(le0) == loss  # deterministic, and the entry point's scene is the test's
    h = 1e-5
    # The steepest block of each finger, and a flexure of each (blocks 3 and 14).
    for i in (int(np.argmax(np.abs(grad[:11]))), int(np.argmax(np.abs(grad[11:]))) + 11, 3, 14):
        e = np.zeros(22)
        e[i] = 1.0
        fd = (loss_at(le0 + h * e) - loss_at(le0 - h * e)) / (2 * h)
        assert abs(grad[i] - fd) < _TOL_GRAD * abs(fd), (i, grad[i], fd)


def test_fem_backend_runs_the_grasp_protocol():
    from mjcodesign.errors import UnsupportedError
    from mjcodesign.sim.fem import FemBackend, FemDynamics
    from mjcodesign.sim.protocol import Simulator, get_backend

    backend = get_backend("fem", dynamics=FemDynamics(dt=1e-5), grasp_options=_coarse())
    assert isinstance(backend, FemBackend) and isinstance(backend, Simulator)
    scene = _box_scene("semi-rigid", 0.022)
    scenario = GraspScenario(**_BRIEF, tendon=TendonForce(tension=2.0))
    designs = [Stiffness.preset("semi-rigid"), Stiffness.preset("paper-optimized")]
    outs = backend.run_batch(scene, scenario, designs)
    assert len(outs) == 2
    for o in outs:
        assert np.isfinite(o.body_force).all() and np.isfinite(o.displacement).all()
        assert o.failure is not Failure.DIVERGED
    one = backend.run(
        dataclasses.replace(scene, built=dataclasses.replace(scene.built, stiffness=designs[1])), scenario
    )
    assert one.body_force == outs[1].body_force  # deterministic, and the mesh reuse changes nothing
    with pytest.raises(UnsupportedError):
        backend.run(scene, scenario, observer=object())


def test_position_mode_servo_holds_its_spring_law():
    """Position mode: the XL330 servo on the FEM tendon, its damper implicit (b·dt/m_eff ~ 50 here)."""
    from mjcodesign.errors import UnsupportedError
    from mjcodesign.scenarios.drive import TendonPosition
    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.grasp_adjoint import loss_gradient
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    drive = TendonPosition(ticks=50)  # winds 0.61 mm (8 mm horn) in 7 ms of the 20 ms grasp
    scene = _box_scene("semi-rigid", 0.0152)
    dt = 1e-5
    grasp = FemGrasp(
        scene, GraspScenario(**_BRIEF, tendon=drive), options=_coarse(), dynamics=FemDynamics(dt=dt)
    )
    run = grasp.run()
    assert run.outcome.failure is not Failure.DIVERGED, run.outcome.reason
    tension, rate = grasp.tendon_history()
    assert np.isfinite(tension).all() and np.isfinite(rate).all()
    assert tension.min() >= 0.0 and tension.max() <= drive.max_tension
    n = grasp.schedule.n_steps
    slack = grasp.tendon_lengths(grasp.placement.vertices, 0)
    # The kernel reads the length at the last substep's start: the final length less that substep's
    # ℓ̇·dt (the rate its damper saw).
    length = grasp.tendon_lengths(run.final_x, n) - rate[-1] * dt
    # Closed form of the servo at the end, wound in fully: T = clip(k (ℓ − (ℓ₀ − pull)), 0, T_max).
    expected = np.clip(drive.stiffness * (length - (slack - drive.pull)), 0.0, drive.max_tension)
    assert tension[-1].min() > 0.0  # the tendon is taut: the law is tested off its clip
    np.testing.assert_allclose(tension[-1], expected, rtol=_TOL_SERVO_LAW)
    # The energy bound reads the tension the servo wrote (the table is NaN ahead of the run).
    assert np.isfinite(run.energy.total_work) and run.energy.plausible, run.energy
    assert Failure.IMPLAUSIBLE not in run.outcome.failures, run.outcome.reason
    with pytest.raises(UnsupportedError):
        loss_gradient(grasp)


def test_blow_up_is_a_diverged_outcome_without_nan():
    """Mass damping past its explicit stability limit blows up: DIVERGED with a reason, no NaN."""
    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    scene = _box_scene("soft", 0.0152)
    scenario = GraspScenario(**_BRIEF, tendon=TendonForce(tension=2.0))
    # α·dt = 3 > 2: each step multiplies a vertex's velocity by 1 − α·dt = −2.
    grasp = FemGrasp(scene, scenario, options=_coarse(), dynamics=FemDynamics(dt=1e-5, mass_damping=3e5))
    out = grasp.run().outcome
    assert out.failure is Failure.DIVERGED and out.reason.startswith("diverged: FEM")
    assert np.isfinite(out.body_force).all() and np.isfinite(out.displacement).all()


def test_grasp_study_short_version(tmp_path):
    """The CI version of ``crosscheck --scenario grasp``: two cases, short horizon, coarse mesh."""
    from mjcodesign.crosscheck import grasp_study, short_settings
    from mjcodesign.crosscheck.grasp import STUDY_TENSION
    from mjcodesign.sim.fem import GRASP_TENSION

    assert STUDY_TENSION == GRASP_TENSION  # one tension for the study and the gradient's baseline
    records, summary = grasp_study(models=("chain", "fem"), cache_dir=tmp_path, **short_settings())
    assert len(records) == 2 and summary["cases"] == 2
    for r in records:
        for m in ("chain", "fem"):
            assert np.isfinite(r[m]["body_force"]).all() and np.isfinite(r[m]["displacement"]).all()
            assert r[m]["failures"] or r[m]["success"]
    assert 0.0 <= summary["success_agreement"] <= 1.0
    assert set(summary["correlation"]) == {f"f{i}" for i in range(6)} | {f"dq{i}" for i in range(3)}
    assert len(summary["disagreements"]) == round(2 * (1 - summary["success_agreement"]))


def test_grasp_cli_model_fem_selects_the_fem(tmp_path, monkeypatch):
    """``mjcodesign grasp --model fem``: the FEM backend gets a chain scene of the object and pose."""
    import trimesh

    from mjcodesign.cli.grasp import grasp
    from mjcodesign.errors import DesignError
    from mjcodesign.scenarios.outcome import failed_outcome
    from mjcodesign.sim.fem import FemBackend

    seen = {}

    def fake_run(self, scene, scenario, *, observer=None, label="grasp"):
        seen.update(scene=scene, scenario=scenario, backend=self)
        return failed_outcome(Failure.NOT_LIFTED, "not lifted (stub)")

    monkeypatch.setattr(FemBackend, "run", fake_run)
    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=_BOX).export(path)
    out = grasp(str(path), "semi-rigid", "fem", tension=3.0, cache_dir=tmp_path)
    assert isinstance(seen["backend"], FemBackend)
    import warp as wp

    # --device auto: CUDA when Warp finds it, else the CPU
    assert seen["backend"].grasp_options.device == ("cuda" if wp.get_cuda_device_count() else "cpu")
    assert seen["scene"].built.finger_model is FingerModel.CHAIN
    assert seen["scenario"].tension == 3.0
    assert out["reason"] == "not lifted (stub)"
    with pytest.raises(DesignError, match="--model fem"):
        grasp(str(path), "semi-rigid", "fem", backend="mjwarp", cache_dir=tmp_path)


def _study_record(case: str, chain_ok: bool, fem_failures: list[str]) -> dict:
    starts = {
        "settle": 0,
        "close": 1,
        "tighten": 2,
        "lift": 3,
        "hold": 4,
        "impulse": 6,
        "post_hold": 7,
        "end": 8,
    }
    path = [[0.0, 0.0, 0.0]] * 4 + [[0.0, 0.0, 0.03]] * 5

    def rec(ok: bool, failures: list[str]) -> dict:
        return {"success": ok, "failures": [] if ok else failures, "reason": "ok" if ok else failures[0],
                "body_force": [0.0] * 5 + [0.1], "displacement": [0.0, 0.0, 0.001], "path": path,
                "starts": starts, "hold_force_ratio": 1.0, "max_depth_m": 1e-4}  # fmt: skip

    return {"case": case, "mass_kg": 0.01, "lift": 0.03, "chain": rec(chain_ok, ["not_lifted"]),
            "fem": rec(not fem_failures, fem_failures)}  # fmt: skip


def test_study_summary_keeps_diverged_cases_out_of_the_valid_agreement():
    from mjcodesign.crosscheck.grasp import study_summary

    records = [
        _study_record("a", True, []),  # both succeed
        _study_record("b", False, ["not_lifted"]),  # both fail
        _study_record("c", False, ["diverged"]),  # "agree" on failure, but the FEM blew up
        _study_record("d", True, ["not_lifted"]),  # disagree
    ]
    s = study_summary(records)
    assert s["success_agreement"] == 0.75
    assert s["invalid_cases"] == ["c"]
    assert s["success_agreement_valid"] == pytest.approx(2 / 3)
    assert [d["case"] for d in s["disagreements"]] == ["d"]
    assert s["disagreements"][0]["chain_margin"] is None  # none taken for these records
    records[3]["chain_margin"] = {"same": 4, "of": 6}
    assert study_summary(records)["disagreements"][0]["chain_margin"] == {"same": 4, "of": 6}
    assert s["checks"]["fem"][2]["energy"] and not s["checks"]["chain"][2]["energy"]


def test_quadratic_tets_lump_mass_onto_every_node():
    """HRZ lumping of 10-node tets: every node has mass, and the body's mass and centre of mass are kept."""
    from mjcodesign.sim.fem import FemFinger

    design = FingerDesign()
    quad = FemFinger(design, Stiffness.preset("soft"), options=_coarse(order=2))
    lin = FemFinger(design, Stiffness.preset("soft"), options=_coarse())
    assert np.all(quad.mass > 0)  # explicit dynamics divides by every node's mass
    np.testing.assert_allclose(quad.mass.sum(), lin.mass.sum(), rtol=1e-12)  # the same body
    com = lambda f: f.mass @ f.mesh.vertices / f.mass.sum()  # noqa: E731
    np.testing.assert_allclose(com(quad), com(lin), atol=1e-12)  # gravity's torque on the finger is kept
    corners = np.unique(quad.mesh.tets[:, :4])
    mids = np.setdiff1d(np.arange(quad.mesh.n_vertices), corners)
    assert quad.mass[mids].mean() > quad.mass[corners].mean()  # midsides carry most (32 vs 6 per tet)


@pytest.mark.parametrize(
    ("law", "guides"), [("frictionless", True), ("paper", True), ("frictionless", False)]
)
def test_tendon_kernel_applies_the_reference_law(law, guides):
    """The grasp's tendon kernel against `mjcodesign.design.tendon_law.tendon_forces` on a bent finger.

    Both fingers' waypoints from the mesh weights (segments only without flexure guides), the section
    axes from the spine's top and bottom vertices, the law evaluated in numpy and spread back by the
    same weights (virtual work).
    """
    from mjcodesign.design.tendon_law import tendon_forces
    from mjcodesign.sim.fem import FemDynamics
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    scene = _box_scene("soft", 0.0152)
    options = _coarse(tendon_law=law, flexure_guides=guides)
    grasp = FemGrasp(
        scene,
        GraspScenario(**_BRIEF, tendon=TendonForce(tension=2.0)),
        options=options,
        dynamics=FemDynamics(dt=1e-5),
    )
    g = grasp.gripper
    assert g.n_waypoints == (g.n_blocks if guides else (g.n_blocks + 1) // 2)
    rest = grasp.placement.vertices
    rng = np.random.default_rng(0)
    x = rest + 2e-3 * rng.standard_normal(rest.shape)  # every waypoint and section moved by ~mm
    s = grasp.schedule.n_steps  # the tendon at its full tension
    got = grasp.tendon_forces(x, s)
    tension = grasp.tendon_history()[0][s]
    assert tension.min() > 0.0
    offsets = grasp.schedule.offsets(grasp.placement.axes)[s - 1]
    want = np.zeros_like(x)
    m = g.n_waypoints
    for f in range(2):
        rows = slice(f * m, (f + 1) * m)
        idx, w = g.waypoint_idx[rows], g.waypoint_w[rows]
        points = np.einsum("bk,bkj->bj", w, x[idx])
        top, bottom = g.waypoint_section[rows].T
        exit_point = grasp.placement.exits[f] + offsets[f]
        forces = tendon_forces(points, x[top] - x[bottom], exit_point, tension[f], law)
        np.add.at(want, idx.ravel(), (w[..., None] * forces[:, None, :]).reshape(-1, 3))
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)
