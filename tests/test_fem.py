"""Warp FEM finger: mesh, material, statics against Euler–Bernoulli and the chain, adjoint gradient."""

import subprocess
import sys

import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign, Routing
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.scenarios.press import PRESS_METRICS
from mjcodesign.sim.fem import mesh_finger

_TOL_BEAM = 0.05  # FEM vs Euler–Bernoulli tip deflection
_TOL_CURL = 0.10  # chain vs FEM bend angle and tip displacement
_PRESS_MARGIN = 0.2  # distal-third share, uniform-height minus uniform-pressure (measured 0.27–0.37)
_TOL_LINEAR = 0.05  # flex linear static curl vs its dynamics at 0.3 rad (geometric terms ~ θ²/2 ≈ 5%)
_TOL_GRAD = 1e-4  # adjoint gradient vs central differences (FD step 1e-4 in ln E: error ~1e-8 rel)


def test_import_does_not_import_warp():
    code = "import sys, mjcodesign, mjcodesign.sim.fem, mjcodesign.sim.fem.mesh, mjcodesign.cli.crosscheck, "
    code += (
        "mjcodesign.crosscheck, mjcodesign.bench.fem, mjcodesign.sim.fem.grasp, mjcodesign.sim.fem.press, "
    )
    code += "mjcodesign.sim.fem.backend, mjcodesign.scenarios.press; "
    code += "assert 'warp' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("routing", list(Routing))
def test_mesh_volume_waypoints_tags(routing):
    design = FingerDesign(routing=routing)
    m = mesh_finger(design, 2e-3)
    vol = m.volumes()
    assert (vol > 0).all()
    # The mesh follows the side profile exactly: total volume = sum of the block prisms.
    assert vol.sum() == pytest.approx(sum(b.volume for b in design.blocks()), rel=1e-12)
    np.testing.assert_allclose(m.waypoint_weights @ m.vertices, design.waypoints(), atol=1e-15)
    for b in design.blocks():  # segment waypoints are single vertices
        row = m.waypoint_weights[b.index]
        if b.kind.value == "segment":
            assert np.count_nonzero(row) == 1
    assert set(np.unique(m.tet_block)) == set(range(design.n_blocks))
    np.testing.assert_allclose(m.vertices[m.tip], [design.length, 0, 0.5 * design.flexure_thickness])
    assert np.all(m.vertices[m.base, 0] == 0) and len(m.base) > 0


@pytest.fixture(scope="module")
def wp():
    return pytest.importorskip("warp")


@pytest.fixture(scope="module")
def coarse(wp):
    from mjcodesign.sim.fem import FemFinger, FemOptions

    return FemFinger(
        FingerDesign(), Stiffness.preset("paper-optimized"), options=FemOptions(h=4e-3, spine_layers=2)
    )


def test_rest_state_and_forces_are_energy_gradient(coarse):
    x0 = coarse.mesh.vertices
    assert np.abs(coarse.internal_forces(x0)).max() < 1e-9
    rng = np.random.default_rng(0)
    x = x0 + 1e-4 * rng.standard_normal(x0.shape)
    f = coarse.internal_forces(x)
    eps = 1e-8
    for i, k in [(5, 0), (40, 2), (300, 1)]:
        xp, xm = x.copy(), x.copy()
        xp[i, k] += eps
        xm[i, k] -= eps
        # f = −∂E/∂x
        assert f[i, k] == pytest.approx(-(coarse.energy(xp) - coarse.energy(xm)) / (2 * eps), rel=1e-5)


@pytest.mark.parametrize("preset", ["soft", "paper-optimized"])
def test_quadratic_fem_cantilever_matches_beam_theory(wp, preset):
    from mjcodesign.sim.fem import FemFinger, FemOptions

    fem = FemFinger(
        FingerDesign(), Stiffness.preset(preset), options=FemOptions(h=4e-3, spine_layers=2, order=2)
    )
    r = fem.cantilever()
    # δ_EB = F ∫ (L − x)² / (E(x) I(x)) dx over the real sections (mjcodesign.design.beam).
    assert r.tip_deflection_m == pytest.approx(r.analytic_m, rel=_TOL_BEAM)


