"""``mjcodesign train``, ``mjcodesign predict``, ``mjcodesign smoothness`` and ``mjcodesign bench surrogate``.

Wire them into the main CLI with ``cli_surrogate.add_parser(subparsers)`` and
``cli_surrogate.add_bench_parser(bench_subparsers)``. torch is imported inside the handlers only, so
that ``import mjcodesign.cli`` stays light.
"""

from __future__ import annotations

import argparse
import json
import sys

from mjcodesign.cli.common import (
    add_out_folder,
    emit,
    finite_float,
    int_at_least,
    output_dir,
    parse_design,
    path_text,
    user_cache_dir,
)
from mjcodesign.errors import DesignError

__all__ = ["add_bench_parser", "add_parser", "run_bench", "run_predict", "run_smoothness", "run_train"]

_SPLITS = ("object", "random")  # mjcodesign.surrogate.SPLITS, without importing torch here


def _fraction(text: str) -> float:
    value = finite_float(0.0)(text)
    if value >= 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {value:g}")
    return value


def _widths(text: str) -> tuple[int, ...]:
    try:
        widths = tuple(int(v) for v in text.split(","))
    except ValueError:
        widths = ()
    if not widths or min(widths) < 1:
        raise argparse.ArgumentTypeError(f"must be comma-separated integers >= 1, got {text!r}")
    return widths


_PRECISIONS = ("fp32", "bf16")  # surrogate.train.PRECISIONS, which imports torch (a test keeps them equal)


def _precision(text: str) -> str:
    if text not in _PRECISIONS:
        raise argparse.ArgumentTypeError(f"must be one of {', '.join(_PRECISIONS)}, got {text!r}")
    return text


# Flags of ``train`` that set a TrainConfig or ModelConfig field: (flag, field, type, default, help).
_TRAIN_OPTIONS = (
    ("--epochs", "epochs", int_at_least(1), 200, "most epochs (early stopping ends sooner)"),
    ("--seed", "seed", int_at_least(0), 0, "seeds the split, weights and shuffles"),
    ("--split-seed", "split_seed", int_at_least(0), None,
     "seeds the held-out objects' draw instead of --seed (networks of one --split-seed and several --seed: "
     "an ensemble on the same split)"),
    ("--batch-size", "batch_size", int_at_least(2), 512, "samples per step (paper: 512)"),
    ("--patience", "early_stop_patience", int_at_least(1), 20, "early stopping [epochs]"),
    ("--pose-group", "pose_group", int_at_least(0), 0, "samples of a pose kept together in a batch (0: all)"),
    ("--precision", "precision", _precision, "fp32", "fp32, or bf16 (autocast; ~1.7x faster on AVX512-BF16)"),
    ("--success-weight", "success_weight", finite_float(0.0), 1.0,
     "weight of the success head's cross-entropy on success_p against one output's L1 (0: no head, the "
     "paper's 10 outputs)"),
    ("--rank-weight", "rank_weight", finite_float(0.0), 0.0,
     "weight of a pairwise ranking term on the success head between one pose's designs (0: none)"),
)  # fmt: skip
_OPTIMIZER_OPTIONS = (
    ("--lr", "lr", finite_float(0.0, strict=True), 1e-3, "AdamW learning rate (PointNet: half)"),
    ("--plateau-patience", "plateau_patience", int_at_least(1), 5, "epochs before the LR drops by 0.8"),
)
_MODEL_OPTIONS = (
    ("--hidden", "hidden", int_at_least(1), 1024, "MLP width (paper: 1024)"),
    ("--depth", "depth", int_at_least(1), 5, "MLP layers of --hidden (paper: 5)"),
    ("--penultimate", "penultimate", int_at_least(1), 512, "width before the output (paper: 512)"),
    ("--point-widths", "point_widths", _widths, (64, 128, 128), "PointNet channels (paper: 64,128,128)"),
    ("--dropout", "dropout", _fraction, 0.3, "dropout after every hidden layer (paper: 0.3)"),
)


def _fields(args: argparse.Namespace, options) -> dict:
    return {dest: getattr(args, dest) for _, dest, *_ in options}


