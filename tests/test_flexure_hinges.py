"""The printed chain with several hinges per flexure: its hinges, the tendon across them, its buckling
tension against the n-hinge closed form and the FEM with the same routing, its curl below buckling.

The FEM's numbers are read from ``tests/data/fem_routing_*.json`` (``scripts/fem_routing_record.py``) and
never rerun; the chain's are computed here (milliseconds each).
"""

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.models import build_finger, build_gripper, make_data
from mjcodesign.models.chain import flexure_stops, hinge_axes, hinge_stiffness
from mjcodesign.models.channels import channel_points
from mjcodesign.models.stability import buckling_tension, string_buckling_tension
from mjcodesign.models.types import MAX_FLEXURE_HINGES, FingerModel, SimOptions
from mjcodesign.scenarios.static import curl, rest_options

_DATA = Path(__file__).parent / "data"
_TOL_BUCKLE = (
    0.15  # chain's buckling tension vs the FEM's over its global modes, same routing (issue's target)
)
_TOL_CURL = 0.10  # chain's curl vs the FEM's, same routing, below buckling (issue's target)
# Chain vs the n-hinge closed form: the chord's slope and height, which the form leaves out (measured 4.1-4.9%
# for n = 2 to 16; 4.9% for one hinge across the channel ends, as the FEM records' chain had it).
_TOL_FORM = 0.06
_TOL_LEVER = 1e-6  # tendon lever [m/rad] vs the chord's distance from the hinge: finite differences only
# The record's one-hinge chain vs its closed form: finite differences of models.stability.
_TOL_RECORDED = 1e-6
_EARLY = 1.7  # the one-hinge chain with its guides vs without (the record's): 1.74x on the first flexure
# One-hinge chain vs the 8/16-hinge chains' Richardson limit: its O(n⁻⁴) remainder, measured 1.3e-5.
_TOL_RICHARDSON = 5e-5
_FD = 1e-6  # central-difference step of a hinge angle [rad]
_LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)  # uniform fingers, those of tests/test_routing.py
_HINGES = (2, 3, 4, 8)  # hinges per flexure held to the targets
_FOLD = 2.0  # [rad]: a flexure hinge past this, with its neighbour as far the other way, is an S-fold


def _options(n: int, **kw) -> SimOptions:
    return SimOptions(routing="printed", gravity=False, hinges_per_block=n, **kw)


def _finger(n: int, log_e: float = 15.0):
    return build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=_options(n))


def _record(name: str) -> dict:
    return json.loads((_DATA / f"fem_routing_{name}.json").read_text())["record"]


def _fem_global(log_e: float) -> float:
    """The converged FEM's buckling tension over its global modes [N] at ``log_e``.

    Recorded at ln E 15; a uniform finger's elastic forces are all ∝ E at fixed ν, so T_crit ∝ E exactly
    (tested on the FEM itself in tests/test_fem_routing.py).
    """
    row = _record("refinement")["refinement"][-1]
    return row["fem_global_n"] * np.exp(log_e - row["log_e"])


def _flexure_hinges(built, block: int) -> list[int]:
    return [j for j, b in enumerate(built.fingers[0].joint_blocks) if b == block]


def test_recorded_one_hinge_chain_buckles_across_the_channel_ends():
    # The FEM records' one-hinge chain (chain_n) had the tendon straight from channel exit to entry across
    # each flexure's hinge: a hinge α before and β after the foot of its perpendicular on that chord
    # buckles at k (α+β)/(αβ) (tests/test_routing.py), 1/r of what the guides give it now.
    row = _record("refinement")["refinement"][-1]
    design = FingerDesign()
    built = _finger(1, row["log_e"])
    k = built.model.jnt_stiffness
    pts, axes = channel_points(design), hinge_axes(design)
    single = []
    for j, f in enumerate(b for b in design.blocks() if b.kind is BlockKind.FLEXURE):
        a, b = pts[j, 2][[0, 2]], pts[j + 1, 0][[0, 2]]
        alpha = (np.array([f.mid, axes[f.index]]) - a) @ (b - a) / np.linalg.norm(b - a)
        beta = np.linalg.norm(b - a) - alpha
        single.append(k[f.index] * (alpha + beta) / (alpha * beta))
    assert min(single) == pytest.approx(row["chain_n"], rel=_TOL_RECORDED)
    assert buckling_tension(built)[0] > _EARLY * row["chain_n"]


def test_one_hinge_chain_buckles_as_the_many_hinge_limit():
    # The chains of 8 and 16 hinges per flexure (the tendon straight across them from channel exit to
    # entry) approach the continuous flexure as T_n = T_∞ − c/n² (stability.string_buckling_tension), so
    #     T_∞ ≈ (4 T_16 − T_8) / 3   (Richardson; remainder O(n⁻⁴));
    # the one-hinge chain's guides are placed for T_∞. MuJoCo's forces on both sides, no closed form.
    for log_e in (_LOG_E[0], _LOG_E[-1]):
        t8, t16 = (buckling_tension(_finger(n, log_e))[0] for n in (8, MAX_FLEXURE_HINGES))
        limit = (4.0 * t16 - t8) / 3.0
        assert buckling_tension(_finger(1, log_e))[0] == pytest.approx(limit, rel=_TOL_RICHARDSON)


