"""scripts/tied_flexure_hinges.py: tying a flexure's hinges restricts the free chain's buckling, never lowers it."""

from __future__ import annotations

import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models import build_finger
from mjcodesign.models.stability import buckling_tension
from mjcodesign.models.types import FingerModel, SimOptions

_SAME = 1e-9  # the same eigenproblem on the same matrices (relative): round-off only


@pytest.fixture(scope="module")
def tied(script_module):
    return script_module("tied_flexure_hinges").tied_buckling_tension


@pytest.mark.parametrize("log_e", [13.5, 15.7])
def test_one_hinge_per_block_tied_is_the_free_chain(tied, log_e):
    opts = SimOptions(routing="printed", gravity=False, hinges_per_block=1)
    built = build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=opts)
    assert tied(built, np.ones(11, dtype=int)) == pytest.approx(buckling_tension(built)[0], rel=_SAME)


@pytest.mark.parametrize("seed", [3, 8])
def test_tying_never_lowers_the_buckling_tension_and_scales_with_the_modulus(tied, seed):
    design = FingerDesign()
    flexure = np.array([b.kind is BlockKind.FLEXURE for b in design.blocks()])
    opts = SimOptions(routing="printed", gravity=False, hinges_per_block=2)
    low = np.random.default_rng(seed).uniform(13.5, 17.0 - np.log(2.0), 22)  # doubled E stays printable
    stiff = Stiffness(low)
    built = build_finger(design, stiff, FingerModel.CHAIN, options=opts)
    t = tied(built, np.where(flexure, 2, 1))
    assert t >= buckling_tension(built)[0] * (1 - _SAME)
    doubled = build_finger(design, Stiffness(low + np.log(2.0)), FingerModel.CHAIN, options=opts)
    assert tied(doubled, np.where(flexure, 2, 1)) == pytest.approx(2 * t, rel=1e-6)
    with pytest.raises(ValueError):
        tied(built, np.ones(11, dtype=int))  # 11 counts for a finger with 16 hinges