def add_parser(subparsers) -> None:
    """Register ``train`` and ``predict`` on an ``argparse`` subparsers object."""
    t = subparsers.add_parser("train", help="train the PointNet + MLP surrogate on a dataset; write a report")
    t.add_argument("--data", required=True, type=path_text, help="dataset folder (mjcodesign datagen)")
    add_out_folder(t, "checkpoint and report")
    t.add_argument(
        "--split", choices=_SPLITS, default="object", help="held-out objects, or the paper's 80/20"
    )
    for flag, dest, kind, default, text in _TRAIN_OPTIONS + _OPTIMIZER_OPTIONS + _MODEL_OPTIONS:
        t.add_argument(flag, dest=dest, type=kind, default=default, help=text)
    t.add_argument(
        "--no-frame-inputs",
        action="store_true",
        help="the paper's inputs: no vertical, cloud centre and radius beside the PointNet feature (ablation)",
    )
    t.add_argument(
        "--poses-per-object",
        type=int_at_least(1),
        default=None,
        metavar="N",
        help="train and early-stop on the first N poses of each object only (in the dataset's pose_index "
        "order), every design of those poses (default: all); the held-out objects are the same for every "
        "N, and the held-out metrics are taken on all their poses, so that runs of different N compare "
        "(a learning curve)",
    )
    t.add_argument(
        "--efficiency",
        type=_fraction,
        default=0.25,
        help="share of the training rows of a second run (0: none)",
    )
    t.add_argument(
        "--smoothness-poses",
        type=int_at_least(0),
        default=16,
        help="test poses re-simulated along design lines (0: none)",
    )
    t.add_argument(
        "--smoothness-lines",
        type=int_at_least(1),
        default=4,
        help="random design lines per smoothness pose",
    )
    t.add_argument(
        "--threads", type=int_at_least(1), default=None, help="torch CPU threads (default: torch's)"
    )
    t.add_argument(
        "--tensorboard", type=output_dir, default=None, help="also write TensorBoard events to DIR"
    )
    t.add_argument(
        "--folds",
        type=int_at_least(2),
        default=None,
        help="train K surrogates on an object-level K-fold split (the default evaluation suite's folds for "
        "its in-domain objects when K is theirs, the other objects dealt by --seed), each object held out "
        "once; writes foldK/ checkpoints and folds.json (no efficiency or smoothness runs)",
    )
    t.add_argument(
        "--init",
        type=path_text,
        default=None,
        help="continue from this checkpoint (fine-tuning on --data): its architecture and its normaliser "
        "are kept, not refitted; give no model options",
    )
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=run_train)

    s = subparsers.add_parser(
        "smoothness", help="re-measure a checkpoint's smoothness along design lines against the simulator"
    )
    s.add_argument("--ckpt", required=True, type=path_text, help="checkpoint folder (mjcodesign train --out)")
    s.add_argument("--data", required=True, type=path_text, help="the dataset it was trained on")
    s.add_argument(
        "--poses", type=int_at_least(1), default=16, help="held-out poses, one object after another"
    )
    s.add_argument("--lines", type=int_at_least(1), default=4, help="random design lines per pose")
    s.add_argument(
        "--part", choices=("test", "train"), default="test", help="held-out poses, or training poses"
    )
    s.add_argument("--out", type=path_text, default=None, help="also write every line to this JSON file")
    s.add_argument(
        "--threads", type=int_at_least(1), default=None, help="torch CPU threads (default: torch's)"
    )
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=run_smoothness)

    p = subparsers.add_parser("predict", help="the surrogate's outputs for one object, pose and design")
    p.add_argument(
        "--ckpt", type=path_text, default=None, help="checkpoint folder (default: the shipped weights)"
    )
    p.add_argument("--object", required=True, type=path_text, help="YCB name, egad-like:N or a mesh file")
    p.add_argument(
        "--pose",
        required=True,
        help="FILE.npz[:ROW] (mjcodesign poses --out), a JSON pose file, auto or best",
    )
    p.add_argument("--design", required=True, help="preset, random:SEED, or 11/22 comma-separated ln E")
    p.add_argument(
        "--density", default=None, help="kg/m³ or light/heavy (default: the middle of the training range)"
    )
    p.add_argument("--seed", type=int_at_least(0), default=0, help="seeds the point cloud's draw")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_predict)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``surrogate`` on the ``bench`` command's subparsers object."""
    b = bench_subparsers.add_parser(
        "surrogate",
        help="surrogate speed: MLP inference, training step, PointNet, cached inference, loss+grad",
    )
    b.add_argument("--repeats", type=int_at_least(1), default=5, help="timed repeats per case (fastest kept)")
    b.add_argument(
        "--threads", type=int_at_least(1), default=None, help="torch CPU threads (default: torch's)"
    )
    b.add_argument("--out", type=path_text, default=None, help="also write the JSON to this file")
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=run_bench)