@pytest.mark.parametrize("n", [*_HINGES, MAX_FLEXURE_HINGES])
def test_flexure_hinges_keep_each_blocks_compliance_and_sit_along_the_flexure(n):
    # n hinges in series, each n k: 1 / k_block = Σ 1 / k_hinge, the block's compliance unchanged;
    # hinge j of a flexure from x0 to x1 at x0 + (j + ½)(x1 − x0)/n; segments keep one hinge at the middle.
    design = FingerDesign()
    built = _finger(n)
    m, d = built.model, make_data(built)
    blocks = np.array(built.fingers[0].joint_blocks)
    kinds = [b.kind for b in design.blocks()]
    assert np.bincount(blocks).tolist() == [n if k is BlockKind.FLEXURE else 1 for k in kinds]
    np.testing.assert_allclose(
        1.0 / np.bincount(blocks, weights=1.0 / m.jnt_stiffness),
        hinge_stiffness(design, np.full(11, np.exp(15.0))),
        rtol=1e-12,
    )
    for blk in design.blocks():
        j = _flexure_hinges(built, blk.index)
        parts = 1 if blk.kind is BlockKind.SEGMENT else n
        expected = blk.x0 + (blk.x1 - blk.x0) * (np.arange(parts) + 0.5) / parts
        np.testing.assert_allclose(d.xanchor[j, 0], expected, rtol=0, atol=1e-12)


def _levers(built) -> np.ndarray:
    """dℓ/dθ [m/rad] of the tendon for every hinge on the straight finger, by central differences."""
    m, d = built.model, make_data(built)
    ten = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, built.fingers[0].tendons[0])

    def length(q):
        d.qpos[:] = q
        mujoco.mj_fwdPosition(m, d)
        return d.ten_length[ten]

    return np.array([(length(e * _FD) - length(-e * _FD)) / (2 * _FD) for e in np.eye(m.nq)])


def test_tendon_crosses_every_flexure_hinge_on_its_chord():
    # A straight span shortens at dℓ/dθ = −(distance from the hinge axis to the span's line), for every
    # hinge under it: the span from one channel's exit to the next one's entry crosses all n.
    built = _finger(3)
    lever, d = _levers(built), make_data(built)
    pts = channel_points(FingerDesign())
    flex = [b for b in FingerDesign().blocks() if b.kind is BlockKind.FLEXURE]
    for k, f in enumerate(flex):
        (x0, _, z0), (x1, _, z1) = pts[k, 2], pts[k + 1, 0]
        for j in _flexure_hinges(built, f.index):
            x, z = d.xanchor[j, 0], d.xanchor[j, 2]  # the hinge's axis on the straight finger
            z_line = z0 + (z1 - z0) * (x - x0) / (x1 - x0)
            dist = (z_line - z) * (x1 - x0) / np.hypot(x1 - x0, z1 - z0)
            assert lever[j] == pytest.approx(-dist, abs=_TOL_LEVER)
    # the segments' hinges see the tendon as they do with one hinge per flexure
    segments = [b.index for b in FingerDesign().blocks() if b.kind is BlockKind.SEGMENT]
    ours = [_flexure_hinges(built, i)[0] for i in segments]
    np.testing.assert_allclose(lever[ours], _levers(_finger(1))[segments], rtol=0, atol=_TOL_LEVER)


@pytest.mark.parametrize("n", [*_HINGES, MAX_FLEXURE_HINGES])
def test_buckling_tension_follows_the_n_hinge_closed_form(n):
    # Flexure i as n hinges of n k_i at its parts' middles under the string from segment i's channel exit
    # to segment i+1's entry (string_buckling_tension); the chain buckles at the smallest over its flexures
    # and adds the chord's slope and height. (One hinge per flexure has guides: tests/test_routing.py.)
    design = FingerDesign()
    built = _finger(n)
    t_crit, mode = buckling_tension(built)
    k = hinge_stiffness(design, np.full(11, np.exp(15.0)))
    pts = channel_points(design)
    flex = [b for b in design.blocks() if b.kind is BlockKind.FLEXURE]
    closed = [
        string_buckling_tension(k[f.index], f.x0, f.x1, pts[j, 2, 0], pts[j + 1, 0, 0], n)
        for j, f in enumerate(flex)
    ]
    assert t_crit == pytest.approx(min(closed), rel=_TOL_FORM)
    first = flex[int(np.argmin(closed))].index
    assert built.fingers[0].joint_blocks[int(np.argmax(np.abs(mode)))] == first


