"""The Warp FEM's two-finger grasp with the printed tendon routing (``FemOptions(routing="printed")``).

The grasp's tendon against the statics' load on the same channel points (`FemBody.tendon_load`), its
length against the channel points placed directly, short grasps in both drives within the energy
bound, and what the printed grasp still refuses. Coarse mesh (10 mm cells, 8 mm in the flexures and
cuts) and a 20 ms grasp at 10 µs: seconds each.
"""

import dataclasses

import numpy as np
import pytest

pytest.importorskip("warp")

from mjcodesign.design.finger import FingerDesign  # noqa: E402
from mjcodesign.design.stiffness import Stiffness  # noqa: E402
from mjcodesign.errors import DesignError, UnsupportedError  # noqa: E402
from mjcodesign.models.channels import channel_points  # noqa: E402
from mjcodesign.models.spec import finger_frame_quat  # noqa: E402
from mjcodesign.models.types import FingerModel  # noqa: E402
from mjcodesign.objects import box_object  # noqa: E402
from mjcodesign.scenarios.drive import TendonForce, TendonPosition  # noqa: E402
from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene  # noqa: E402
from mjcodesign.scenarios.outcome import Failure  # noqa: E402
from mjcodesign.sim.fem import FemDynamics, FemOptions  # noqa: E402
from mjcodesign.sim.fem.gripper import SIDES, FemGripper, quat_matrix  # noqa: E402
from mjcodesign.sim.fem.gripper_grasp import FemGrasp  # noqa: E402

PRINTED = FemOptions(h=10e-3, h_flexure=8e-3, spine_layers=2, waypoint_layers=False, routing="printed")
"""The grasp study's coarse mesh (396 vertices a finger) with the printed routing."""
_PHASES = dict(settle_s=0.0, close_s=0.002, tighten_s=0.004, lift_s=0.004, hold_s=0.008, post_hold_s=0.002)
"""A 20 ms grasp through every phase: 2,000 substeps of 10 µs."""
_DT = 1e-5
"""Substep [s]: selective mass scaling keeps it stable; the laws tested here are static."""
_TENSION = 2.0
"""Force-mode tension [N]."""
_TOL_LAW = 1e-12
"""[N] The grasp's tendon forces against the statics' on the same points: one law in float64, the grasp's
on points placed in the world (coordinates ~0.1 m, spans ≥ 2.9 mm), so they differ by the round-off of
the placement, ~1e-16 m over the spans: ~1e-13 of T = 2 N (measured 2.2e-15 N)."""
_TOL_LENGTH = 1e-12
"""[m] Tendon length against the channel points placed directly: the embedding reproduces a point to
~1e-15 m (tests/test_fem_routing.py) and an affine field exactly (linear tets), over 18 spans."""
_TOL_SERVO_LAW = 1e-3
"""Position mode: the tension at the last substep against the servo law at the length that substep read,
the final printed length less ℓ̇·dt (first order in dt), relative; tests/test_fem_grasp.py's bound."""


def _scene(design: str = "semi-rigid", start: float = 0.022):
    """The 9.6 g box at its auto pose, the fingers started ``start`` [m] from the palm's mid-plane."""
    obj = box_object((0.04, 0.04, 0.06), 100.0)
    d = FingerDesign()
    scene = build_scene(obj, d, Stiffness.preset(design), FingerModel.CHAIN, auto_pose(obj, d))
    return dataclasses.replace(scene, start_openings=(start, start))


def _grasp(drive, **kw) -> FemGrasp:
    scenario = GraspScenario(**_PHASES, tendon=drive)
    return FemGrasp(_scene(), scenario, options=PRINTED, dynamics=FemDynamics(dt=_DT), **kw)


@pytest.fixture(scope="module")
def force_grasp():
    return _grasp(TendonForce(tension=_TENSION))