def run_train(args: argparse.Namespace) -> int:
    """Run ``train``: the summary on stdout; library errors propagate (exit 2 there)."""
    import torch
    from rich.console import Console
    from rich.progress import Progress

    from mjcodesign.surrogate import (
        ModelConfig,
        OptimizerConfig,
        TensorBoardLog,
        TrainConfig,
        train_and_report,
        train_folds,
    )

    if args.threads:
        torch.set_num_threads(args.threads)
    cfg = TrainConfig(
        **_fields(args, _TRAIN_OPTIONS), optimizer=OptimizerConfig(**_fields(args, _OPTIMIZER_OPTIONS))
    )
    mcfg = ModelConfig(
        **_fields(args, _MODEL_OPTIONS),
        frame_inputs=not args.no_frame_inputs,
        success_head=args.success_weight > 0,
    )
    if args.init is not None:
        changed = [f for f, dest, _, default, _ in _MODEL_OPTIONS if getattr(args, dest) != default]
        if changed or args.no_frame_inputs:
            raise DesignError(
                f"--init keeps the checkpoint's architecture: drop {', '.join(changed or ['--no-frame-inputs'])}"
            )
        mcfg = None
    fold_of = _fold_of(args) if args.folds is not None else None
    if args.tensorboard:
        TensorBoardLog.check()  # a missing package is refused before any work
    boards: list = []  # the event writer, made at the first epoch (bad input leaves no file behind)
    console = Console(stderr=True)
    bars: dict[str, int] = {}
    try:
        with Progress(console=console, transient=True, disable=not console.is_terminal) as progress:

            def on_epoch(run, log):
                if run not in bars:
                    bars[run] = progress.add_task(f"train {run}", total=args.epochs)
                text = f"train {run}: loss {log.train_loss:.4f}, validation {log.val_loss:.4f}"
                progress.update(bars[run], completed=log.epoch + 1, description=text)
                if not console.is_terminal:  # a log file or pipe gets one line per epoch instead of the bar
                    console.print(
                        f"{text}, lr {log.lr:.3g}, {log.seconds:.0f} s{' (best)' if log.best else ''}"
                    )
                if args.tensorboard and run == "full":
                    if not boards:
                        boards.append(TensorBoardLog(args.tensorboard))
                    boards[0](log)

            if fold_of is not None:
                m = train_folds(args.data, args.out, fold_of, overwrite=args.overwrite, config=cfg,
                                model_config=mcfg, init=args.init, on_epoch=on_epoch, warn=_warn)  # fmt: skip
                emit(_folds_summary(args, m), args.json)
                return 0
            m = train_and_report(
                args.data,
                args.out,
                overwrite=args.overwrite,
                split_mode=args.split,
                config=cfg,
                model_config=mcfg,
                efficiency=args.efficiency,
                smoothness_poses=args.smoothness_poses,
                smoothness_lines=args.smoothness_lines,
                cache_dir=user_cache_dir(),
                on_epoch=on_epoch,
                init=args.init,
                warn=_warn,
                poses_per_object=args.poses_per_object,
            )
    finally:
        for board in boards:
            board.close()
    net = m["test"]["surrogate"]
    res = {
        "out": args.out,
        "split": m["split"],
        "train_rows": m["training"]["train_rows"],
        "epochs": m["training"]["epochs"],
        "best_epoch": m["training"]["best_epoch"],
        "wall_s": m["training"]["wall_s"],
        "test_loss": {k: v["loss"] for k, v in m["test"].items()},
        "mae": net["mae"],
        "success": {k: net["success"][k] for k in ("accuracy", "roc_auc", "rate", "predicted_rate")},
        "verdict": m["verdict"],
    }
    if "efficiency" in m:
        res["efficiency_test_loss"] = m["efficiency"]["test"]["loss"]
    emit(res, args.json)
    return 0