def test_static_gradient_matches_central_differences(coarse):
    load = coarse.tendon_load(0.1)
    x = coarse.solve_static(load, steps=2)
    dm = np.zeros_like(x)
    dm[coarse.mesh.tip, 2] = 1.0  # metric: tip height z_tip
    grad = coarse.static_gradient(x, load, dm)
    assert np.all(grad[11:] == 0.0)  # finger B does not touch finger A
    base = Stiffness.preset("paper-optimized").log_e.ravel()
    eps = 1e-4
    try:
        for i in (1, 4, 9):
            vals = []
            for s in (1, -1):
                le = base.copy()
                le[i] += s * eps
                coarse.set_log_e(le)
                vals.append(coarse.solve_static(load, steps=2, x0=x)[coarse.mesh.tip, 2])
            fd = (vals[0] - vals[1]) / (2 * eps)
            assert grad[i] == pytest.approx(fd, rel=_TOL_GRAD)
    finally:
        coarse.set_log_e(base)


def test_explicit_dynamics_free_fall_start(coarse):
    from mjcodesign.sim.fem import FemDynamics

    dyn = FemDynamics(dt=0.5 * coarse.stable_dt(), mass_damping=0.0)
    t = 5e-4
    tip = coarse.rollout(t, dynamics=dyn, position=(0.0, 0.0, 0.05), frames=1)
    # Before the bending wave from the clamp reaches it, the tip falls freely: Δz = −g t² / 2.
    assert tip[-1, 2] - tip[0, 2] == pytest.approx(-0.5 * 9.81 * t**2, rel=0.02)


_TOL_GROUND = 1e-4  # [m]: a soft finger's weight on ke = 1e7 Pa/m presses vertices in by ~10 µm


def test_explicit_dynamics_rests_on_the_ground(coarse):
    from mjcodesign.sim.fem import FemDynamics

    # Clamped 0.5 mm above the ground: the finger sags onto it and stays there (bounded friction). A
    # static outcome, so at the paper's 2.5 µs with selective mass scaling (32% added mass; 8,000 steps,
    # not the true masses' 83,000 at their stable 0.24 µs: 6 s instead of 61 s here).
    tip = coarse.rollout(0.02, dynamics=FemDynamics(), position=(0.0, 0.0, 5e-4), frames=4, scale_mass=True)
    rest = coarse.mesh.vertices[coarse.mesh.tip, 2]  # the tip vertex's height above the bottom face
    assert np.all(np.isfinite(tip))
    assert tip[-1, 2] == pytest.approx(rest, abs=_TOL_GROUND)
    assert abs(tip[-1, 0] - tip[0, 0]) < _TOL_GROUND


@pytest.fixture(scope="module")
def soft_curl(wp):
    from mjcodesign.models.types import TendonMode
    from mjcodesign.scenarios.static import curl
    from mjcodesign.sim.fem import FemFinger, FemOptions

    stiffness = Stiffness.preset("soft")
    # Linear tets keep this under 20 s; the quadratic FEM curl takes minutes here (numbers in the xfail).
    fem = FemFinger(FingerDesign(), stiffness, options=FemOptions(h=3e-3, spine_layers=4))
    r = fem.curl(0.05)
    c = curl(FingerDesign(), stiffness, "chain", 0.05, tendon_mode=TendonMode.POINT_FORCE)
    return r, c


def test_fem_curl_bends_inwards(soft_curl):
    r, c = soft_curl
    assert r.bend_angle_rad > 0.3 and c["bend_angle_rad"] > 0.3
    assert np.all(np.array(r.block_angles_rad)[1::2] > 0)  # every flexure closes


