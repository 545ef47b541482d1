"""``mjcodesign optimize`` (co-design through the surrogate) and ``mjcodesign bench optimize``.

Wire them in with ``cli_optimize.add_parser(subparsers)`` and ``cli_optimize.add_bench_parser(bench)``.
torch, matplotlib and rerun are imported inside the handlers only.
"""

from __future__ import annotations

import argparse
import contextlib
import json
from pathlib import Path

from mjcodesign.cli.common import (
    add_mass_mode,
    add_out_folder,
    check_output_link,
    emit,
    finite_float,
    int_at_least,
    output_file,
    path_text,
    user_cache_dir,
)

__all__ = ["add_bench_parser", "add_parser", "run", "run_bench"]

_MODES = ("joint", "individual")
_OBJECTIVES = ("lopt", "success")  # mjcodesign.codesign.Objective, without importing torch here
_ROBUST = ("worst", "mean")  # mjcodesign.codesign.robust.Robust


def add_parser(subparsers) -> None:
    """Register ``optimize`` on the main subparsers object."""
    p = subparsers.add_parser(
        "optimize", help="co-design the 22 block stiffnesses and a grasp pose per object (surrogate)"
    )
    p.add_argument(
        "--ckpt",
        type=path_text,
        default=None,
        help="surrogate checkpoint folder (default: the shipped weights)",
    )
    p.add_argument(
        "--objects",
        required=True,
        help="a named set (ycb-in-domain, …), or comma-separated object names, mesh files (STL/OBJ/PLY) "
        "and folders of meshes; a file's mesh is what its poses and the re-simulation load",
    )
    p.add_argument(
        "--poses",
        type=path_text,
        required=True,
        help="a grasp-candidate .npz (`poses --out`), a folder of them, or a dataset folder (its poses)",
    )
    p.add_argument(
        "--poses-per-object",
        type=int_at_least(1),
        default=10,
        help="first N candidates per object (paper: 10)",
    )
    p.add_argument("--mode", choices=_MODES, default="joint", help="one design for all objects, or one each")
    p.add_argument(
        "--objective",
        choices=_OBJECTIVES,
        default="lopt",
        help="lopt: the paper's Algorithm 1 on L_opt; success: maximise the success head's predicted "
        "probability at each object's best pose (a checkpoint trained with a success head)",
    )
    p.add_argument(
        "--density",
        default=None,
        help="object density [kg/m³] or light (100) / heavy (400), the paper's relative scale, or ycb-median "
        "(680); default: the checkpoint dataset's (its one density; light for a range)",
    )
    add_mass_mode(p, "in the surrogate's input and the re-simulation, in place of --density")
    p.add_argument("--seed", type=int_at_least(0), default=0, help="draws candidate clouds")
    add_out_folder(p, "output")
    p.add_argument(
        "--rrd", type=output_file, default=None, help="also log the loss curves to this Rerun file"
    )
    p.add_argument("--max-iterations", type=int_at_least(1), default=2000, help="N of Algorithm 1")
    p.add_argument("--patience", type=int_at_least(1), default=100, help="T_p of Algorithm 1 (paper: 100)")
    p.add_argument("--top-b", type=int_at_least(1), default=5, help="B of Algorithm 1 (paper: 5)")
    for flag, kind, default, meta, text in (
        ("--mc-samples", int_at_least(0), 0, "K", "--objective success: read the success head K times with dropout "
         "on (Monte Carlo dropout) and optimise the mean; 0: one deterministic pass"),
        ("--uncertainty", finite_float(0.0), 0.0, "LAMBDA", "--objective success: add LAMBDA times the K draws' "
         "standard deviation to each pose's loss (a penalty on what the network is unsure of; needs --mc-samples >= 2)"),
    ):  # fmt: skip
        p.add_argument(flag, type=kind, default=default, metavar=meta, help=text)
    p.add_argument("--no-ground-truth", action="store_true", help="skip re-simulating the designs in MuJoCo")
    p.add_argument(
        "--robust",
        choices=_ROBUST,
        default=None,
        help="co-design across model variants: each (object, pose)'s loss is the worst of, or the mean over, "
        "the surrogates of --ckpt (the nominal model) and every --variant; the ground truth is simulated "
        "under each model (default: off)",
    )
    p.add_argument(
        "--variant",
        type=path_text,
        action="append",
        default=None,
        metavar="CKPT",
        help="with --robust: a checkpoint trained on a dataset of one model variant (e.g. datagen --routing "
        "printed, or --scenario '{\"friction\": 0.6}'); repeat for more; named by its folder",
    )
    p.add_argument(
        "--threads",
        type=int_at_least(0),
        default=0,
        help="torch threads (0: torch's default; 1 suits a shared host)",
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``optimize``; library errors propagate to the main CLI (exit 2, one line)."""
    from rich.console import Console
    from rich.progress import Progress

    from mjcodesign.codesign import Mode, Objective, OptimizeConfig
    from mjcodesign.codesign.run import run_codesign
    from mjcodesign.data import resolve_objects
    from mjcodesign.objects import parse_density
    from mjcodesign.surrogate import checkpoint_or_shipped

    density = None if args.density is None else parse_density(args.density)
    variants = _variants(args.robust, args.variant)
    objects, meshes = _objects(args.objects, resolve_objects)
    if args.rrd:
        check_output_link(args.rrd, "--rrd", overwrite=args.overwrite)
    ckpt = checkpoint_or_shipped(args.ckpt)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    cfg = OptimizeConfig(
        mode=Mode(args.mode),
        objective=Objective(args.objective),
        top_b=args.top_b,
        patience=args.patience,
        max_iterations=args.max_iterations,
        mc_samples=args.mc_samples,
        uncertainty=args.uncertainty,
    )
    with contextlib.ExitStack() as stack:
        bar: list = []  # the progress bar, started at the first iteration: a refusal before it is one line

        def on_step(s) -> None:
            if not bar:
                bar.append(stack.enter_context(Progress(console=Console(stderr=True), transient=True)))
                bar.append(bar[0].add_task("optimize", total=cfg.max_iterations))
            text = f"optimize: loss {s.total:.4g}, {s.converged}/{len(objects)} converged"
            bar[0].update(bar[1], completed=s.iteration, description=text)

        def say(msg: str) -> None:
            if bar:
                bar[0].update(bar[1], description=msg)

        record, result = run_codesign(
            checkpoint=ckpt,
            objects=objects,
            poses=args.poses,
            per_object=args.poses_per_object,
            density=density,
            mass=args.mass,
            out=args.out,
            config=cfg,
            overwrite=args.overwrite,
            seed=args.seed,
            ground_truth=not args.no_ground_truth,
            cache_dir=user_cache_dir(),
            sources=meshes,
            on_step=on_step,
            progress=say,
            variants=variants,
            robust=args.robust or "worst",
        )
    if args.rrd:
        _log_rerun(Path(args.rrd), result)
        record["rrd"] = args.rrd
    if args.json:
        print(json.dumps(record))
    else:
        emit({k: v for k, v in record.items() if k not in ("ground_truth", "best_pose")}, False)
        if record["ground_truth"]:
            emit(record["ground_truth"]["rates"], False)
    return 0


def _variants(robust: str | None, paths: list[str] | None) -> dict[str, str] | None:
    """``--robust`` and ``--variant``: the variants' checkpoints by name (their folders' names), or None.

    Raises :class:`~mjcodesign.errors.DesignError` for one flag without the other, a missing folder or
    two variants of one name.
    """
    from mjcodesign.errors import DesignError

    if robust is None and not paths:
        return None
    if robust is None:
        raise DesignError("--variant needs --robust worst|mean (how the variants' losses combine)")
    if not paths:
        raise DesignError("--robust needs at least one --variant CKPT (a checkpoint of a model variant)")
    named: dict[str, str] = {}
    for p in paths:
        if not Path(p).is_dir():
            raise DesignError(f"--variant {p}: no such checkpoint folder")
        name = Path(p).resolve().name
        if name in named or name == "nominal":
            raise DesignError(f"--variant {p}: two variants named {name!r} (name their folders apart)")
        named[name] = p
    return named


def _objects(text: str, resolve) -> tuple[tuple[str, ...], dict[str, str]]:
    """``--objects``: names, mesh files and folders of meshes, or a named set; (names, mesh of a name).

    A named set or a folder goes through ``resolve_objects``; a mesh file must exist; any other entry
    is a name the poses hold. The mesh of a file entry is what its poses and re-simulation load.
    """
    from mjcodesign.codesign import object_key
    from mjcodesign.errors import MeshError
    from mjcodesign.objects import MESH_SUFFIXES, OBJECT_SETS

    if text.strip() in OBJECT_SETS:
        return tuple(resolve(text)), {}
    items = [n.strip() for n in text.split(",") if n.strip()]
    if not items:
        raise MeshError("--objects is empty")
    entries: list[str] = []
    for item in items:
        if Path(item).is_dir() or Path(item).suffix.lower() in MESH_SUFFIXES:
            entries += [str(Path(f).resolve()) for f in resolve(item)]  # refuses a missing file
        else:
            entries.append(item)
    names = tuple(object_key(e) for e in entries)
    if len(set(names)) != len(names):
        raise MeshError(f"--objects lists an object twice: {text}")
    meshes = {object_key(e): e for e in entries if Path(e).suffix.lower() in MESH_SUFFIXES}
    return names, meshes


def _log_rerun(path: Path, result) -> None:
    """The loss curves as Rerun scalars: ``loss/total`` and ``loss/OBJECT`` against ``iteration``."""
    from mjcodesign.errors import OutputError

    try:
        import rerun as rr
    except ImportError:
        from mjcodesign.errors import UnsupportedError

        raise UnsupportedError("--rrd needs rerun-sdk (pip install 'mjcodesign[viz]')") from None
    rec = rr.RecordingStream("mjcodesign-optimize")
    try:
        rec.save(str(path))
    except Exception as exc:  # rerun raises its own error types for a bad path
        raise OutputError(f"cannot write {path}: {exc}") from exc
    it = list(range(1, result.iterations + 1))
    rec.send_columns(
        "loss/total",
        indexes=[rr.TimeColumn("iteration", sequence=it)],
        columns=rr.Scalars.columns(scalars=result.total_curve),
    )
    for k, name in enumerate(result.objects):
        rec.send_columns(
            f"loss/{name}",
            indexes=[rr.TimeColumn("iteration", sequence=it)],
            columns=rr.Scalars.columns(scalars=result.curves[:, k]),
        )
    rec.flush()


def add_bench_parser(bench_subparsers) -> None:
    """Register ``optimize`` on the ``bench`` command's subparsers object."""
    p = bench_subparsers.add_parser(
        "optimize", help="one joint co-design iteration (46 objects x 10 poses) vs the bare MLP; a whole run"
    )
    p.add_argument(
        "--ckpt", type=path_text, default=None, help="a checkpoint (default: the paper's net, random)"
    )
    p.add_argument("--poses", type=path_text, default=None, help="a dataset folder for the whole run")
    p.add_argument("--objects", default=None, help="comma-separated objects of the whole run (default: all)")
    p.add_argument("--repeats", type=int_at_least(1), default=20, help="timed iterations")
    p.add_argument("--whole-run", action="store_true", help="also time a whole joint optimisation")
    p.add_argument(
        "--cma-budget", type=int_at_least(0), default=0, help="rollouts of the CMA-ES baseline (0: skip)"
    )
    p.add_argument("--fem", action="store_true", help="also time one FEM grasp gradient (minutes on a CPU)")
    p.add_argument("--seed", type=int_at_least(0), default=0)
    p.add_argument("--threads", type=int_at_least(0), default=0, help="torch threads (0: torch's default)")
    p.add_argument("--out", type=path_text, default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench optimize``."""
    from mjcodesign.bench import run_benchmark

    objects = None if args.objects is None else tuple(n.strip() for n in args.objects.split(",") if n.strip())
    res = run_benchmark(
        "optimize",
        command=args.command_line,
        out=args.out,
        checkpoint=args.ckpt,
        poses=args.poses,
        objects=objects,
        repeats=args.repeats,
        whole_run=args.whole_run,
        cma_budget=args.cma_budget,
        fem=args.fem,
        seed=args.seed,
        threads=args.threads,
    )
    if args.json:
        print(json.dumps(res))
    else:
        emit({k: v for k, v in res.items() if not isinstance(v, dict)}, False)
    return 0
