"""The finger's design: geometry and tendon routing, per-block stiffness, beam theory, the tendon law.

Light (numpy only): importing any module here imports this package, and so all of it.
"""

from mjcodesign.design.beam import (
    block_bending_compliance,
    block_effective_ei,
    block_tip_rotation,
    cantilever_tip_deflection,
    second_moment,
    section_compliance,
)
from mjcodesign.design.calibration import CalibratedFem, block_compliance, calibration_for
from mjcodesign.design.finger import Block, BlockKind, FingerDesign, Routing
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E, PRESETS, Stiffness
from mjcodesign.design.tendon_law import TENDON_VARIANTS, tendon_forces, unit_vectors

__all__ = [
    "FingerDesign",
    "Block",
    "BlockKind",
    "Routing",
    "Stiffness",
    "PRESETS",
    "LOG_E_MIN",
    "LOG_E_MAX",
    "N_LOG_E",
    "second_moment",
    "block_bending_compliance",
    "block_effective_ei",
    "block_tip_rotation",
    "cantilever_tip_deflection",
    "section_compliance",
    "CalibratedFem",
    "block_compliance",
    "calibration_for",
    "TENDON_VARIANTS",
    "tendon_forces",
    "unit_vectors",
]
