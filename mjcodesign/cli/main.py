"""The ``mjcodesign`` command line. Flags live here only; the library never reads argv."""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib.util
import json
import os
import shlex
import sys
import warnings

from mjcodesign.cli.common import (
    Parser,
    add_out_folder,
    emit,
    finite_float,
    int_at_least,
    one_line,
    parse_design,
    path_text,
    quiet_warp,
)
from mjcodesign.errors import MjcodesignError

__all__ = ["main", "build_parser"]

_MODELS = ("chain", "flex", "flex-quadratic")
_FLEX_TENDON_NOTE = (
    "note: the exported flex model carries the native tendon, which is approximate on flex (its waypoint "
    "sites ride on the nearest nodes: README, Limits); simulate it with TendonMode.POINT_FORCE"
)
_MUJOCO_WARNINGS_SHOWN = 5  # distinct MuJoCo warning texts printed after a command that succeeded


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
    from mjcodesign.models import TendonMode, build_finger, build_gripper, export_model
    from mjcodesign.outputs import OutputKind, check_output, staged

    folder = check_output(args.out, OutputKind.FINGER, overwrite=args.overwrite)
    stiffness = parse_design(args.design)
    build = build_gripper if args.gripper else build_finger
    kwargs = {} if args.gripper else {"scene": True}
    built = build(FingerDesign(), stiffness, args.model, **kwargs)
    with staged(folder) as tmp:
        manifest = export_model(built, tmp)
    if built.finger_model.is_flex and built.tendon_mode is TendonMode.NATIVE:
        print(_FLEX_TENDON_NOTE, file=sys.stderr)
    manifest["out"] = str(args.out)
    emit({k: v for k, v in manifest.items() if k != "flex_cell_young_pa"}, args.json)
    return 0


def _model_list(text: str) -> list[str]:
    """The argparse type of ``--models``: comma-separated finger models, each once."""
    models = [m.strip() for m in text.split(",")]
    unknown = [m for m in models if m not in _MODELS]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown model(s) {unknown}: choose from {', '.join(_MODELS)}")
    if len(set(models)) != len(models):
        raise argparse.ArgumentTypeError(f"a model is listed twice: {text}")
    return models


def _cmd_bench_finger(args) -> int:
    from rich.console import Console
    from rich.progress import Progress

    from mjcodesign.bench import run_benchmark

    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("bench finger", total=len(args.models))

        def progress(model: str, done: int) -> None:
            bar.update(task, completed=done, description=f"bench finger: {model}")

        curl = {"models": args.models, "seconds": args.seconds, "flex_cells": args.flex_cells}
        res = run_benchmark("finger", command=args.command_line, out=args.out, progress=progress, **curl)
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
    add_out_folder(exp, "output")
    exp.add_argument("--gripper", action="store_true", help="export the two-finger gripper, not one finger")
    exp.add_argument("--json", action="store_true")
    exp.set_defaults(func=_cmd_finger_export)

    bench = sub.add_parser("bench", help="benchmarks (write JSON)")
    bsub = bench.add_subparsers(dest="what", required=True, parser_class=Parser)
    bf = bsub.add_parser("finger", help="steps/s of a 1-s free tendon curl per model, one thread")
    bf.add_argument(
        "--models",
        type=_model_list,
        default=list(_MODELS),
        help=f"comma-separated, from {', '.join(_MODELS)}",
    )
    bf.add_argument(
        "--seconds", type=finite_float(0.0, strict=True), default=1.0, help="simulated seconds per model"
    )
    bf.add_argument("--out", type=path_text, default=None, help="also write the JSON to this file")
    bf.add_argument(
        "--flex-cells",
        type=int_at_least(1),
        default=None,
        help="interpolation cells along the finger (flex)",
    )
    bf.add_argument("--json", action="store_true")
    bf.set_defaults(func=_cmd_bench_finger)

    from mjcodesign.cli import crosscheck as cli_crosscheck
    from mjcodesign.cli import data as cli_data
    from mjcodesign.cli import design as cli_design
    from mjcodesign.cli import evaluate as cli_evaluate
    from mjcodesign.cli import fabrication as cli_fabrication
    from mjcodesign.cli import grasp as cli_grasp
    from mjcodesign.cli import hardware as cli_hardware
    from mjcodesign.cli import labels as cli_labels
    from mjcodesign.cli import landscape as cli_landscape
    from mjcodesign.cli import optimize as cli_optimize
    from mjcodesign.cli import oracle as cli_oracle
    from mjcodesign.cli import poses as cli_poses
    from mjcodesign.cli import surrogate as cli_surrogate
    from mjcodesign.cli import viz as cli_viz

    cli_grasp.add_bench_parser(bsub)
    cli_crosscheck.add_bench_parser(bsub)
    cli_viz.add_bench_parser(bsub)
    cli_poses.add_bench_parser(bsub)
    cli_data.add_bench_parser(bsub)
    cli_optimize.add_bench_parser(bsub)
    cli_surrogate.add_bench_parser(bsub)
    cli_landscape.add_bench_parser(bsub)
    cli_evaluate.add_bench_parser(bsub)
    cli_labels.add_bench_parser(bsub)
    cli_oracle.add_bench_parser(bsub)
    cli_viz.add_parser(sub)
    cli_grasp.add_parser(sub)
    cli_crosscheck.add_parser(sub)
    cli_fabrication.add_parser(sub)
    cli_poses.add_parser(sub)
    cli_data.add_parser(sub)
    cli_optimize.add_parser(sub)
    cli_design.add_parser(sub)
    cli_surrogate.add_parser(sub)
    cli_evaluate.add_parser(sub)
    cli_hardware.add_parser(sub)
    return p