@pytest.mark.xfail(
    strict=True,
    reason="chain misses the FEM by >10%: soft, 0.05 N, bend chain 0.685 rad vs linear-tet FEM 0.60 "
    "and quadratic FEM 0.81 (rel 0.15; 0.087 at 0.02 N, 0.23 at 0.08 N)",
)
def test_chain_curl_within_tolerance_of_fem(soft_curl):
    r, c = soft_curl
    assert c["bend_angle_rad"] == pytest.approx(r.bend_angle_rad, rel=_TOL_CURL)
    assert np.linalg.norm(c["tip_displacement_m"]) == pytest.approx(
        np.linalg.norm(r.tip_displacement_m), rel=_TOL_CURL
    )


def test_crosscheck_cli_json(wp, capsys):
    import argparse
    import json

    from mjcodesign.cli import crosscheck as cli_crosscheck
    from mjcodesign.cli.common import quiet_warp

    quiet_warp()  # as `mjcodesign.cli.main.main` does before a command that reaches Warp
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command")
    cli_crosscheck.add_parser(sub)
    bench = sub.add_parser("bench").add_subparsers(dest="what")
    cli_crosscheck.add_bench_parser(bench)
    assert p.parse_args(["bench", "fem", "--json"]).fem_order == 1
    from mjcodesign.bench.fem import GRIPPER_MESHES

    for mesh in GRIPPER_MESHES:  # every named mesh of the grasp benchmark can be asked for
        assert p.parse_args(["bench", "fem", "--gripper", mesh]).gripper == mesh
    args = p.parse_args(
        "crosscheck --scenario cantilever --models chain,fem --design soft --fem-h 4e-3 --fem-layers 2 --json".split()
    )
    assert args.func(args) == 0
    rows = json.loads(capsys.readouterr().out)  # nothing but the JSON on stdout
    assert [r["model"] for r in rows] == ["chain", "fem"]
    for r in rows:
        assert set(r) == {"scenario", "model", "design", "metric", "value", "reference", "rel_diff"}
    assert rows[0]["rel_diff"] < _TOL_BEAM  # the chain is built from beam theory


# -- rigid-object contact and the dynamic gradient (mjcodesign.sim.fem.contact) -----------------------
_TOL_REST = 0.02  # Σ contact force vs m·g after 25 ms of damped settling
_MAX_PENETRATION = 2e-4  # [m]; pressure m·g/A ≈ 80 Pa over ke = 1e7 Pa/m is 8 µm on average
_TOL_DYN_GRAD = 1e-3  # adjoint vs central FD of a 0.5 ms contact rollout (measured ≤ 2e-4)


@pytest.fixture(scope="module")
def dyn_finger(wp):
    from mjcodesign.sim.fem import FemFinger, FemOptions

    opts = FemOptions(h=4e-3, spine_layers=2, waypoint_layers=False)
    return FemFinger(FingerDesign(), Stiffness.preset("paper-optimized"), options=opts)


def test_free_finger_resting_on_box_carries_its_weight(dyn_finger):
    from mjcodesign.sim.fem import FemContact, FemDynamics, RigidObject

    top = 0.01
    box = RigidObject.box((0.068, 0.0, 0.5 * top), (0.08, 0.02, 0.5 * top))
    sim = FemContact(
        dyn_finger, box, position=(0, 0, top), dynamics=FemDynamics(mass_damping=400.0), clamp=False
    )
    r = sim.run(0.025, frames=3)
    mg = dyn_finger.mass.sum() * 9.81
    f = r.object_force
    # Statics of the free finger on the box: Σ F_contact = −m·g (the ground is never reached).
    assert f[:, 2].sum() == pytest.approx(mg, rel=_TOL_REST)
    assert np.abs(f[:, :2].sum(axis=0)).max() < _TOL_REST * mg  # no net friction on a level box
    assert 0.0 < r.max_penetration < _MAX_PENETRATION
    assert r.x[:, 2].min() > top - _MAX_PENETRATION