def _finger_frames(grasp: FemGrasp, s: int):
    """Each finger's rotation (finger frame → world) and base origin [m] at the end of substep ``s``."""
    R = grasp.placement.rotation
    design = grasp.gripper.design
    out = []
    for f, (side, opening) in enumerate(zip(SIDES, grasp.scene.start_openings, strict=True)):
        Rf = R @ quat_matrix(finger_frame_quat(side))
        origin = grasp.placement.palm + R @ np.array([0.0, side * (opening + design.height_base), 0.0])
        out.append((Rf, origin + grasp.base_offsets[s][f]))
    return out


def _world(grasp: FemGrasp, x_finger: np.ndarray, s: int) -> np.ndarray:
    """Both fingers at finger-frame positions ``x_finger`` (n_per_finger, 3), bases where substep ``s`` ends."""
    return np.vstack([x_finger @ Rf.T + o for Rf, o in _finger_frames(grasp, s)])


def test_the_grasp_runs_the_statics_channel_points(force_grasp):
    """The same embedding: each finger's table rebuilds `FemBody.path_weights` exactly, anchor included."""
    g = force_grasp.gripper
    n = g.n_per_finger
    assert g.n_waypoints == 17  # six segments' entry, middle and exit, less the anchor
    for f, body in enumerate(g.fingers):
        rows = slice(f * g.n_waypoints, (f + 1) * g.n_waypoints)
        dense = np.zeros((g.n_waypoints, n))
        for r, (idx, w) in enumerate(zip(g.waypoint_idx[rows] - f * n, g.waypoint_w[rows], strict=True)):
            np.add.at(dense[r], idx, w)
        np.testing.assert_array_equal(dense, body.path_weights)
        np.testing.assert_array_equal(body.anchor, channel_points(g.design)[0, 0])
    assert g.tendon_points_disjoint()


@pytest.mark.parametrize("pose", ["rest", "bent"])
def test_tendon_forces_equal_the_statics_load(force_grasp, pose):
    """At the rest pose (and a random one), the grasp's kernel forces are `FemBody.tendon_load`'s.

    The frictionless tendon's load f = −T ∂ℓ/∂x on the same points: the statics in the finger frame,
    the grasp on the placed fingers, rotated back. Both fingers, the base (and so the anchor) where the
    carriage has taken it.
    """
    grasp = force_grasp
    g = grasp.gripper
    n = g.n_per_finger
    s = grasp.schedule.n_steps  # the tension in full
    tension = grasp.tendon_history()[0][s]
    assert np.all(tension == _TENSION)
    x = g.fingers[0].mesh.vertices.copy()
    if pose == "bent":
        free = ~np.isin(np.arange(n), g.fingers[0].mesh.base)
        x[free] += 1e-3 * np.random.default_rng(0).standard_normal((int(free.sum()), 3))
    got = grasp.tendon_forces(_world(grasp, x, s - 1), s)  # substep s reads the bases where s − 1 ended
    for f, (Rf, _) in enumerate(_finger_frames(grasp, s)):
        want, _ = g.fingers[f].tendon_load(_TENSION)(x)
        assert np.abs(want).max() > 0.1 * _TENSION  # the channel points are loaded
        np.testing.assert_allclose(got[f * n : (f + 1) * n] @ Rf, want, rtol=0, atol=_TOL_LAW)


def test_tendon_length_is_the_channel_polyline(force_grasp):
    """ℓ through the embedded channel points against the channel points themselves, at rest and stretched.

    A known deformation: x' = X + X_x b (b a constant vector) keeps the base face (X_x = 0, the anchor
    on it) and is affine, which linear tets reproduce exactly, so each channel point p goes to p + p_x b
    and ℓ' = Σ |Δp + Δp_x b| over the channel polyline.
    """
    grasp = force_grasp
    g = grasp.gripper
    s = grasp.schedule.n_steps  # the carriages closed and the palm lifted: the anchor moved with the base
    X = g.fingers[0].mesh.vertices
    p = channel_points(g.design).reshape(-1, 3)
    b = np.array([0.05, 0.02, -0.08])
    length = lambda pts: np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()  # noqa: E731
    np.testing.assert_array_equal(grasp.base_offsets[0], 0.0)  # so the frames are the placement's:
    np.testing.assert_allclose(_world(grasp, X, 0), grasp.placement.vertices, rtol=0, atol=1e-15)
    assert np.linalg.norm(grasp.base_offsets[s], axis=1).min() > 1e-3
    rest = grasp.tendon_lengths(_world(grasp, X, s), s)
    bent = grasp.tendon_lengths(_world(grasp, X + X[:, :1] * b, s), s)
    np.testing.assert_allclose(rest, length(p), rtol=0, atol=_TOL_LENGTH)
    np.testing.assert_allclose(bent, length(p + p[:, :1] * b), rtol=0, atol=_TOL_LENGTH)
    change = length(p + p[:, :1] * b) - length(p)
    assert abs(change) > 1e-3  # the deformation does move the tendon (by +8.1 mm)
    np.testing.assert_allclose(bent - rest, change, rtol=0, atol=2 * _TOL_LENGTH)