def _warn(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr, flush=True)


_FOLDS_REFUSES = (("--split", "split", "object"), ("--efficiency", "efficiency", 0.25),
                  ("--smoothness-poses", "smoothness_poses", 16), ("--smoothness-lines", "smoothness_lines", 4),
                  ("--tensorboard", "tensorboard", None),
                  ("--poses-per-object", "poses_per_object", None))  # flags whose run --folds does not make, at their defaults  # fmt: skip


def _fold_of(args: argparse.Namespace) -> dict[str, int]:
    """``--folds K``: each dataset object's fold (:func:`~mjcodesign.evaluation.suite.suite_folds`)."""
    from mjcodesign.data import open_dataset
    from mjcodesign.evaluation.suite import load_suite, suite_folds

    bad = [flag for flag, dest, default in _FOLDS_REFUSES if getattr(args, dest) != default]
    if bad:
        raise DesignError(f"--folds trains no {', '.join(bad)} run: drop {', '.join(bad)}")
    objects = open_dataset(args.data).manifest.get("objects", ())
    names = [str(o["name"]) for o in objects if o.get("status") == "ready"]
    fold_of = suite_folds(load_suite("default"), names, args.folds, seed=args.seed)
    filled = len(set(fold_of.values()))
    if filled < args.folds:
        raise DesignError(
            f"--folds {args.folds}: the dataset's {len(names)} objects fill {filled} of the folds "
            "(each fold holds out at least one object)"
        )
    return fold_of


def _folds_summary(args: argparse.Namespace, m: dict) -> dict:
    per_fold = [{"fold": f["path"], "held_out": len(f["held_out"]), "test_loss": f["test"]["loss"],
                 "success_roc_auc": f["test"]["success"]["roc_auc"]} for f in m["folds"]]  # fmt: skip
    return {"out": args.out, "folds": len(m["folds"]), "held_out": m["held_out"], "per_fold": per_fold}


def run_predict(args: argparse.Namespace) -> int:
    """Run ``predict``."""
    from mjcodesign.objects import parse_density

    design = parse_design(args.design)  # a wrong length exits 2 before torch is imported
    density = None if args.density is None else parse_density(args.density)

    from mjcodesign.surrogate import checkpoint_or_shipped, predict_grasp

    res = predict_grasp(
        checkpoint_or_shipped(args.ckpt),
        args.object,
        args.pose,
        design,
        density,
        seed=args.seed,
        cache_dir=user_cache_dir(),
    )
    emit(res if args.json else {k: v for k, v in res.items() if k not in ("pose", "design")}, args.json)
    return 0


def run_smoothness(args: argparse.Namespace) -> int:
    """Run ``smoothness``."""
    import torch

    from mjcodesign.outputs import write_atomic
    from mjcodesign.surrogate import checkpoint_smoothness

    if args.out:  # refused before the re-simulation, not after it
        from pathlib import Path

        from mjcodesign.errors import OutputError

        out = Path(args.out)
        if out.is_dir() or not out.parent.is_dir():
            raise OutputError(f"--out {out}: need a file path in an existing folder")
    if args.threads:
        torch.set_num_threads(args.threads)
    res = checkpoint_smoothness(
        args.ckpt, args.data, poses=args.poses, lines=args.lines, part=args.part, cache_dir=user_cache_dir()
    )
    if args.out:
        write_atomic(args.out, json.dumps({"ckpt": args.ckpt, "data": args.data, **res}, indent=1))
    emit({"ckpt": args.ckpt, "part": res["part"], **res["median"]}, args.json)
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench surrogate``."""
    import torch

    from mjcodesign.bench import run_benchmark

    if args.threads:
        torch.set_num_threads(args.threads)
    res = run_benchmark("surrogate", command=args.command_line, out=args.out, repeats=args.repeats)
    if args.json:
        print(json.dumps(res))
    else:
        emit([{"case": k, **v} for k, v in res["cases"].items()], False)
        emit({k: v for k, v in res.items() if k != "cases"}, False)
    sys.stdout.flush()
    return 0