def test_contact_gradient_matches_central_differences(dyn_finger):
    from mjcodesign.sim.fem import FemContact, RigidObject

    # A box pressed 0.2 mm into the tip segment's top, the tendon pulling the finger into it.
    box = RigidObject.box((0.135, 0.0, 0.0162), (0.015, 0.015, 0.01))
    sim = FemContact(dyn_finger, box, tension=0.5)
    horizon = 200 * sim.dyn.dt
    value, grad = sim.mean_force_gradient(horizon, segment=64)
    assert value > 0.1
    assert np.all(grad[11:] == 0.0)
    base = Stiffness.preset("paper-optimized").log_e.ravel()
    eps = 1e-4
    try:
        for i in (8, 9, 10):  # the blocks near the contact (base blocks: ~1e-10, FD noise)
            vals = []
            for s in (1, -1):
                le = base.copy()
                le[i] += s * eps
                dyn_finger.set_log_e(le)
                vals.append(sim.run(horizon, frames=1).mean_normal_force)
            fd = (vals[0] - vals[1]) / (2 * eps)
            assert grad[i] == pytest.approx(fd, rel=_TOL_DYN_GRAD)
    finally:
        dyn_finger.set_log_e(base)


@pytest.fixture(scope="module")
def press_results(wp):
    from dataclasses import asdict

    from mjcodesign.crosscheck import press_tension
    from mjcodesign.scenarios.press import press_linear, press_mujoco
    from mjcodesign.sim.fem import FemFinger, FemOptions, press_fem

    stiffness = Stiffness.preset("paper-optimized")
    tension = press_tension(stiffness)
    out = {}
    for routing in Routing:
        design = FingerDesign(routing=routing)
        fem = FemFinger(design, stiffness, options=FemOptions(h=4e-3, spine_layers=2))
        out[routing] = (
            asdict(press_fem(fem, tension)),
            press_mujoco(design, stiffness, "chain", tension),
            press_mujoco(design, stiffness, "flex", tension),  # ~5-20 s per routing
            press_linear(design, stiffness, "flex", tension),
            press_linear(design, stiffness, "flex-quadratic", tension),
        )
    return out


def test_press_uniform_height_loads_the_tip(press_results):
    # Paper, Fig. 2: uniform-pressure routing spreads the contact force, uniform-height loads the tip.
    p = press_results[Routing.UNIFORM_PRESSURE]
    h = press_results[Routing.UNIFORM_HEIGHT]
    for k in range(5):  # FEM, chain, flex, linear flex, linear flex-quadratic
        assert h[k]["distal_third_fraction"] > p[k]["distal_third_fraction"] + _PRESS_MARGIN
        assert h[k]["centroid_over_length"] > p[k]["centroid_over_length"]
        assert h[k]["n_contacts"] < p[k]["n_contacts"]


_CALIBRATED = (
    "with the chain and flex stiffness calibrated to the converged FEM (SimOptions.stiffness_model "
    "'fem', the default; README 'Limits': the flex models' tendon curl misses the FEM)"
)


@pytest.mark.xfail(
    strict=True,
    reason=f"measured 2026-12-01 {_CALIBRATED}: the chain's distal-third share with uniform-pressure "
    "routing is 0.59 against the FEM's 0.74 (-20%)",
)
def test_press_chain_matches_fem(press_results):
    for fem, chain, *_ in press_results.values():
        for k in PRESS_METRICS:
            assert chain[k] == pytest.approx(fem[k], rel=_TOL_CURL), k


