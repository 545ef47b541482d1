"""The ``mjcodesign`` command line. Flags live here only; the library never reads argv."""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys

from mjcodesign.cli.common import Parser, emit, parse_design, quiet_warp
from mjcodesign.errors import MjcodesignError

__all__ = ["main", "build_parser"]

_MODELS = ("chain", "flex", "flex-quadratic")


def _cmd_validate_beam(args) -> int:
    from mjcodesign.design import FingerDesign
    from mjcodesign.scenarios.static import validate_beam

    stiffness = parse_design(args.design)
    res = validate_beam(FingerDesign(), stiffness, args.model, force=args.force, dynamic=args.dynamic or None)
    res["design"] = args.design
    emit(res, args.json)
    return 0


def _cmd_finger_export(args) -> int:
    from mjcodesign.design import FingerDesign
    from mjcodesign.models import build_finger, build_gripper, export_model

    stiffness = parse_design(args.design)
    build = build_gripper if args.gripper else build_finger
    kwargs = {} if args.gripper else {"scene": True}
    built = build(FingerDesign(), stiffness, args.model, **kwargs)
    manifest = export_model(built, args.out)
    manifest["out"] = str(args.out)
    emit({k: v for k, v in manifest.items() if k != "flex_cell_young_pa"}, args.json)
    return 0


def _cmd_bench_finger(args) -> int:
    from mjcodesign.bench import run_benchmark

    res = run_benchmark(
        "finger",
        out=args.out,
        models=args.models.split(","),
        seconds=args.seconds,
        flex_cells=args.flex_cells,
    )
    if args.json:
        print(json.dumps(res))
    else:
        emit([{"model": k, **v} for k, v in res.items()], False)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser."""
    p = Parser(prog="mjcodesign", description="Co-design tendon-driven soft grippers on MuJoCo.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    val = sub.add_parser("validate", help="check the finger models against references")
    vsub = val.add_subparsers(dest="what", required=True, parser_class=Parser)
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
    fsub = finger.add_subparsers(dest="what", required=True, parser_class=Parser)
    exp = fsub.add_parser("export", help="write a self-contained MJCF, MJB and block STLs")
    exp.add_argument("--design", default="paper-optimized")
    exp.add_argument("--model", choices=_MODELS, default="chain")
    exp.add_argument("--out", required=True)
    exp.add_argument("--gripper", action="store_true", help="export the two-finger gripper, not one finger")
    exp.add_argument("--json", action="store_true")
    exp.set_defaults(func=_cmd_finger_export)

    bench = sub.add_parser("bench", help="benchmarks (write JSON)")
    bsub = bench.add_subparsers(dest="what", required=True, parser_class=Parser)
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
    from mjcodesign.cli import data as cli_data
    from mjcodesign.cli import fabrication as cli_fabrication
    from mjcodesign.cli import grasp as cli_grasp
    from mjcodesign.cli import poses as cli_poses
    from mjcodesign.cli import viz as cli_viz

    cli_grasp.add_bench_parser(bsub)
    cli_crosscheck.add_bench_parser(bsub)
    cli_viz.add_bench_parser(bsub)
    cli_poses.add_bench_parser(bsub)
    cli_data.add_bench_parser(bsub)
    cli_viz.add_parser(sub)
    cli_grasp.add_parser(sub)
    cli_crosscheck.add_parser(sub)
    cli_fabrication.add_parser(sub)
    cli_poses.add_parser(sub)
    cli_data.add_parser(sub)

    from mjcodesign.hardware.cli import add_parser as add_hardware

    add_hardware(sub)
    return p


def _reaches_warp(args: argparse.Namespace) -> bool:
    """Whether this command can initialise Warp: the FEM, the mjwarp backend, or the poses' SDF (Warp).

    ``grasp`` on MuJoCo C with an ``auto`` or file pose, ``bench grasp`` and ``bench viz`` never reach
    Warp, and importing it costs ~1.3 s, so they skip it; ``hw`` plans no poses.
    """
    command, what = args.command, getattr(args, "what", None)
    if command == "bench":
        return what in ("fem", "poses", "datagen")
    if command == "grasp":
        return "mjwarp" in getattr(args, "backend", "") or getattr(args, "pose", None) == "best"
    return command in ("crosscheck", "poses", "datagen")


def main(argv: list[str] | None = None) -> int:
    """Entry point: typed library errors become exit code 2 and one line on stderr."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if _reaches_warp(args) and importlib.util.find_spec("warp") is not None:
        try:
            quiet_warp()  # once, before the library's wp.init(), which is then silent
        except (ImportError, OSError, RuntimeError):
            pass  # the library call that needs Warp reports it
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
