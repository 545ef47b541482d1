"""Write a stiffness design's print files to a folder: two 3MF projects, block STLs and a print sheet."""

from __future__ import annotations

import json
from pathlib import Path

from mjcodesign.design import Stiffness
from mjcodesign.errors import OutputError
from mjcodesign.fabrication.plan import Calibration, plan_print
from mjcodesign.fabrication.print3mf import write_bambu_3mf, write_prusa_3mf, write_stls

__all__ = ["PRUSA_3MF", "BAMBU_3MF", "SHEET_JSON", "SHEET_MD", "STL_DIR", "export_print"]

PRUSA_3MF = "gripper_prusaslicer.3mf"
BAMBU_3MF = "gripper_bambu_orca.3mf"
SHEET_JSON = "print_sheet.json"
SHEET_MD = "print_sheet.md"
STL_DIR = "stl"


def export_print(design: str, calibration: Path | None, out: Path) -> dict:
    """Write every output file to ``out`` and return the JSON-ready report (moduli in Pa).

    ``design``: a preset name or 11/22 comma-separated ln(E/Pa); ``calibration``: a calibration TOML,
    or None for the packaged example table. Raises :class:`OutputError` when ``out`` cannot be written.
    """
    stiffness = Stiffness.parse(design)
    cal = Calibration.default() if calibration is None else Calibration.load(calibration)
    plan = plan_print(stiffness, cal)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {out}: {exc.strerror or exc}") from exc
    files = {
        "prusaslicer_3mf": write_prusa_3mf(plan, out / PRUSA_3MF),
        "bambu_orca_3mf": write_bambu_3mf(plan, out / BAMBU_3MF),
    }
    stls = write_stls(plan, out / STL_DIR)
    report = {"design": design, **plan.as_dict()}
    report["files"] = {
        **{k: str(v) for k, v in files.items()},
        "print_sheet_json": str(out / SHEET_JSON),
        "print_sheet_md": str(out / SHEET_MD),
        "stl": [str(p) for p in stls],
    }
    try:
        (out / SHEET_JSON).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        (out / SHEET_MD).write_text(plan.markdown(), encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write the print sheet to {out}: {exc.strerror or exc}") from exc
    return report
