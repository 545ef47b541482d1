"""The chain's printed tendon routing: channel sites, lever and buckling tension from the tendon's path."""

import argparse
import functools

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.models import TendonMode, build_finger, make_data
from mjcodesign.models.channels import PRINTED_CHANNELS, channel_points, flexure_guides
from mjcodesign.models.stability import (
    beam_string_buckling_tension,
    buckling_tension,
    string_buckling_tension,
    tangent_stiffness,
)
from mjcodesign.models.types import FingerModel, SimOptions

# The printed chain with one hinge per flexure between its guides (the printed default ties two per flexure:
# tests/test_tied_flexures.py).
_PRINTED = SimOptions(routing="printed", gravity=False, hinges_per_block=1)
# One-hinge chain vs the 400-hinge closed form in the chord's frame: the form's own gap to the beam (1/n²,
# measured 3.7e-6 to 4.9e-6); the chain is within 5e-10 of the beam's (stability.beam_string_buckling_tension).
_TOL_BEAM = 1e-5
_BEAM_HINGES = 400  # the closed form's hinges standing for a continuous flexure
_EARLY = 1.7  # the beam vs one hinge across the channel ends: 1.74-2.33x on the default finger's flexures
_TOL_ORDER = 1e-4  # the n-hinge form's gap ratio halving n: 4 (1/n²) up to its O(n⁻⁴) part (1.9e-5)
_TOL_SHORT = 1e-4  # a 0.1 µm flexure vs one hinge: the beam's correction of order l/a (1.4e-5)
_TOL_CHORD = 1e-12  # guides' path length vs the chord's, relative: round-off of ~10 mm sums
_TOL_LEVER = 1e-6  # tendon lever [m/rad] vs the chord's distance from the hinge: finite differences only
_TOL_HOLE = 0.1e-3  # channel height vs the STL's hole centre [m]: the line fit's residual is 0.08 mm
_FD = 1e-6  # central-difference step of a hinge angle [rad]
# ln E of uniform fingers across the printable range; nothing in the routing is fitted to any of them.
_LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)


def _finger(log_e: float, options: SimOptions = _PRINTED):
    built = build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=options)
    return built, make_data(built)


def _chord_frames(built) -> list[tuple[int, float, float, float, float]]:
    """Every flexure in the frame of the tendon's chord across it, from the built finger's own geometry.

    (block, s0, s_mid, s1, span): the feet of the flexure's axis points at its ends and middle on the chord
    from the channel exit before it (A, at s = 0) to the entry after it (B, at s = span) [m].
    """
    design = FingerDesign()
    pts = channel_points(design)
    axes = built.model.jnt_pos[:, 2]  # hinge heights above the back [m], one hinge per block
    out = []
    for j, f in enumerate(b for b in design.blocks() if b.kind is BlockKind.FLEXURE):
        a, b = pts[j, 2][[0, 2]], pts[j + 1, 0][[0, 2]]
        span = float(np.linalg.norm(b - a))
        t = (b - a) / span
        s0, s_mid, s1 = ((np.array([x, axes[f.index]]) - a) @ t for x in (f.x0, f.mid, f.x1))
        out.append((f.index, s0, s_mid, s1, span))
    return out


@functools.lru_cache
def _unit_beam(s0: float, s1: float, span: float) -> float:
    """The 400-hinge closed form of a flexure over [s0, s1] under a string over [0, span], k = 1 (T ∝ k)."""
    return string_buckling_tension(1.0, s0, s1, 0.0, span, _BEAM_HINGES)


# Designs never tuned on: uniform across the printable range, and random ones (seeds outside the
# calibration's training and the FEM records').
_DESIGNS = [Stiffness([e] * 11) for e in _LOG_E] + [Stiffness.random(seed) for seed in (20, 21, 22, 23, 24)]