@pytest.mark.parametrize("log_e", _LOG_E)
@pytest.mark.parametrize("n", _HINGES)
def test_chain_buckling_tension_matches_the_converged_fem_over_its_global_modes(n, log_e):
    # The FEM's buckling over its global modes (flexures and segments bending as wholes; mesh-converged,
    # tests/test_fem_routing.py) against the chain's K + T H singular, both with the printed routing. One
    # hinge per flexure: tests/test_fem_routing.py.
    assert buckling_tension(_finger(n, log_e))[0] == pytest.approx(_fem_global(log_e), rel=_TOL_BUCKLE)


# The FEM's printed curls (quadratic tets, h 4 mm, 2 spine layers): random:0-9 at the tensions where the
# one-hinge chain bends 0.8 rad, and at those where it bends 1.3 rad (the FEM bends 1.16-1.23 rad there).
_CURLS = ("curl", "curl13_seeds0-2", "curl13_seeds3-9")


def _curl_cases() -> list:
    return [
        pytest.param(row, id=f"{_record(name)['bend_target_rad']}rad-{row['design']}")
        for name in _CURLS
        for row in _record(name)["curl"]
    ]


# Two and four free hinges per flexure, and the printed routing's default: two tied to one angle.
_CURL_OPTIONS = {"2": _options(2), "4": _options(4), "2-tied": SimOptions(routing="printed", gravity=False)}


@pytest.mark.parametrize("hinges", list(_CURL_OPTIONS))
@pytest.mark.parametrize("row", _curl_cases())
def test_chain_curl_matches_the_fem_below_buckling(row, hinges):
    # Free curl (gravity off) at the record's tension, below buckling; bend (sum of hinge angles against
    # the FEM's tip-section rotation) and |tip| against the FEM's.
    options = _CURL_OPTIONS[hinges]
    built = build_finger(FingerDesign(), Stiffness.parse(row["design"]), FingerModel.CHAIN, options=options)
    assert row["tension_n"] < min(row["chain_t_crit_n"], buckling_tension(built)[0])
    r = curl(FingerDesign(), Stiffness.parse(row["design"]), "chain", row["tension_n"], options=options)
    assert r["bend_angle_rad"] == pytest.approx(row["fem_bend_angle_rad"], rel=_TOL_CURL)
    fem_tip = np.linalg.norm(row["fem_tip_displacement_m"])
    assert np.linalg.norm(r["tip_displacement_m"]) == pytest.approx(fem_tip, rel=_TOL_CURL)


def test_a_flexures_stop_holds_the_sum_of_its_hinges():
    design = FingerDesign()
    built = _finger(4)
    m = built.model
    stops = flexure_stops(design, hinge_axes(design))
    for f in (b for b in design.blocks() if b.kind is BlockKind.FLEXURE):
        hinges = _flexure_hinges(built, f.index)
        assert not m.jnt_limited[hinges].any()
        for name, shares in (
            (f"A_flex{f.index}", {}),
            (f"A_gap{f.index}", {f.index - 1: 0.5, f.index + 1: 0.5}),
        ):
            ten = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, name)
            np.testing.assert_array_equal(m.tendon_range[ten], stops[f.index])
            adr, num = m.tendon_adr[ten], m.tendon_num[ten]
            coef = {int(m.wrap_objid[w]): m.wrap_prm[w] for w in range(adr, adr + num)}
            expected = {j: 1.0 for j in hinges}
            for block, share in shares.items():
                share = 1.0 if block in (0, design.n_blocks - 1) else share
                expected.update({j: share for j in _flexure_hinges(built, block)})
            assert coef == expected


def test_gripper_is_refused_because_flexures_fold_past_buckling():
    # Past buckling the hinges of one flexure can turn opposite ways (an S) at a constant sum, which the
    # stops hold, and the chain's links never touch: soft at 10 N (~20x its buckling tension) folds.
    with pytest.raises(UnsupportedError, match="S that nothing stops"):
        build_gripper(FingerDesign(), Stiffness.preset("soft"), FingerModel.CHAIN, options=_options(2))
    design, soft = FingerDesign(), Stiffness.preset("soft")
    built = build_finger(
        design, soft, FingerModel.CHAIN, options=rest_options(design, soft.finger(0), _options(2))
    )
    m, d = built.model, mujoco.MjData(built.model)
    act = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, built.fingers[0].actuators[0])
    d.ctrl[act] = 10.0
    mujoco.mj_step(m, d, nstep=int(1.0 / m.opt.timestep))
    q = d.qpos[_flexure_hinges(built, 1)]
    assert q.max() > _FOLD and q.min() < -_FOLD


def test_hinges_per_flexure_are_a_whole_number_in_range():
    for bad in (0, MAX_FLEXURE_HINGES + 1, True, 2.0):
        with pytest.raises(DesignError, match="hinges per flexure"):
            SimOptions(routing="printed", hinges_per_block=bad)
    with pytest.raises(DesignError, match="hinges_per_block must be 1 or 2"):
        SimOptions(hinges_per_block=3)  # the guided chain splits every block in two at most
