"""MuJoCo models of the fingers and the gripper: shared types, the chain and flex builders, the tendon.

Build a model with :func:`build_finger` or :func:`build_gripper`; :class:`TendonDriver` pulls its
tendons; :func:`export_model` writes it out.
"""

from mjcodesign.models.builder import apply_cell_moduli, build_finger, build_gripper, make_data, set_openings
from mjcodesign.models.export import export_model
from mjcodesign.models.simulate import check_state, has_warning, reset_warnings
from mjcodesign.models.spec import compile_spec, finger_frame_quat, new_spec
from mjcodesign.models.tendon import TendonDriver
from mjcodesign.models.types import (
    CONTYPE_FINGER,
    CONTYPE_WORLD,
    MAX_OPENING,
    PALM_HALF,
    Built,
    FingerHandle,
    FingerModel,
    GripperPose,
    SimOptions,
    TendonMode,
    grasp_model,
)

__all__ = [
    "apply_cell_moduli",
    "build_finger",
    "build_gripper",
    "make_data",
    "set_openings",
    "export_model",
    "check_state",
    "has_warning",
    "reset_warnings",
    "compile_spec",
    "finger_frame_quat",
    "new_spec",
    "TendonDriver",
    "CONTYPE_FINGER",
    "CONTYPE_WORLD",
    "MAX_OPENING",
    "PALM_HALF",
    "Built",
    "FingerHandle",
    "FingerModel",
    "GripperPose",
    "SimOptions",
    "TendonMode",
    "grasp_model",
]
