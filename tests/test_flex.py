import mujoco
import numpy as np
import pytest

from mjcodesign.finger import FingerDesign
from mjcodesign.flex import add_flex_finger, apply_cell_young, cell_young, flex_cells
from mjcodesign.mjcf import SimOptions, new_spec
from mjcodesign.stiffness import Stiffness
from mjcodesign.validate import validate_beam

# Compiled flex stiffness is linear in E; scaling a record reproduces a recompile to round-off.
_TOL_SCALED_VS_COMPILED = 1e-12
# Calibrated trilinear flex vs Euler–Bernoulli (issue: <= 0.05 when calibrated).
_TOL_BEAM_FLEX = 0.05


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
    m2 = mujoco.MjModel  # noqa: F841 - keep names explicit
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


@pytest.mark.parametrize("design", ["semi-rigid", "paper-optimized"])
def test_calibrated_trilinear_flex_matches_euler_bernoulli(design):
    res = validate_beam(FingerDesign(), Stiffness.preset(design), "flex")
    assert res["rel_error"] <= _TOL_BEAM_FLEX, res