@pytest.mark.parametrize(
    "model",
    [
        pytest.param(
            2,
            id="flex",
            marks=pytest.mark.xfail(
                strict=True,
                reason="measured: with uniform-pressure routing the trilinear flex loads the proximal "
                "segments more than the FEM (20.3 mN, distal share 0.74, centroid 0.75 L): 22.0 mN (+9%), "
                "0.62 (-17%), 0.71 (-6%) under beam stiffness; uniform height within 5%",
            ),
        ),
        # flex-quadratic (linear solve): 22.5 mN (+11%), distal 0.65 (-13%) under beam stiffness; within
        # 10% on every metric since the stiffness is calibrated to the FEM
        pytest.param(4, id="flex-quadratic-linear"),
    ],
)
def test_press_flex_matches_fem(press_results, model):
    for res in press_results.values():
        for k in PRESS_METRICS:
            assert res[model][k] == pytest.approx(res[0][k], rel=_TOL_CURL), k


_TOL_LINEAR_PRESS = 0.02  # total force and centroid: the finger moves 0.5 mm, so linear is exact to ~1%


@pytest.mark.xfail(
    strict=True,
    reason=f"measured 2026-12-01 {_CALIBRATED}: with uniform-height routing the flex dynamics' centroid "
    "is 0.979 L against the linear solve's 1.0 L (2.1%)",
)
def test_linear_press_matches_flex_dynamics(press_results):
    # The linear contact solve against the same trilinear flex run to a settled press. The distal share is
    # left out: 0.68 (linear, 6 vertex contacts, frictionless) against 0.62 (dynamics, 50 soft contacts).
    for _, _, dyn, lin, _ in press_results.values():
        for k in ("total_force_n", "centroid_over_length"):
            assert lin[k] == pytest.approx(dyn[k], rel=_TOL_LINEAR_PRESS), k


def test_press_settling_tells_drift_from_jitter():
    from mjcodesign.scenarios.press import settled

    rng = np.random.default_rng(0)
    t = np.arange(10) * 0.1
    base = np.array([0.02, 0.5, 0.6])
    jitter = base * (1 + 0.01 * rng.standard_normal((10, 3)))  # the flex: ~1% scatter, no trend
    creep = base * (1 + 0.013 * t[:, None])  # the chain at 2 s: +1.3% per second, smooth
    assert settled(jitter)
    assert not settled(creep)
    assert settled(np.tile(base, (10, 1)))


def test_plot_curves_writes_png(tmp_path):
    pytest.importorskip("matplotlib")
    from mjcodesign.crosscheck import plot_curves
    from mjcodesign.models.types import TendonMode
    from mjcodesign.scenarios.static import curl

    tensions = [0.02, 0.04]
    rs = [
        curl(FingerDesign(), Stiffness.preset("soft"), "chain", t, tendon_mode=TendonMode.POINT_FORCE)
        for t in tensions
    ]
    curves = {
        "chain": {
            "tension": tensions,
            "bend": [r["bend_angle_rad"] for r in rs],
            "tip": [r["tip_displacement_m"] for r in rs],
        }
    }
    out = tmp_path / "curl.png"
    plot_curves(curves, str(out))
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(Exception, match="curl scenario"):
        plot_curves({}, str(tmp_path / "none.png"))


def test_flex_linear_curl_matches_its_dynamics_at_small_bend():
    from mjcodesign.models.builder import build_finger
    from mjcodesign.models.flex import linear_curl
    from mjcodesign.models.types import SimOptions, TendonMode
    from mjcodesign.scenarios.static import curl

    design, stiffness, tension = FingerDesign(), Stiffness.preset("soft"), 0.02  # ≈ 0.3 rad of bend
    built = build_finger(
        design, stiffness, "flex", tendon_mode=TendonMode.POINT_FORCE, options=SimOptions(gravity=False)
    )
    lin = linear_curl(built.model, built.fingers[0], design, tension)
    dyn = curl(design, stiffness, "flex", tension, tendon_mode=TendonMode.POINT_FORCE)
    # Linear statics is the first-order rest state: measured 1% (tip) and 2.3% (bend) at 0.3 rad.
    assert np.linalg.norm(lin["tip_displacement_m"]) == pytest.approx(
        np.linalg.norm(dyn["tip_displacement_m"]), rel=_TOL_LINEAR
    )
    assert lin["bend_angle_rad"] == pytest.approx(dyn["bend_angle_rad"], rel=_TOL_LINEAR)


