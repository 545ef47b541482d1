"""``mjcodesign evaluate``: the paper's Table 1 and disturbance sweep, re-simulated.

Every input is checked before anything runs or is written; a refused command exits 2 with one line and
leaves no folder behind. The report lands in ``--out`` only when the run finished.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from mjcodesign.cli.common import emit, int_at_least, path_text, user_cache_dir

__all__ = ["add_parser", "run"]

_RECORDED_PER_GROUP = 2  # best and worst rollouts per design group re-run into --rrd


def add_parser(subparsers) -> None:
    """Register ``evaluate`` on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "evaluate", help="re-simulate designs over object sets: the paper's Table 1 and disturbance sweep"
    )
    p.add_argument(
        "--ckpt",
        type=path_text,
        default=None,
        help="surrogate checkpoint (needed for --pose-sampling surrogate)",
    )
    p.add_argument(
        "--designs",
        default="soft,semi-rigid",
        help="comma-separated: presets, random:SEED, joint:FILE (a design file), individual:DIR (OBJECT.json files)",
    )
    p.add_argument(
        "--objects",
        default="ycb-in-domain,ood",
        help="comma-separated sets (ycb-in-domain, ycb-ood, egad-like, ood), folders, YCB names or mesh files; "
        "the paper's 46 training objects form the in-domain column, everything else the out-of-domain one",
    )
    p.add_argument("--density", default="light,heavy", help="comma-separated: light, heavy")
    p.add_argument("--pose-sampling", default="fixed,surrogate", help="comma-separated: fixed, surrogate")
    p.add_argument(
        "--impulse", default="0.1,0.2,0.4", help="disturbances in the paper's units [N s], comma-separated"
    )
    p.add_argument(
        "--candidates", type=int_at_least(1), default=10, help="surrogate sampling picks among the first N"
    )
    p.add_argument(
        "--anygrasp", type=path_text, default=None, help="folder of the authors' AnyGrasp OBJECT.npz poses"
    )
    p.add_argument("--model", choices=("chain", "flex"), default="chain")
    p.add_argument("--seed", type=int_at_least(0), default=0)
    p.add_argument(
        "--out",
        type=path_text,
        required=True,
        help="report folder (table.md, disturbance.md, results.json, success.png)",
    )
    p.add_argument(
        "--rrd",
        type=path_text,
        default=None,
        help="also record the best and worst grasps per group for Rerun",
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def _objects(text: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    from mjcodesign.data import resolve_objects
    from mjcodesign.evaluation import domain_of, parse_list

    names: list[str] = []
    for item in parse_list(text, "objects"):
        for n in resolve_objects(item):
            if n not in names:
                names.append(n)
    inside = tuple(n for n in names if domain_of(n) == "in-domain")
    return inside, tuple(n for n in names if domain_of(n) != "in-domain")


def _impulses(text: str) -> tuple[float, ...]:
    from mjcodesign.errors import DesignError
    from mjcodesign.evaluation import parse_list

    try:
        return tuple(float(v) for v in parse_list(text, "impulse"))
    except ValueError:
        raise DesignError(f"--impulse: numbers in the paper's N s, comma-separated, got {text!r}") from None


def _config(args: argparse.Namespace):
    from mjcodesign.evaluation import EvalConfig, parse_design_groups, parse_list

    inside, outside = _objects(args.objects)
    if args.anygrasp is not None and not Path(args.anygrasp).is_dir():
        from mjcodesign.errors import PoseError

        raise PoseError(f"--anygrasp: {args.anygrasp} is not a folder")
    return EvalConfig(
        designs=parse_design_groups(args.designs),
        in_domain=inside,
        out_of_domain=outside,
        densities=parse_list(args.density, "density"),
        pose_sampling=parse_list(args.pose_sampling, "pose-sampling"),
        impulses=_impulses(args.impulse),
        candidates=args.candidates,
        anygrasp=args.anygrasp,
        model=args.model,
        seed=args.seed,
        cache_dir=str(user_cache_dir()),
    )


def _check_out(out: Path) -> None:
    from mjcodesign.errors import OutputError

    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} is a file")
    if out.is_dir() and any(out.iterdir()) and not (out / "results.json").is_file():
        raise OutputError(f"--out {out} holds other files: give an empty folder or an earlier report's")
    base = out
    while not base.exists():  # the folders are made when the report is written
        base = base.parent
    if not base.is_dir() or not os.access(base, os.W_OK):
        raise OutputError(f"--out {out}: {base} is not a writable folder")


def run(args: argparse.Namespace) -> int:
    """Run ``evaluate``; library errors propagate (exit 2 there)."""
    from rich.console import Console
    from rich.progress import Progress

    from mjcodesign.errors import DesignError
    from mjcodesign.evaluation import prepare_objects, record_examples, run_evaluation, write_report

    config = _config(args)
    out = Path(args.out)
    _check_out(out)
    from mjcodesign.outputs import OutputKind, check_output

    check_output(out, OutputKind.EVALUATION, inputs={"--ckpt": args.ckpt, "--anygrasp": args.anygrasp})
    if args.rrd is not None and not Path(args.rrd).resolve().parent.is_dir():
        from mjcodesign.errors import OutputError

        raise OutputError(f"--rrd {args.rrd}: folder {Path(args.rrd).parent} does not exist")
    surrogate = None
    n_points = None
    if config.needs_surrogate:
        if args.ckpt is None:
            raise DesignError(
                "--pose-sampling surrogate needs --ckpt DIR (a checkpoint from `mjcodesign train`)"
            )
        from mjcodesign.surrogate import load_surrogate

        surrogate = load_surrogate(args.ckpt)
        n_points = int(surrogate.meta["dataset"]["cloud_points"])
    t0 = time.perf_counter()
    console = Console(stderr=True)
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        tasks: dict[str, int] = {}

        def progress(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total)
            bar.update(tasks[stage], completed=done)

        kwargs = {} if n_points is None else {"n_points": n_points}
        objects = prepare_objects(config, progress=progress, **kwargs)
        for o in objects:
            if o.error:
                print(f"warning: {o.name}: {o.error}", file=sys.stderr)
        if not any(o.candidates is not None for o in objects):
            raise DesignError("no object could be loaded and posed (see the warnings above)")
        rows = run_evaluation(config, objects, surrogate, progress=progress)
    wall = time.perf_counter() - t0
    meta = {
        "wall_time_s": wall,
        "checkpoint": args.ckpt,
        "designs": [{"label": g.label, "group": g.group} for g in config.designs],
        "impulses_paper_ns": list(config.impulses),
        "model": config.model,
        "seed": config.seed,
        "command": sys.argv,
    }
    if args.rrd:
        from mjcodesign.cli.viz import open_recorder

        recorder = open_recorder(args)
        try:
            meta["recorded"] = record_examples(rows, objects, config, recorder, per_group=_RECORDED_PER_GROUP)
        except BaseException:
            recorder.close(discard=True)
            raise
        recorder.close()
    summary = write_report(out, rows, objects, config, meta)
    summary["out"] = str(out)
    summary["rollouts"] = len(rows)
    emit(summary if args.json else _flat(summary), args.json)
    return 0


def _flat(summary: dict) -> list[dict]:
    rows = []
    for e in summary["table"]:
        row = {"group": e["design_label"], "pose": e["pose_sampling"]}
        for k, c in e["cells"].items():
            row[k] = "—" if c["rate"] is None else f"{100 * c['rate']:.1f}% ({c['success']}/{c['rollouts']})"
        rows.append(row)
    return rows
