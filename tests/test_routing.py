"""The chain's printed tendon routing: channel sites, lever and buckling tension from the tendon's path."""

import argparse

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.models import TendonMode, build_finger, make_data
from mjcodesign.models.channels import PRINTED_CHANNELS, channel_points
from mjcodesign.models.stability import buckling_tension, tangent_stiffness
from mjcodesign.models.types import FingerModel, SimOptions

_PRINTED = SimOptions(routing="printed", gravity=False)
_TOL_BUCKLE = 0.15  # buckling tension of the straight finger vs the closed form k (a+b)/(ab) (issue's target)
_TOL_LEVER = 1e-6  # tendon lever [m/rad] vs the chord's distance from the hinge: finite differences only
_TOL_HOLE = 0.1e-3  # channel height vs the STL's hole centre [m]: the line fit's residual is 0.08 mm
_FD = 1e-6  # central-difference step of a hinge angle [rad]
# ln E of uniform fingers across the printable range; nothing in the routing is fitted to any of them.
_LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)


def _finger(log_e: float, options: SimOptions = _PRINTED):
    built = build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=options)
    return built, make_data(built)


def _spans() -> list[tuple[float, float]]:
    """(a, b) [m]: each flexure hinge's distance to the channel exit before it and the entry after it."""
    pts = channel_points(FingerDesign())
    flex = [b for b in FingerDesign().blocks() if b.kind is BlockKind.FLEXURE]
    return [(f.mid - pts[k, 2, 0], pts[k + 1, 0, 0] - f.mid) for k, f in enumerate(flex)]


@pytest.mark.parametrize("log_e", _LOG_E)
def test_buckling_tension_of_uniform_fingers_matches_the_closed_form(log_e):
    # A string pulled at tension T straight across a hinge, from a before it to b after it, has
    # d²ℓ/dθ² = −ab/(a+b): the hinge's stiffness k becomes k − T ab/(a+b), zero at
    #     T_crit = k (a+b) / (ab)   (= 2k/d for a = b = d).
    # The straight finger's tangent stiffness K_t(T) = K + T H is MuJoCo's (springs and the spatial
    # tendon's actuator force differenced: models.stability), so T_crit is the smallest T with K + T H
    # singular.
    built, _ = _finger(log_e)
    t_crit, mode = buckling_tension(built)
    k = built.model.jnt_stiffness
    closed = [k[2 * i + 1] * (a + b) / (a * b) for i, (a, b) in enumerate(_spans())]
    assert t_crit == pytest.approx(min(closed), rel=_TOL_BUCKLE)
    assert np.argmax(np.abs(mode)) == 1 + 2 * int(np.argmin(closed))  # the flexure that buckles first


def test_guided_tendon_adds_no_geometric_stiffness():
    # The default fixed tendon acts with constant levers: its force does not change with the angles,
    # so no tension can buckle it (the contrast with the printed routing above).
    built, _ = _finger(13.5, SimOptions(gravity=False))
    K0 = tangent_stiffness(built, 0.0)
    np.testing.assert_allclose(tangent_stiffness(built, 10.0), K0, rtol=1e-6, atol=1e-9)
    assert buckling_tension(built)[0] == np.inf


def test_printed_lever_is_the_chords_distance_from_each_flexure_hinge():
    # A straight span shortens at dℓ/dθ = −(distance from the hinge axis to the span's line).
    built, d = _finger(15.0)
    m = built.model
    ten = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, built.fingers[0].tendons[0])

    def length(q):
        d.qpos[:] = q
        mujoco.mj_fwdPosition(m, d)
        return d.ten_length[ten]

    lever = [(length(e * _FD) - length(-e * _FD)) / (2 * _FD) for e in np.eye(m.nq)]
    pts = channel_points(FingerDesign())
    axes = m.jnt_pos[:, 2]  # hinge heights above the back [m]
    flex = [b for b in FingerDesign().blocks() if b.kind is BlockKind.FLEXURE]
    for k, f in enumerate(flex):
        (x0, _, z0), (x1, _, z1) = pts[k, 2], pts[k + 1, 0]
        z_line = z0 + (z1 - z0) * (f.mid - x0) / (x1 - x0)
        dist = (z_line - axes[f.index]) * (x1 - x0) / np.hypot(x1 - x0, z1 - z0)
        assert lever[f.index] == pytest.approx(-dist, abs=_TOL_LEVER)