# Quadratic-tet FEM free curl (h 4 mm, 2 spine layers, frictionless tendon, gravity off) at about 0.3 rad,
# from `mjcodesign crosscheck --scenario curl` on this machine: design -> (tension [N], bend [rad],
# |tip displacement| [m]). One FEM case takes about a minute here (4 load increments, 20 Newton
# iterations), so the MuJoCo models are tested against these recorded values (README, cross-simulator
# table). Semi-rigid at 0.4017 N equals soft at 0.02 N to 4 digits (uniform E: the curl scales with
# T/E). random:0 is `Stiffness.random(0)`; its tension is a round value near 0.3 rad of bend.
_FEM_CURL = {
    "soft": (0.02, 0.3202, 0.03074),
    "semi-rigid": (0.4017, 0.3202, 0.03074),
    "random:0": (0.04, 0.2891, 0.02920),
}


_CURL_MISSES = {
    ("random:0", "flex"): 0.2470,
    ("semi-rigid", "flex"): 0.2556,
    ("soft", "flex"): 0.2557,
    ("semi-rigid", "flex-quadratic"): 0.2871,
    ("soft", "flex-quadratic"): 0.2871,
}
"""Bend [rad] the flex models reached on 2026-12-01 with the stiffness calibrated to the FEM:
10-20% short of the recorded FEM (the soft flex reached 0.298 under beam stiffness, within 10%)."""


def _curl_cases():
    for design in sorted(_FEM_CURL):
        for model in ("chain", "flex", "flex-quadratic"):
            miss = _CURL_MISSES.get((design, model))
            marks = ()
            if miss is not None:
                reason = f"measured bend {miss} rad against the FEM's {_FEM_CURL[design][1]} {_CALIBRATED}"
                marks = pytest.mark.xfail(strict=True, reason=reason)
            yield pytest.param(design, model, id=f"{design}-{model}", marks=marks)


@pytest.mark.parametrize(("design", "model"), list(_curl_cases()))
def test_curl_within_tolerance_of_recorded_fem(design, model):
    from mjcodesign.crosscheck import model_curl

    tension, bend, tip = _FEM_CURL[design]
    r = model_curl(FingerDesign(), Stiffness.parse(design), model, tension)
    assert r["bend_angle_rad"] == pytest.approx(bend, rel=_TOL_CURL)
    assert np.linalg.norm(r["tip_displacement_m"]) == pytest.approx(tip, rel=_TOL_CURL)


# random:0 at the largest default crosscheck tension (`crosscheck --scenario curl --design random:0`,
# quadratic FEM as above): 1.30 rad of bend.
_FEM_CURL_LARGE = ("random:0", 0.17333, 1.3023, 0.1229)


@pytest.mark.parametrize(
    "model",
    [
        "chain",  # its native tendon with the lever held (measured: bend 3.6% short, tip 3.2%)
        pytest.param(
            "flex",
            marks=pytest.mark.xfail(
                strict=True,
                reason="measured at 1.3 rad: flex bend 0.89 rad (32% short of the FEM), tip 89 mm (28%): "
                "its cells bend about their mid-height with beam theory's lever (README, limits)",
            ),
        ),
    ],
)
def test_large_curl_within_tolerance_of_recorded_fem(model):
    from mjcodesign.crosscheck import model_curl

    design, tension, bend, tip = _FEM_CURL_LARGE
    r = model_curl(FingerDesign(), Stiffness.parse(design), model, tension)
    assert r["bend_angle_rad"] == pytest.approx(bend, rel=_TOL_CURL)
    assert np.linalg.norm(r["tip_displacement_m"]) == pytest.approx(tip, rel=_TOL_CURL)
