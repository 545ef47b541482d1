"""The ``mjcodesign`` command line. Flags live here only; the library never reads argv."""

from __future__ import annotations

import argparse
import json
import sys

from mjcodesign.errors import MjcodesignError

__all__ = ["main", "build_parser"]

_MODELS = ("chain", "flex", "flex-quadratic")


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2."""

    def error(self, message: str):  # noqa: D102
        sys.stderr.write(f"error: {message}\n")
        raise SystemExit(2)


def _design(text: str):
    from mjcodesign.design.stiffness import Stiffness

    return Stiffness.parse(text)


def _emit(obj, as_json: bool) -> None:
    if as_json:
        print(json.dumps(obj, indent=None))
        return
    from rich.console import Console
    from rich.table import Table

    if isinstance(obj, dict):
        table = Table("key", "value")
        for k, v in obj.items():
            table.add_row(str(k), _fmt(v))
        Console().print(table)
        return
    rows = obj
    table = Table()
    keys = list(rows[0].keys())
    for k in keys:
        table.add_column(k)
    for r in rows:
        table.add_row(*[_fmt(r[k]) for k in keys])
    Console().print(table)


def _fmt(v) -> str:
    from rich.markup import escape

    return escape(_plain(v))


def _plain(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_plain(x) for x in v[:6]) + (", …]" if len(v) > 6 else "]")
    return str(v)


def _cmd_validate_beam(args) -> int:
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.scenarios.static import validate_beam

    stiffness = _design(args.design)
    res = validate_beam(FingerDesign(), stiffness, args.model, force=args.force, dynamic=args.dynamic or None)
    res["design"] = args.design
    _emit(res, args.json)
    return 0


def _cmd_finger_export(args) -> int:
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.models.builder import build_finger, build_gripper
    from mjcodesign.models.export import export_model

    stiffness = _design(args.design)
    build = build_gripper if args.gripper else build_finger
    kwargs = {} if args.gripper else {"scene": True}
    built = build(FingerDesign(), stiffness, args.model, **kwargs)
    manifest = export_model(built, args.out)
    manifest["out"] = str(args.out)
    _emit({k: v for k, v in manifest.items() if k != "flex_cell_young_pa"}, args.json)
    return 0


def _cmd_bench_finger(args) -> int:
    from mjcodesign.bench.finger import bench_finger

    res = bench_finger(
        models=args.models.split(","), seconds=args.seconds, out=args.out, flex_cells=args.flex_cells
    )
    if args.json:
        print(json.dumps(res))
    else:
        _emit([{"model": k, **v} for k, v in res.items()], False)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser."""
    p = _Parser(prog="mjcodesign", description="Co-design tendon-driven soft grippers on MuJoCo.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    val = sub.add_parser("validate", help="check the finger models against references")
    vsub = val.add_subparsers(dest="what", required=True, parser_class=_Parser)
    beam = vsub.add_parser("beam", help="cantilever tip load against Euler–Bernoulli")
    beam.add_argument("--model", choices=_MODELS, default="chain")
    beam.add_argument(
        "--design", default="paper-optimized", help="preset name, random:SEED or 11/22 comma-separated log E"
    )
    beam.add_argument("--force", type=float, default=None, help="tip force [N]; default gives δ = 1%% of L")
    beam.add_argument(
        "--dynamic",
        action="store_true",
        help="flex: run the dynamics to rest instead of the linear static solve",
    )
    beam.add_argument("--json", action="store_true")
    beam.set_defaults(func=_cmd_validate_beam)

    finger = sub.add_parser("finger", help="finger models")
    fsub = finger.add_subparsers(dest="what", required=True, parser_class=_Parser)
    exp = fsub.add_parser("export", help="write a self-contained MJCF, MJB and block STLs")
    exp.add_argument("--design", default="paper-optimized")
    exp.add_argument("--model", choices=_MODELS, default="chain")
    exp.add_argument("--out", required=True)
    exp.add_argument("--gripper", action="store_true", help="export the two-finger gripper, not one finger")
    exp.add_argument("--json", action="store_true")
    exp.set_defaults(func=_cmd_finger_export)

    bench = sub.add_parser("bench", help="benchmarks (write JSON)")
    bsub = bench.add_subparsers(dest="what", required=True, parser_class=_Parser)
    bf = bsub.add_parser("finger", help="steps/s of a 1-s free tendon curl per model, one thread")
    bf.add_argument("--models", default=",".join(_MODELS))
    bf.add_argument("--seconds", type=float, default=1.0, help="simulated seconds per model")
    bf.add_argument("--out", default=None, help="also write the JSON to this file")
    bf.add_argument(
        "--flex-cells", type=int, default=None, help="interpolation cells along the finger (flex)"
    )
    bf.add_argument("--json", action="store_true")
    bf.set_defaults(func=_cmd_bench_finger)

    from mjcodesign.cli import crosscheck as cli_crosscheck
    from mjcodesign.cli import fabrication as cli_fabrication
    from mjcodesign.cli import grasp as cli_grasp
    from mjcodesign.cli import poses as cli_poses
    from mjcodesign.cli import viz as cli_viz

    cli_grasp.add_bench_parser(bsub)
    cli_crosscheck.add_bench_parser(bsub)
    cli_viz.add_bench_parser(bsub)
    cli_poses.add_bench_parser(bsub)
    cli_viz.add_parser(sub)
    cli_grasp.add_parser(sub)
    cli_crosscheck.add_parser(sub)
    cli_fabrication.add_parser(sub)
    cli_poses.add_parser(sub)

    from mjcodesign.hardware.cli import add_parser as add_hardware

    add_hardware(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point: typed library errors become exit code 2 and one line on stderr."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MjcodesignError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
