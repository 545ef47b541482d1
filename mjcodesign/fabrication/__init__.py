"""Fabrication: a stiffness design mapped to print settings (calibration tables) and slicer-ready files."""

from mjcodesign.fabrication.export import export_print, write_print_files
from mjcodesign.fabrication.plan import (
    FINGER_NAMES,
    INFILL_PATTERNS,
    SETTINGS,
    BlockPrint,
    Calibration,
    CalibrationCurve,
    PrintPlan,
    SettingSpec,
    plan_print,
)
from mjcodesign.fabrication.print3mf import (
    Placement,
    block_mesh,
    placements,
    write_bambu_3mf,
    write_prusa_3mf,
    write_stls,
)

__all__ = [
    "Calibration",
    "CalibrationCurve",
    "SettingSpec",
    "SETTINGS",
    "INFILL_PATTERNS",
    "FINGER_NAMES",
    "BlockPrint",
    "PrintPlan",
    "plan_print",
    "Placement",
    "block_mesh",
    "placements",
    "write_prusa_3mf",
    "write_bambu_3mf",
    "write_stls",
    "export_print",
    "write_print_files",
]