@pytest.mark.parametrize(
    "stiffness", _DESIGNS, ids=[f"uniform{e}" for e in _LOG_E] + [f"random{s}" for s in range(20, 25)]
)
def test_buckling_tension_is_the_continuous_flexures(stiffness):
    # Flexure i as an Euler–Bernoulli beam (EI = k_i l, its n → ∞ hinges) under the tendon straight from
    # the channel exit before it to the entry after it, in the chord's frame (the hinge points' feet on
    # it, s = (p − A)·t): T_i = string_buckling_tension with n = 400 hinges (1/n² short of the beam,
    # 4e-6). A string across one hinge from α before it to β after it has d²ℓ/dθ² = −αβ/(α+β), so
    # the hinge's stiffness k becomes k − T αβ/(α+β) and buckles at
    #     T_crit = k (α+β) / (αβ);
    # the chain's guides sit where that is T_i (mjcodesign.models.channels.flexure_guides). The straight
    # finger's tangent stiffness K_t(T) = K + T H is MuJoCo's (springs and the spatial tendon's actuator
    # force differenced: models.stability), so T_crit is the smallest T with K + T H singular.
    built = build_finger(FingerDesign(), stiffness, FingerModel.CHAIN, options=_PRINTED)
    t_crit, mode = buckling_tension(built)
    k = built.model.jnt_stiffness
    beam = [k[i] * _unit_beam(s0, s1, span) for i, s0, _, s1, span in _chord_frames(built)]
    assert t_crit == pytest.approx(min(beam), rel=_TOL_BEAM)
    assert np.argmax(np.abs(mode)) == 1 + 2 * int(np.argmin(beam))  # the flexure that buckles first
    # the one hinge between the channel ends alone would buckle 1.74-2.33x earlier
    single = [k[i] * span / (s_mid * (span - s_mid)) for i, _, s_mid, _, span in _chord_frames(built)]
    assert min(single) < min(beam) / _EARLY


def test_beam_closed_form_is_the_many_hinge_limit():
    # beam_string_buckling_tension solves ω l = atan(1/(ω a₀)) + atan(1/(ω b₁)), T = EI ω² (EI = k l);
    # the n-hinge form approaches it as 1/n². With the string's ends at the flexure's (a₀ = b₁ = 0) it is
    # Euler's pinned column, T = π² EI / l²; a short flexure is the single hinge's k (a+b)/(ab).
    k, x0, x1, x_a, x_b = 2e-3, 0.0, 8e-3, -3.4e-3, 8.6e-3
    beam = beam_string_buckling_tension(k, x0, x1, x_a, x_b)
    gaps = [beam / string_buckling_tension(k, x0, x1, x_a, x_b, n) - 1.0 for n in (100, 200)]
    assert gaps[0] > 0 and gaps[0] / gaps[1] == pytest.approx(4.0, rel=_TOL_ORDER)
    assert beam_string_buckling_tension(k, x0, x1, x0, x1) == pytest.approx(np.pi**2 * k / x1, rel=1e-12)
    short, a, b = 1e-7, 3e-3, 2e-3
    t = beam_string_buckling_tension(k, -short / 2, short / 2, -a, b)
    assert t == pytest.approx(k * (a + b) / (a * b), rel=_TOL_SHORT)
    with pytest.raises(DesignError, match="span"):
        beam_string_buckling_tension(k, x0, x1, x0 + 1e-3, x_b)


