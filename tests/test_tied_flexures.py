"""The printed chain's default flexures: two hinges tied to one angle by MuJoCo joint equalities.

Its options, its ties, its buckling tension against the converged FEM and the tied-coordinate
projection, what it does past buckling, and a grasp under the servo (its curl below buckling against the
FEM's recorded curls: tests/test_flexure_hinges.py). The FEM's numbers are read from ``tests/data/fem_routing_*.json`` and never rerun.
"""

import importlib.util
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.models import build_finger, build_gripper
from mjcodesign.models.chain import TIE_SOLIMP, flexure_stops, hinge_axes, tie_solref
from mjcodesign.models.stability import buckling_tension, equality_basis
from mjcodesign.models.types import (
    DEFAULT_TIMESTEP,
    PRINTED_FLEXURE_HINGES,
    TIED_TIMESTEP,
    FingerModel,
    SimOptions,
)
from mjcodesign.scenarios.static import rest_options

_ROOT = Path(__file__).parent.parent
_DATA = Path(__file__).parent / "data"
_TIED = SimOptions(routing="printed", gravity=False)
_TOL_BUCKLE = 0.15  # tied chain's buckling tension vs the converged FEM's global modes (issue's target)
_TOL_SAME = 1e-9  # MuJoCo's built ties vs the script's projection: the same eigenproblem, round-off only
# Largest |θ_j − θ_{j+1}| of a tied flexure during a rollout [rad]: a soft constraint at MuJoCo's highest
# impedance corrects a violation within ~2 steps, but the implicit hinge damping (b = β k, far above the
# light middle link's inertia over a step) is applied after the constraint solve and lets the pair part
# while the finger whips. Measured: free curls to rest at 10-50 N 0.004-0.057 rad; real-regime grasps of
# benchmarks/records/2026-12-05_tied_flexure_grasps.json up to 0.119 rad; this file's box grasp 0.012 rad.
# A free pair past buckling folds to ±2.5 rad (tests/test_flexure_hinges.py).
_TOL_TIE_MOTION = 0.15
_TOL_TIE_REST = 1e-4  # [rad] at rest the tie holds the pair (the 2-ms reference corrects it fully)
_TOL_STOP = 0.05  # [rad] a flexure's sum past its stop at rest: soft stops at 2 dt under ~20x T_crit
_LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)  # uniform fingers, those of tests/test_routing.py
_FLEXURES = (1, 3, 5, 7, 9)


def _record(name: str) -> dict:
    return json.loads((_DATA / f"fem_routing_{name}.json").read_text())["record"]


def _fem_global(log_e: float) -> float:
    """The converged FEM's buckling tension over its global modes [N] at ``log_e`` (∝ E on uniform fingers)."""
    row = _record("refinement")["refinement"][-1]
    return row["fem_global_n"] * np.exp(log_e - row["log_e"])


