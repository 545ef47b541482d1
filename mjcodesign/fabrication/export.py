"""Write a stiffness design's print files to a folder: two 3MF projects, block STLs and a print sheet.

The folder follows the output-folder rule of :mod:`mjcodesign.outputs`: the files are written complete
into a temporary sibling, then swapped into place, so a failure leaves the output folder as it was.
"""

from __future__ import annotations

import json
from pathlib import Path

from mjcodesign.design import Stiffness
from mjcodesign.errors import OutputError
from mjcodesign.fabrication.plan import Calibration, PrintPlan, plan_print
from mjcodesign.fabrication.print3mf import write_bambu_3mf, write_prusa_3mf, write_stls
from mjcodesign.outputs import OutputKind, check_output, staged

__all__ = ["PRUSA_3MF", "BAMBU_3MF", "SHEET_JSON", "SHEET_MD", "STL_DIR", "export_print", "write_print_files"]

PRUSA_3MF = "gripper_prusaslicer.3mf"
BAMBU_3MF = "gripper_bambu_orca.3mf"
SHEET_JSON = "print_sheet.json"
SHEET_MD = "print_sheet.md"
STL_DIR = "stl"


def export_print(design: str, calibration: Path | None, out: Path, *, overwrite: bool = False) -> dict:
    """Write every output file to ``out`` and return the JSON-ready report (moduli in Pa).

    ``design``: a preset name or 11/22 comma-separated ln(E/Pa); ``calibration``: a calibration TOML,
    or None for the packaged example table; ``overwrite``: write into a folder that holds other files
    (kept). All files are written before any lands in ``out``; raises :class:`OutputError` when ``out``
    is refused or cannot be written, and then leaves it as it was (no folder is left behind).
    """
    folder = check_output(out, OutputKind.PRINT, overwrite=overwrite, inputs={"--calibration": calibration})
    stiffness = Stiffness.parse(design)
    cal = Calibration.default() if calibration is None else Calibration.load(calibration)
    plan = plan_print(stiffness, cal)
    with staged(folder) as staging:
        report = write_print_files(plan, staging, Path(out), design)
    return report


def write_print_files(plan: PrintPlan, staging: Path, out: Path, design: str) -> dict:
    """Write ``plan``'s files into folder ``staging`` (which becomes ``out``); the JSON-ready report."""
    write_prusa_3mf(plan, staging / PRUSA_3MF)
    write_bambu_3mf(plan, staging / BAMBU_3MF)
    stls = [f"{STL_DIR}/{p.name}" for p in write_stls(plan, staging / STL_DIR)]
    report = {"design": design, **plan.as_dict()}
    report["files"] = {
        "prusaslicer_3mf": str(out / PRUSA_3MF),
        "bambu_orca_3mf": str(out / BAMBU_3MF),
        "print_sheet_json": str(out / SHEET_JSON),
        "print_sheet_md": str(out / SHEET_MD),
        "stl": [str(out / rel) for rel in stls],
    }
    try:
        (staging / SHEET_JSON).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        (staging / SHEET_MD).write_text(plan.markdown(), encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write the print sheet to {out}: {exc.strerror or exc}") from exc
    return report
