"""``mjcodesign export-print``: slicer-ready files and a print sheet for a stiffness design.

``add_parser(subparsers)`` registers it on the main CLI; the parser's ``func`` is :func:`run`, which calls
:func:`mjcodesign.fabrication.export_print` and prints.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from mjcodesign.cli.common import add_out_folder, path_text

__all__ = ["add_parser", "run"]


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


def _path(text: str) -> Path:
    """The argparse type of a path, checked as text (:func:`path_text`): ``Path("")`` would be ``.``."""
    return Path(path_text(text))


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--design",
        required=True,
        help="stiffness preset (soft, semi-rigid, paper-optimized) or 11 or 22 comma-separated ln(E/Pa)",
    )
    p.add_argument(
        "--calibration",
        type=_path,
        default=None,
        help="calibration TOML (default: the packaged EXAMPLE table for TPU 95A, placeholder values)",
    )
    add_out_folder(p, "print files'")
    p.add_argument("--json", action="store_true", help="print the per-block mapping as JSON on stdout")


def run(args: argparse.Namespace) -> int:
    """Run ``export-print``; returns the exit code. Library errors propagate to the caller."""
    from mjcodesign.fabrication import export_print

    report = export_print(args.design, args.calibration, args.out, overwrite=args.overwrite)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"wrote {report['files']['prusaslicer_3mf']}, {report['files']['bambu_orca_3mf']}, "
            f"{len(report['files']['stl'])} STL and the print sheet; "
            f"largest |error| {report['max_abs_rel_error']:.1%}"
        )
    return 0