def test_printed_tendon_runs_through_every_channel_and_nothing_else():
    built, _ = _finger(15.0)
    m = built.model
    (chain,) = built.fingers[0].site_chains
    assert len(chain) == 3 * len(PRINTED_CHANNELS)
    ten = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, built.fingers[0].tendons[0])
    adr, num = m.tendon_adr[ten], m.tendon_num[ten]
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, m.wrap_objid[w]) for w in range(adr, adr + num)]
    assert names == ["A_tendon_exit", *chain]
    assert not any(n.startswith("A_wp") for n in names)  # no guide on a flexure


def test_channels_lie_in_the_printed_fingers_holes(reference_dir):
    trimesh = pytest.importorskip("trimesh")
    stl = trimesh.load(reference_dir / "hardware" / "sim_finger.stl")  # mm; x across, y up, z along
    for entry, _, exit_ in channel_points(FingerDesign()):
        # 1 mm inside each mouth (the STL's segment ends are rounded) and at the middle
        for x in (entry[0] + 1e-3, 0.5 * (entry[0] + exit_[0]), exit_[0] - 1e-3):
            z = entry[2] + (exit_[2] - entry[2]) * (x - entry[0]) / (exit_[0] - entry[0])
            sec = stl.section(plane_origin=[0, 0, x * 1e3], plane_normal=[0, 0, 1])
            flat, _ = sec.to_2D(to_2D=np.eye(4))
            holes = [np.array(h.coords)[:, 1].mean() * 1e-3 for p in flat.polygons_full for h in p.interiors]
            assert holes, f"no channel at {x * 1e3:.2f} mm"
            assert min(abs(h - z) for h in holes) < _TOL_HOLE


def test_printed_routing_is_refused_where_it_does_not_apply():
    with pytest.raises(DesignError, match="routing"):
        SimOptions(routing="straight")
    with pytest.raises(DesignError, match="6-segment"):
        options = SimOptions(routing="printed", stiffness_model="beam")
        build_finger(
            FingerDesign(n_segments=5), Stiffness([15.0] * 9, n_blocks=9), FingerModel.CHAIN, options=options
        )
    with pytest.raises(UnsupportedError, match="printed"):
        build_finger(FingerDesign(), Stiffness([15.0] * 11), FingerModel.FLEX, options=_PRINTED)
    with pytest.raises(UnsupportedError, match="printed"):
        build_finger(
            FingerDesign(),
            Stiffness([15.0] * 11),
            FingerModel.CHAIN,
            options=_PRINTED,
            tendon_mode=TendonMode.POINT_FORCE,
        )


def test_routing_flag_gives_the_options():
    from mjcodesign.cli.common import Parser
    from mjcodesign.cli.finger_flags import add_routing, routing_options

    p = Parser()
    add_routing(p)
    assert routing_options(p.parse_args([])) is None
    assert routing_options(p.parse_args(["--routing", "printed"])) == SimOptions(routing="printed")
    assert routing_options(argparse.Namespace()) is None


def test_grasp_routing_flag_reaches_the_model(tmp_path, monkeypatch, capsys):
    import json

    import trimesh

    import mjcodesign.cli.grasp as cg
    from mjcodesign.cli.main import main

    monkeypatch.setattr(cg, "user_cache_dir", lambda: tmp_path / "cache")
    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    outs = {}
    for routing in ("guided", "printed"):
        args = [
            "grasp",
            "--object",
            str(box),
            "--regime",
            "paper",
            "--density",
            "heavy",
            "--design",
            "semi-rigid",
            "--json",
        ]
        assert main([*args, "--routing", routing]) == 0
        outs[routing] = json.loads(capsys.readouterr().out)
    assert outs["guided"]["success"] and outs["printed"]["success"]  # routing_compare: both hold it at 10 N
    assert outs["guided"]["displacement"] != outs["printed"]["displacement"]