def _reaches_warp(args: argparse.Namespace) -> bool:
    """Whether this command can initialise Warp: the FEM, the mjwarp backend, or the poses' SDF (Warp).

    ``grasp`` of a MuJoCo model (``--model chain|flex``) on MuJoCo C with an ``auto`` or file pose,
    ``bench grasp`` and ``bench viz`` never reach Warp, and importing it costs ~1.3 s, so they skip it;
    ``hw`` plans no poses.
    """
    command, what = args.command, getattr(args, "what", None)
    if command == "bench":
        return what in ("fem", "poses", "datagen", "landscape", "optimize", "evaluate")
    if command == "grasp":
        return (
            getattr(args, "model", None) == "fem"
            or "mjwarp" in getattr(args, "backend", "")
            or getattr(args, "pose", None) == "best"
        )
    return command in ("crosscheck", "poses", "datagen", "evaluate", "optimize", "predict", "design")


def _reaches_mujoco(args: argparse.Namespace) -> bool:
    """Whether this command can step or compile a MuJoCo model (``view`` and the motor commands never do).

    Importing MuJoCo costs ~1 s, so the commands that cannot reach it skip :func:`_mujoco_warnings`.
    """
    if args.command == "view":
        return False
    return args.command != "hw" or args.hw_command in ("grasp", "selftest")


@contextlib.contextmanager
def _mujoco_warnings(warnings: list[str]):
    """Collect MuJoCo's warning texts in ``warnings`` while the command runs.

    MuJoCo's default handler prints each warning on stdout (which would break ``--json``) and appends
    it to ``MUJOCO_LOG.TXT`` in the working directory. The library never depends on those texts: it
    reads ``MjData.warning`` and raises :class:`~mjcodesign.errors.SimulationDiverged`. The handler is a
    process global, so only the CLI sets it, and puts the previous one back.
    """
    import mujoco

    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(warnings.append)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def main(argv: list[str] | None = None) -> int:
    """Entry point: typed library errors become exit code 2 and one line on stderr.

    Python's and MuJoCo's warnings are held while the command runs: a refused command prints its one
    error line, which says what went wrong; otherwise they are shown after the command (on stderr).
    """
    _check_mujoco_gl(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    # The command line as run, for the records the command writes (the library never reads argv).
    args.command_line = shlex.join(["mjcodesign", *(sys.argv[1:] if argv is None else argv)])
    if _reaches_warp(args) and importlib.util.find_spec("warp") is not None:
        try:
            quiet_warp()  # once, before the library's wp.init(), which is then silent
        except (ImportError, OSError, RuntimeError):
            pass  # the library call that needs Warp reports it
    held: list[warnings.WarningMessage] = []
    mujoco_texts: list[str] = []
    mujoco = _mujoco_warnings(mujoco_texts) if _reaches_mujoco(args) else contextlib.nullcontext()
    try:
        with warnings.catch_warnings(record=True) as held, mujoco:
            code = int(args.func(args) or 0)
            sys.stdout.flush()  # a full or closed stdout fails here, as a write error, not at exit
    except MjcodesignError as exc:
        sys.stderr.write(f"error: {one_line(str(exc))}\n")
        return 2
    except OSError as exc:
        if exc.errno not in _WRITE_ERRNOS:
            _show_warnings(held, mujoco_texts)
            raise
        _drop_stdout()
        where = f": {one_line(str(exc.filename))}" if exc.filename else " (standard output)"
        sys.stderr.write(f"error: cannot write{where}: {exc.strerror}\n")
        return 2
    except KeyboardInterrupt:
        _show_warnings(held, mujoco_texts)
        sys.stderr.write("error: interrupted\n")
        return 130
    except BaseException:  # a bug: its traceback follows what was held
        _show_warnings(held, mujoco_texts)
        raise
    _show_warnings(held, mujoco_texts)
    return code


# The environment's write failures (a full disk or quota, a read-only file system, a closed pipe): one
# line, not a traceback. Any other OSError escaping a command is a bug.
_WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG, errno.EPIPE})
# Commands that render with MuJoCo's OpenGL (the design report's images); the rest never do.
_RENDERING_COMMANDS = frozenset({"design"})


def _drop_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush does not fail again."""
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, sys.stdout.fileno())
    os.close(null)


def _check_mujoco_gl(argv: list[str]) -> None:
    """Make a ``MUJOCO_GL`` that MuJoCo refuses at import harmless, or refuse it.

    MuJoCo raises at ``import mujoco`` for a value it does not know, and building the parser imports
    it. A command that renders nothing does not use the value, so it is turned off for this process
    (``disable``); a command that renders exits 2 with one line.
    """
    gl = os.environ.get("MUJOCO_GL")
    if gl is None or "mujoco" in sys.modules:
        return
    try:
        import mujoco  # noqa: F401
    except RuntimeError as exc:
        if "MUJOCO_GL" not in str(exc):
            raise
        command = next((a for a in argv if not a.startswith("-")), None)
        if command in _RENDERING_COMMANDS:
            sys.stderr.write(f"error: {one_line(str(exc))} (egl or osmesa render without a display)\n")
            raise SystemExit(2) from None
        os.environ["MUJOCO_GL"] = "disable"  # this command renders nothing


def _show_warnings(held: list[warnings.WarningMessage], mujoco_texts: list[str]) -> None:
    """Show the held Python warnings as Python would have, then MuJoCo's distinct warning texts."""
    for w in held:
        warnings.showwarning(w.message, w.category, w.filename, w.lineno, w.file, w.line)
    for text in list(dict.fromkeys(mujoco_texts))[:_MUJOCO_WARNINGS_SHOWN]:
        sys.stderr.write(f"warning: MuJoCo: {text}\n")


if __name__ == "__main__":
    raise SystemExit(main())