@pytest.fixture(scope="module")
def projection():
    spec = importlib.util.spec_from_file_location(
        "tied_flexure_hinges", _ROOT / "scripts/tied_flexure_hinges.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.tied_buckling_tension


def _pairs(built) -> list[tuple[int, int]]:
    """(dof, dof) of every tied pair: consecutive hinges of one flexure."""
    blocks = np.array(built.fingers[0].joint_blocks)
    out = []
    for f in _FLEXURES:
        j = np.flatnonzero(blocks == f)
        out += list(zip(j[:-1], j[1:], strict=True))
    return out


def test_the_printed_routing_defaults_to_two_tied_hinges_per_flexure_at_a_finer_step():
    printed = SimOptions(routing="printed")
    assert (printed.hinges_per_block, printed.tied_flexures, printed.timestep) == (
        PRINTED_FLEXURE_HINGES,
        True,
        TIED_TIMESTEP,
    )
    guided = SimOptions()
    assert (guided.hinges_per_block, guided.tied_flexures, guided.timestep) == (1, False, DEFAULT_TIMESTEP)
    one = SimOptions(routing="printed", hinges_per_block=1)
    assert (one.tied_flexures, one.timestep) == (False, DEFAULT_TIMESTEP)  # one hinge between guides
    assert not SimOptions(routing="printed", hinges_per_block=3).tied_flexures  # n free hinges, as asked
    assert SimOptions(routing="printed", tied_flexures=False).hinges_per_block == 1
    for bad in (
        dict(tied_flexures=True),
        dict(routing="printed", hinges_per_block=1, tied_flexures=True),
    ):
        with pytest.raises(DesignError, match="tied_flexures"):
            SimOptions(**bad)
    with pytest.raises(DesignError, match="True, False or None"):
        SimOptions(routing="printed", tied_flexures=1)


def test_replace_resolves_the_routing_defaults_again_and_keeps_what_was_given():
    assert SimOptions().replace(routing="printed") == SimOptions(routing="printed")  # tied, 1 ms
    assert SimOptions(routing="printed").replace(routing="guided") == SimOptions()
    one = SimOptions(routing="printed", hinges_per_block=1, friction=0.6)
    assert one.replace(friction=1.0) == SimOptions(routing="printed", hinges_per_block=1)  # still one hinge
    fine = SimOptions(timestep=5e-4).replace(routing="printed")
    assert (fine.timestep, fine.tied_flexures) == (5e-4, True)  # a given step stays given
    assert SimOptions().replace(routing="printed", timestep=2e-3).timestep == 2e-3
    with pytest.raises(DesignError, match="no field colour"):
        SimOptions().replace(colour="red")


def test_each_flexures_hinges_are_tied_by_a_joint_equality():
    built = build_finger(FingerDesign(), Stiffness([15.0] * 11), FingerModel.CHAIN, options=_TIED)
    m = built.model
    pairs = _pairs(built)
    assert m.neq == len(pairs) == len(_FLEXURES) * (PRINTED_FLEXURE_HINGES - 1)
    got = {(int(m.jnt_dofadr[m.eq_obj1id[e]]), int(m.jnt_dofadr[m.eq_obj2id[e]])) for e in range(m.neq)}
    assert got == {(int(a), int(b)) for a, b in pairs}
    np.testing.assert_array_equal(m.eq_type, mujoco.mjtEq.mjEQ_JOINT)
    np.testing.assert_array_equal(m.eq_data[:, :5], np.tile([0.0, 1.0, 0.0, 0.0, 0.0], (m.neq, 1)))  # θ1 = θ2
    np.testing.assert_allclose(m.eq_solref, np.tile(tie_solref(TIED_TIMESTEP), (m.neq, 1)))
    np.testing.assert_allclose(m.eq_solimp, np.tile(TIE_SOLIMP, (m.neq, 1)))
    # the allowed directions: one angle per block, a flexure's split equally over its two hinges
    N = equality_basis(built)
    assert N.shape == (m.nv, 11)
    for a, b in pairs:
        np.testing.assert_allclose(N[a], N[b], atol=1e-12)
    # the guided chain and the one-hinge printed chain have no ties
    for opts in (SimOptions(gravity=False), SimOptions(routing="printed", hinges_per_block=1)):
        assert (
            build_finger(FingerDesign(), Stiffness([15.0] * 11), FingerModel.CHAIN, options=opts).model.neq
            == 0
        )


@pytest.mark.parametrize("log_e", _LOG_E)
def test_buckling_tension_matches_the_converged_fem_over_its_global_modes(log_e):
    # K(T) = K0 + T H (MuJoCo's spring and tendon forces) restricted to the ties' null space, singular at
    # T_crit; against the converged FEM's buckling over its global modes, both with the printed routing.
    built = build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=_TIED)
    t_crit, mode = buckling_tension(built)
    assert t_crit == pytest.approx(_fem_global(log_e), rel=_TOL_BUCKLE)
    flex1 = np.flatnonzero(np.array(built.fingers[0].joint_blocks) == 1)
    np.testing.assert_allclose(mode[flex1], 1.0, atol=1e-9)  # flexure 1 goes first, as the FEM's mode


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_built_ties_buckle_as_the_tied_coordinate_projection_on_random_designs(projection, seed):
    # The free two-hinge chain's tangent stiffness projected on one angle per block (C, a flexure's angle
    # split equally over its hinges): C^T (K0 + T H) C singular (scripts/tied_flexure_hinges.py) is what the
    # built equalities allow; and tying can only raise the free chain's buckling tension (a restriction).
    stiffness = Stiffness.random(seed)
    counts = np.array([2 if b.kind is BlockKind.FLEXURE else 1 for b in FingerDesign().blocks()])
    free = build_finger(
        FingerDesign(),
        stiffness,
        FingerModel.CHAIN,
        options=SimOptions(routing="printed", gravity=False, hinges_per_block=2),
    )
    tied = build_finger(FingerDesign(), stiffness, FingerModel.CHAIN, options=_TIED)
    t_tied = buckling_tension(tied)[0]
    assert t_tied == pytest.approx(projection(free, counts), rel=_TOL_SAME)
    assert t_tied >= buckling_tension(free)[0] * (1 - _TOL_SAME)


@pytest.mark.parametrize("design", ["soft", "random:21"])
def test_past_buckling_the_tied_flexures_curl_to_their_stops_without_an_s(design):
    # At 10 N (soft: 20x its buckling tension) the free two-hinge chain folds flexure 1 into an S at
    # +2.9 / -2.5 rad and never rests (tests/test_flexure_hinges.py). Tied, every flexure's hinges stay
    # equal, each flexure turns inwards, and the finger comes to rest with no flexure past its stop.
    fd, stiffness = FingerDesign(), Stiffness.parse(design)
    built = build_finger(
        fd, stiffness, FingerModel.CHAIN, options=rest_options(fd, stiffness.finger(0), _TIED)
    )
    m, d = built.model, mujoco.MjData(built.model)
    assert buckling_tension(build_finger(fd, stiffness, FingerModel.CHAIN, options=_TIED))[0] < 10.0
    act = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, built.fingers[0].actuators[0])
    d.ctrl[act] = 10.0
    pairs = _pairs(built)
    worst = 0.0
    for _ in range(int(1.0 / m.opt.timestep)):
        mujoco.mj_step(m, d)
        worst = max(worst, max(abs(d.qpos[a] - d.qpos[b]) for a, b in pairs))
    assert d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    assert worst < _TOL_TIE_MOTION
    assert max(abs(d.qpos[a] - d.qpos[b]) for a, b in pairs) < _TOL_TIE_REST
    blocks = np.array(built.fingers[0].joint_blocks)
    stops = flexure_stops(fd, hinge_axes(fd))
    for f in _FLEXURES:
        turn = d.qpos[blocks == f].sum()
        assert 0.0 < turn < stops[f, 1] + _TOL_STOP


