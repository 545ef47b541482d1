"""Write a stiffness design's print files to a folder: two 3MF projects, block STLs and a print sheet.

The files are written complete into a hidden staging folder inside the output folder, then renamed into
place: a failure leaves the output folder as it was (no half set of files).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
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
_STAGING_PREFIX = ".export-print-"


def export_print(design: str, calibration: Path | None, out: Path) -> dict:
    """Write every output file to ``out`` and return the JSON-ready report (moduli in Pa).

    ``design``: a preset name or 11/22 comma-separated ln(E/Pa); ``calibration``: a calibration TOML,
    or None for the packaged example table. All files are written before any lands in ``out``; raises
    :class:`OutputError` when ``out`` cannot be written, and then leaves it as it was (a folder this call
    created is removed again).
    """
    stiffness = Stiffness.parse(design)
    cal = Calibration.default() if calibration is None else Calibration.load(calibration)
    plan = plan_print(stiffness, cal)
    out = Path(out)
    created: list[Path] = []
    try:
        created = _missing_folders(out)
        out.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=_STAGING_PREFIX, dir=out))
    except OSError as exc:
        _remove_empty(created)
        raise OutputError(f"cannot create output directory {out}: {exc.strerror or exc}") from exc
    try:
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
        _commit(staging, out, [PRUSA_3MF, BAMBU_3MF, SHEET_JSON, SHEET_MD, *stls])
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        _remove_empty(created)
        raise
    shutil.rmtree(staging, ignore_errors=True)
    return report


def _commit(staging: Path, out: Path, names: list[str]) -> None:
    """Rename the staged files ``names`` (relative paths) into ``out``.

    Every destination is checked first (no folder where a file goes, a folder or nothing where the STL
    folder goes), so that a refusal comes before any file has moved.
    """
    stl_dir = out / STL_DIR
    if stl_dir.exists() and not stl_dir.is_dir():
        raise OutputError(f"cannot write STL files to {stl_dir}: it is not a folder")
    for rel in names:
        if (out / rel).is_dir():
            raise OutputError(f"cannot write {out / rel}: Is a directory")
    made_stl_dir = _missing_folders(stl_dir)
    try:
        stl_dir.mkdir(exist_ok=True)
        for rel in names:
            os.replace(staging / rel, out / rel)
    except OSError as exc:
        _remove_empty(made_stl_dir)
        raise OutputError(f"cannot write the print files to {out}: {exc.strerror or exc}") from exc


def _missing_folders(path: Path) -> list[Path]:
    """``path`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    while not path.exists() and path != path.parent:
        missing.append(path)
        path = path.parent
    return missing


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders this call created (deepest first), as long as they are empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return
