import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models.flex import add_flex_finger, apply_cell_young, cell_young, flex_cells
from mjcodesign.models.spec import new_spec
from mjcodesign.models.types import SimOptions
from mjcodesign.scenarios.static import validate_beam

# Compiled flex stiffness is linear in E; scaling a record reproduces a recompile to round-off.
_TOL_SCALED_VS_COMPILED = 1e-12
# Calibrated flex vs Euler–Bernoulli (issue: <= 0.05 when calibrated, and for quadratic).
_TOL_BEAM_FLEX = 0.05
# Linear static solve of the compiled stiffness vs the dynamics run to rest (same model, small load).
_TOL_STATIC_VS_DYNAMIC = 0.01


def _raw_flex(young_compiled, quadratic=False):
    d = FingerDesign()
    opts = SimOptions()
    spec = new_spec("t", opts, flex=True, scene=False)
    base = spec.worldbody.add_body(name="base")
    h = add_flex_finger(
        spec, base, d, np.full(11, young_compiled), "A_", opts, quadratic=quadratic, locking=1.0
    )
    spec.flexes[0].young = young_compiled
    return spec.compile(), h


@pytest.mark.parametrize("quadratic", [False, True])
def test_scaled_cell_records_equal_a_recompile(quadratic):
    e = np.exp(15.3)
    ref, _ = _raw_flex(e, quadratic)
    m, h = _raw_flex(1e6, quadratic)  # compiled at the reference modulus
    h.cell_young = np.full(len(h.cell_young), e)
    apply_cell_young(m, h)
    np.testing.assert_allclose(m.flex_stiffness, ref.flex_stiffness, rtol=_TOL_SCALED_VS_COMPILED, atol=0)


def test_cells_align_with_blocks():
    d = FingerDesign()
    assert flex_cells(d, SimOptions()) == 17
    e = Stiffness.preset("paper-optimized").finger(0)
    ce = cell_young(d, e, 17)
    # segments own two cells, flexures one: every cell carries exactly its block's modulus
    expected = np.concatenate([[e[i]] * (2 if i % 2 == 0 else 1) for i in range(11)])
    np.testing.assert_allclose(ce, expected, rtol=1e-10)


def _design(name):
    if name.startswith("random"):
        return Stiffness(np.random.default_rng(int(name[-1])).uniform(13.5, 17.0, 22))
    return Stiffness.preset(name)


@pytest.mark.parametrize("model", ["flex", "flex-quadratic"])
@pytest.mark.parametrize("design", ["soft", "semi-rigid", "paper-optimized", "random0", "random1"])
def test_beam_calibrated_flex_matches_euler_bernoulli(model, design):
    # δ = F ∫_0^L (L − x)² / (E(x) I(x)) dx
    res = validate_beam(FingerDesign(), _design(design), model, options=SimOptions(stiffness_model="beam"))
    assert res["small_deflection"]
    assert res["rel_error"] <= _TOL_BEAM_FLEX, res


@pytest.mark.parametrize("model", ["flex", "flex-quadratic"])
def test_fem_calibrated_flex_matches_euler_bernoulli_on_a_uniform_design(model):
    res = validate_beam(FingerDesign(), _design("semi-rigid"), model)
    assert res["rel_error"] <= _TOL_BEAM_FLEX, res


def test_static_solve_equals_dynamics_to_rest():
    s = Stiffness.preset("paper-optimized")
    static = validate_beam(FingerDesign(), s, "flex")
    dyn = validate_beam(FingerDesign(), s, "flex", dynamic=True)
    assert dyn["method"] == "dynamics-to-rest" and static["method"] == "linear-static"
    rel = abs(dyn["tip_deflection_m"] - static["tip_deflection_m"]) / static["tip_deflection_m"]
    assert rel < _TOL_STATIC_VS_DYNAMIC, (static, dyn)


def test_assembled_stiffness_has_rigid_modes_in_its_null_space():
    from mjcodesign.models.builder import build_finger
    from mjcodesign.models.flex import assemble_stiffness

    for model in ("flex", "flex-quadratic"):
        built = build_finger(FingerDesign(), Stiffness.preset("soft"), model)
        h = built.fingers[0]
        K = assemble_stiffness(built.model, h)
        nx, ny, nz, _, _ = h.grid
        d = FingerDesign()
        X = np.array(
            [
                [d.length * i / (nx - 1), d.width * (j / (ny - 1) - 0.5), d.height_base * k / (nz - 1)]
                for i in range(nx)
                for j in range(ny)
                for k in range(nz)
            ]
        )
        u = np.cross([0.3, -0.2, 0.5], X).ravel()
        assert np.linalg.norm(K @ u) <= 1e-9 * np.linalg.norm(K) * np.linalg.norm(u)
        # positive definite once the base is clamped
        free = np.arange(3 * ny * nz, K.shape[0])
        assert np.linalg.eigvalsh(K[np.ix_(free, free)]).min() > 0


def test_under_converged_flex_raises_not_ignored():
    from mjcodesign.errors import SimulationDiverged
    from mjcodesign.models.builder import build_finger
    from mjcodesign.models.simulate import check_state

    # Too few solver iterations for the quadratic flex's M+K solve: MuJoCo warns, we must refuse.
    opts = SimOptions(flex_quadratic_iterations=20)
    built = build_finger(FingerDesign(), Stiffness.preset("semi-rigid"), "flex-quadratic", options=opts)
    d = mujoco.MjData(built.model)
    d.ctrl[:] = 2.0
    with pytest.raises(SimulationDiverged, match="INERTIA"):
        for _ in range(20):
            mujoco.mj_step(built.model, d)
            check_state(d)


# -- the flex models are not offered for grasping ---------------------------------------------------


@pytest.mark.parametrize("model", ["flex", "flex-quadratic"])
def test_a_flex_grasp_job_is_refused(model):
    from mjcodesign.errors import UnsupportedError
    from mjcodesign.jobs import GraspJob
    from mjcodesign.models.types import GripperPose
    from mjcodesign.objects import box_object

    obj = box_object((0.05,) * 3, 400.0)
    with pytest.raises(UnsupportedError, match="cannot grasp"):
        GraspJob(obj=obj, pose=GripperPose(), design=Stiffness.preset("semi-rigid"), finger_model=model)
    job = GraspJob(obj=obj, pose=GripperPose(), design=Stiffness.preset("semi-rigid"), finger_model="chain")
    assert job.finger_model.value == "chain"


@pytest.mark.parametrize("command", [["grasp"], ["bench", "grasp"]])
def test_grasp_commands_refuse_flex_before_any_work(command, tmp_path, capsys):
    # The object does not exist: the refusal comes first, from the parser, with the reason.
    from mjcodesign.cli.main import main

    with pytest.raises(SystemExit) as exc:
        main([*command, "--object", str(tmp_path / "missing.stl"), "--model", "flex"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1, err
    assert "--model" in err[0] and "cannot grasp" in err[0] and "missing" not in err[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "command",
    [
        ["evaluate", "--objects", "013_apple", "--designs", "soft"],
        ["bench", "landscape", "--objects", "013_apple"],
        ["datagen", "--objects", "013_apple"],
    ],
)
def test_batch_commands_refuse_flex_at_parsing(command, tmp_path, capsys):
    # Refused by the parser with the reason, before any object is posed or any folder is made.
    from mjcodesign.cli.main import main

    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main([*command, "--model", "flex", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1, err
    assert "--model" in err[0] and "cannot grasp" in err[0]
    assert not out.exists()
