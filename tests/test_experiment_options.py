"""The experiment options' fences (docs/validation/experiment-options.md).

The options kept for a record are tested where their physics is (tests/test_tendon.py, test_grasp.py,
test_calibration.py, test_fem.py, test_fem_grasp.py, test_fem_locking.py, test_crosscheck.py); here, the
combinations that would silently mean something else are refused.
"""

import pytest

from mjcodesign.design.finger import FingerDesign, Routing
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import UnsupportedError
from mjcodesign.models.builder import build_finger
from mjcodesign.models.types import FingerModel, SimOptions


def test_uniform_height_is_a_design_law_the_printed_routing_refuses():
    # Routing (the design's tendon height law) and SimOptions.routing (where the model's tendon runs) are
    # two axes: a uniform-height design builds guided, but the printed channels are the printed finger's.
    design = FingerDesign(routing="uniform-height")
    assert design.routing is Routing.UNIFORM_HEIGHT
    guided = build_finger(design, Stiffness.preset("semi-rigid"), FingerModel.CHAIN)
    assert guided.options.routing == "guided"
    with pytest.raises(UnsupportedError, match="uniform-height design has none"):
        build_finger(
            design, Stiffness.preset("semi-rigid"), FingerModel.CHAIN, options=SimOptions(routing="printed")
        )
    printed = build_finger(
        FingerDesign(),
        Stiffness.preset("semi-rigid"),
        FingerModel.CHAIN,
        options=SimOptions(routing="printed"),
    )
    assert printed.options.routing == "printed"