def test_datagen_routing_is_recorded_and_reaches_every_rollout(tmp_path, monkeypatch):
    import dataclasses
    import json

    import trimesh

    import mjcodesign.jobs as jobs
    from mjcodesign.cli.main import main
    from mjcodesign.data import DatagenConfig, parse_density_spec

    base = DatagenConfig(
        objects=("013_apple",), poses_per_object=1, designs_per_pose=1, density=parse_density_spec("light")
    )
    printed = dataclasses.replace(base, routing="printed")
    assert base.options is None and printed.options == SimOptions(routing="printed")
    assert base.as_dict()["sim_options"] == dataclasses.asdict(SimOptions())  # guided keeps its fingerprint
    assert printed.fingerprint() != base.fingerprint()
    assert DatagenConfig.from_dict(printed.as_dict()) == printed
    with pytest.raises(DesignError, match="--routing"):
        dataclasses.replace(base, routing="straight")
    with pytest.raises(UnsupportedError, match="chain"):
        dataclasses.replace(base, routing="printed", model=FingerModel.FLEX)

    seen = []
    run = jobs.run_jobs
    monkeypatch.setattr(jobs, "run_jobs", lambda js, *a, **k: seen.extend(js) or run(js, *a, **k))
    monkeypatch.setattr("mjcodesign.data.tasks.run_jobs", jobs.run_jobs)
    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    out = tmp_path / "ds"
    args = ["datagen", "--objects", str(box), "--regime", "paper", "--poses-per-object", "1"]
    assert main([*args, "--designs-per-pose", "2", "--routing", "printed", "--out", str(out)]) == 0
    assert json.loads((out / "manifest.json").read_text())["config"]["sim_options"]["routing"] == "printed"
    assert seen and all(j.options == SimOptions(routing="printed") for j in seen)


_TOL_REST = 5e-4  # hinge angle [rad]: run_to_rest's stop against the energy minimum (measured ≤ 1.1e-4)


def _planar_tendon(design: FingerDesign):
    """ℓ(θ) [m]: the printed tendon's length at hinge angles θ, by planar kinematics alone (no MuJoCo)."""
    from mjcodesign.models.chain import hinge_axes
    from mjcodesign.models.types import tendon_exit_site

    hinges = np.array([[b.mid, a] for b, a in zip(design.blocks(), hinge_axes(design), strict=True)])
    segments = [b.index for b in design.blocks() if b.kind is BlockKind.SEGMENT]
    # (point (x, z, 1), body: -1 the base) of every site the tendon passes, in order
    sites = [(np.r_[tendon_exit_site(design)[[0, 2]], 1.0], -1)]
    for i, pts in zip(segments, channel_points(design), strict=True):
        sites += [(np.r_[p[[0, 2]], 1.0], k) for p, k in zip(pts, (i - 1, i, i), strict=True)]

    def length(theta: np.ndarray) -> float:
        frames = [np.eye(3)]  # body k's pose: turned about hinges 0..k in turn (homogeneous, 3x3)
        for (hx, hz), th in zip(hinges, theta, strict=True):
            c, s = np.cos(th), np.sin(th)
            turn = np.array([[c, -s, hx - c * hx + s * hz], [s, c, hz - s * hx - c * hz], [0.0, 0.0, 1.0]])
            frames.append(frames[-1] @ turn)
        xy = np.array([(frames[k + 1] @ p)[:2] for p, k in sites])
        return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())

    return length


@pytest.mark.parametrize("seed", [1, 3])
def test_printed_curl_is_the_minimum_of_spring_and_tendon_energy(seed):
    # At rest under tension T the chain minimises U(θ) = ½ Σ k_j θ_j² + T ℓ(θ), ℓ the length of the
    # tendon through the channel points placed by planar kinematics (no MuJoCo). Up to ~1.7 rad of bend,
    # below buckling and short of every stop (no active constraint), MuJoCo's rest must be that minimum.
    from scipy.optimize import minimize

    from mjcodesign.scenarios.static import curl

    design, stiffness = FingerDesign(), Stiffness.random(seed)
    built = build_finger(design, stiffness, FingerModel.CHAIN, options=_PRINTED)
    k = built.model.jnt_stiffness.copy()
    tension = 0.2 * buckling_tension(built)[0]
    rest = {}
    curl(
        design,
        stiffness,
        FingerModel.CHAIN,
        tension,
        options=SimOptions(routing="printed"),
        observe=lambda b, d: rest.update(q=d.qpos.copy(), constraints=d.nefc),
    )
    assert rest["constraints"] == 0  # no stop reached: the energy below is the whole story

    length = _planar_tendon(design)

    def energy(theta):
        return 0.5 * k @ theta**2 + tension * length(theta)

    ref = minimize(energy, np.zeros(len(k)), method="BFGS", options={"gtol": 1e-10}).x
    assert ref.sum() > 0.5  # a real curl, not the straight finger
    np.testing.assert_allclose(rest["q"], ref, atol=_TOL_REST)
