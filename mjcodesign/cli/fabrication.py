"""``mjcodesign export-print``: slicer-ready files and a print sheet for a stiffness design.

Wire it into the main CLI with ``cli_fabrication.add_parser(subparsers)``; the parser's ``func`` is
:func:`run`. ``python -m mjcodesign.cli_fabrication ARGS`` runs the same command on its own.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["add_parser", "run", "export_print"]

PRUSA_3MF = "gripper_prusaslicer.3mf"
BAMBU_3MF = "gripper_bambu_orca.3mf"
SHEET_JSON = "print_sheet.json"
SHEET_MD = "print_sheet.md"
STL_DIR = "stl"


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``export-print`` on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "export-print",
        help="stiffness design to print settings: 3MF (PrusaSlicer, Bambu/Orca), STL, print sheet",
        description=(
            "Map every block's log E to the nearest setting of a calibration table (infill for segments, "
            "solid layers or wall loops for flexures) and write slicer-ready files to --out."
        ),
    )
    _arguments(p)
    p.set_defaults(func=run)
    return p


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--design",
        required=True,
        help="stiffness preset (soft, semi-rigid, paper-optimized) or 11 or 22 comma-separated ln(E/Pa)",
    )
    p.add_argument(
        "--calibration",
        type=Path,
        default=None,
        help="calibration TOML (default: the packaged EXAMPLE table for TPU 95A, placeholder values)",
    )
    p.add_argument("--out", type=Path, required=True, help="output directory (created if missing)")
    p.add_argument("--json", action="store_true", help="print the per-block mapping as JSON on stdout")


def export_print(design: str, calibration: Path | None, out: Path) -> dict:
    """Write every output file and return the JSON-ready report (moduli in Pa)."""
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import OutputError
    from mjcodesign.fabrication.plan import Calibration, plan_print
    from mjcodesign.fabrication.print3mf import write_bambu_3mf, write_prusa_3mf, write_stls

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


def run(args: argparse.Namespace) -> int:
    """Run ``export-print``; returns the exit code. Library errors propagate to the caller."""
    report = export_print(args.design, args.calibration, args.out)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"wrote {report['files']['prusaslicer_3mf']}, {report['files']['bambu_orca_3mf']}, "
            f"{len(report['files']['stl'])} STL and the print sheet; "
            f"largest |error| {report['max_abs_rel_error']:.1%}"
        )
    return 0