def test_guides_sit_on_the_chord_and_span_each_flexure_hinge_alone():
    # Each flexure's two guides lie on the tendon's straight span from the channel exit before it to the
    # entry after it, in order, on the bodies before and after its hinge: the straight finger's tendon
    # path (and length) is the channel ends' chord.
    built, d = _finger(15.0)
    m = built.model
    (chain,) = built.fingers[0].site_chains
    pos = {n: d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n)] for n in chain}
    for f in (b for b in FingerDesign().blocks() if b.kind is BlockKind.FLEXURE):
        a, p, q, b = (
            pos[f"A_{n}"]
            for n in (f"ch{f.index - 1}_out", f"guide{f.index}_p", f"guide{f.index}_d", f"ch{f.index + 1}_in")
        )
        span = np.linalg.norm(b - a)
        parts = [np.linalg.norm(p - a), np.linalg.norm(q - p), np.linalg.norm(b - q)]
        assert sum(parts) == pytest.approx(span, rel=_TOL_CHORD) and min(parts) > 0  # collinear, in order
        hinge = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"A_hinge{f.index}")
        body = m.jnt_bodyid[hinge]
        sites = {n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"A_guide{f.index}_{n}") for n in "pd"}
        assert m.site_bodyid[sites["d"]] == body and m.site_bodyid[sites["p"]] == m.body_parentid[body]


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


def test_printed_tendon_runs_through_every_channel_and_each_flexures_guides():
    built, _ = _finger(15.0)
    m = built.model
    (chain,) = built.fingers[0].site_chains
    segments = [b.index for b in FingerDesign().blocks() if b.kind is BlockKind.SEGMENT]
    expected = []
    for i in segments:
        expected += [f"A_ch{i}_{end}" for end in ("in", "mid", "out")]
        if i + 1 < FingerDesign().n_blocks:
            expected += [f"A_guide{i + 1}_p", f"A_guide{i + 1}_d"]
    assert chain == expected and len(chain) == 3 * len(PRINTED_CHANNELS) + 2 * (len(PRINTED_CHANNELS) - 1)
    ten = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, built.fingers[0].tendons[0])
    adr, num = m.tendon_adr[ten], m.tendon_num[ten]
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, m.wrap_objid[w]) for w in range(adr, adr + num)]
    assert names == ["A_tendon_exit", *chain]
    assert not any(n.startswith("A_wp") for n in names)  # none of the guided routing's waypoints


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


# This config's fingerprint before SimOptions had tied flexures (computed at commit 567b356): its rows
# are unchanged, so its fingerprint must be too.
_GUIDED_FINGERPRINT = "f088e2529672d23c73c291c01ecc82cfb46972c8bfbc7ca744b68840a1259778"


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
    assert base.fingerprint() == _GUIDED_FINGERPRINT  # guided keeps its fingerprint
    assert "tied_flexures" not in base.as_dict()["sim_options"]
    assert printed.as_dict()["sim_options"]["tied_flexures"] is True  # the rows are the tied chain's
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
    guides = flexure_guides(design, hinge_axes(design))
    sites = [(np.r_[tendon_exit_site(design)[[0, 2]], 1.0], -1)]
    for j, (i, pts) in enumerate(zip(segments, channel_points(design), strict=True)):
        sites += [(np.r_[p[[0, 2]], 1.0], k) for p, k in zip(pts, (i - 1, i, i), strict=True)]
        if j < len(guides):  # flexure i + 1's guides, before and after its hinge
            sites += [(np.r_[p[[0, 2]], 1.0], k) for p, k in zip(guides[j], (i, i + 1), strict=True)]

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
    # tendon through the channel points and the flexures' guides placed by planar kinematics (no MuJoCo).
    # Up to ~2.6 rad of bend, below buckling and short of every stop (no active constraint), MuJoCo's
    # rest must be that minimum.
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
        options=SimOptions(routing="printed", hinges_per_block=1),
        observe=lambda b, d: rest.update(q=d.qpos.copy(), constraints=d.nefc),
    )
    assert rest["constraints"] == 0  # no stop reached: the energy below is the whole story

    length = _planar_tendon(design)

    def energy(theta):
        return 0.5 * k @ theta**2 + tension * length(theta)

    ref = minimize(energy, np.zeros(len(k)), method="BFGS", options={"gtol": 1e-10}).x
    assert ref.sum() > 0.5  # a real curl, not the straight finger
    np.testing.assert_allclose(rest["q"], ref, atol=_TOL_REST)