def test_gripper_refuses_what_cannot_grasp_with_one_line():
    design, semi = FingerDesign(), Stiffness.preset("semi-rigid")
    for options, match in (
        (SimOptions(routing="printed", hinges_per_block=2), "S that nothing stops"),
        (SimOptions(routing="printed", hinges_per_block=3, tied_flexures=True), "2 tied hinges per flexure"),
    ):
        with pytest.raises(UnsupportedError, match=match) as err:
            build_gripper(design, semi, FingerModel.CHAIN, options=options)
        assert "\n" not in str(err.value)
    assert (
        build_gripper(design, semi, FingerModel.CHAIN, options=SimOptions(routing="printed")).model.neq
        == 2 * 5
    )


class _Ties:
    """Observer: the largest tie violation [rad] over a grasp rollout's states, both fingers."""

    worst = None

    def rollout(self, rollout) -> None:
        from mjcodesign.sim.mujoco_c import STATE_SPEC

        m = rollout.model
        d = mujoco.MjData(m)
        pairs = [(m.jnt_qposadr[m.eq_obj1id[e]], m.jnt_qposadr[m.eq_obj2id[e]]) for e in range(m.neq)]
        worst = 0.0
        for row in rollout.states:
            mujoco.mj_setState(m, d, row, mujoco.mjtState(STATE_SPEC))
            worst = max(worst, max((abs(d.qpos[a] - d.qpos[b]) for a, b in pairs), default=0.0))
        self.worst = worst

    def snapshot(self, snapshot) -> None:
        """Grasps only."""

    def close(self) -> None:
        """Nothing to flush."""


def test_a_grasp_under_the_servo_holds_the_ties_and_does_not_diverge():
    # The real regime (the XL330 servo at 1000 ticks pulls tens of newtons): the one-hinge chain between
    # guides diverged on every grasp checked (benchmarks/records/2026-12-05_tied_flexure_grasps.json).
    from mjcodesign.objects import box_object
    from mjcodesign.scenarios import get_regime
    from mjcodesign.scenarios.grasp import auto_pose, build_scene
    from mjcodesign.sim import MujocoBackend

    obj = box_object((0.05,) * 3, 400.0)  # the tests' 50 g box
    scenario = get_regime("real").scenario
    scene = build_scene(
        obj,
        FingerDesign(),
        Stiffness.preset("semi-rigid"),
        FingerModel.CHAIN,
        auto_pose(obj),
        options=SimOptions(routing="printed"),
    )
    ties = _Ties()
    out = MujocoBackend(nthread=1).run(scene, scenario, observer=ties)
    assert not out.failures or not any(f.is_sample_error for f in out.failures), out.reason
    assert out.success, out.reason
    assert ties.worst is not None and ties.worst < _TOL_TIE_MOTION


@pytest.mark.parametrize("text", ["random:3", ",".join(["14", "17"] * 11)])
def test_a_batchs_design_rewrite_equals_a_recompile(text):
    # Evaluations and datasets write each design into a copy of one scene's model (with_stiffness) instead
    # of compiling it: with the ties, every hinge, damping and piece solref must equal a recompile, the
    # ties themselves included (they do not depend on the design).
    from numpy.testing import assert_array_equal

    from mjcodesign.objects import box_object
    from mjcodesign.scenarios.grasp import auto_pose, build_scene
    from mjcodesign.sim import with_stiffness

    obj, printed = box_object((0.05,) * 3, 400.0), SimOptions(routing="printed")
    pose, design = auto_pose(obj), Stiffness.parse(text)
    scene = build_scene(
        obj, FingerDesign(), Stiffness.preset("soft"), FingerModel.CHAIN, pose, options=printed
    )
    ref = build_scene(obj, FingerDesign(), design, FingerModel.CHAIN, pose, options=printed).model
    m = with_stiffness(scene, design)
    assert m.neq == ref.neq == 2 * len(_FLEXURES)
    names = ("jnt_stiffness", "dof_damping", "geom_solref", "body_mass", "eq_data", "eq_solref", "eq_solimp")
    for name in names:
        assert_array_equal(getattr(m, name), getattr(ref, name), err_msg=name)