@pytest.mark.parametrize(
    "drive", [TendonForce(tension=_TENSION), TendonPosition(ticks=50)], ids=["force", "servo"]
)
def test_short_printed_grasp_is_finite_and_within_the_energy_bound(drive):
    """A 20 ms printed grasp in each drive: no blow-up, finite outcome, no energy from nowhere.

    In position mode the servo reads the printed path's length: T = clip(k (ℓ − (ℓ₀ − pull)), 0, T_max)
    at the end, ℓ the final `tendon_lengths` less that substep's ℓ̇·dt.
    """
    grasp = _grasp(drive)
    run = grasp.run()
    out = run.outcome
    assert out.failure is not Failure.DIVERGED, out.reason
    assert Failure.IMPLAUSIBLE not in out.failures, out.reason
    assert np.isfinite(run.final_x).all() and np.isfinite(run.frames.pos).all()
    assert np.isfinite(out.body_force).all() and np.isfinite(out.displacement).all()
    assert run.energy.plausible and run.energy.total_work > 0.0, run.energy
    tension, rate = grasp.tendon_history()
    assert np.isfinite(tension).all() and tension.max() > 0.0
    if rate is None:
        return
    n = grasp.schedule.n_steps
    slack = grasp.tendon_lengths(grasp.placement.vertices, 0)
    length = grasp.tendon_lengths(run.final_x, n) - rate[-1] * _DT
    expected = np.clip(drive.stiffness * (length - (slack - drive.pull)), 0.0, drive.max_tension)
    assert tension[-1].min() > 0.0  # taut: the law is tested off its clip
    np.testing.assert_allclose(tension[-1], expected, rtol=_TOL_SERVO_LAW)


def test_printed_grasp_refusals(force_grasp):
    with pytest.raises(DesignError, match="flexure_guides"):
        FemOptions(routing="printed", flexure_guides=False)  # the older guided variant only
    with pytest.raises(DesignError, match="frictionless"):
        FemOptions(routing="printed", tendon_law="paper")
    with pytest.raises(DesignError, match="channels"):
        FemGripper(FingerDesign(routing="uniform-height"), Stiffness.preset("soft"), options=PRINTED, dt=_DT)
    # The servo's implicit damper sums each tendon point's own compliance: points that share a free
    # vertex are refused (none do on the meshes in use; here one is made to).
    g = FemGripper(force_grasp.gripper.design, Stiffness.preset("semi-rigid"), options=PRINTED, dt=_DT)
    assert g.tendon_points_disjoint()
    # Which slot holds a free vertex of non-zero weight depends on the mesh's round-off (a slot may
    # hold a pinned vertex at weight 1e-16), so the shared vertex is planted between two such slots.
    free = g.pinned[: g.n_per_finger] == 0
    a, b = ([k for k in range(g.waypoint_idx.shape[1]) if g.waypoint_w[p, k] != 0 and free[g.waypoint_idx[p, k]]]
            for p in (0, 1))  # fmt: skip
    assert a and b, "the first two tendon points weigh no free vertex"
    g.waypoint_idx[1, b[0]] = g.waypoint_idx[0, a[0]]  # both weigh it now
    assert not g.tendon_points_disjoint()
    with pytest.raises(UnsupportedError, match="implicit damper"):
        _grasp(TendonPosition(ticks=50), gripper=g)
