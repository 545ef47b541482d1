"""``mjcodesign bench labels``: how repeatable a grasp label is under the evaluation's perturbations.

The benchmark is :mod:`mjcodesign.bench.labels`; this module parses its flags and prints its numbers.
"""

from __future__ import annotations

import json

from mjcodesign.cli.common import emit, int_at_least, output_file, user_cache_dir

__all__ = ["add_bench_parser"]

_DESIGNS = "soft,semi-rigid,paper-optimized,random:0,random:1,random:2,random:3,random:4"


def _cmd_labels(args) -> int:
    from mjcodesign.bench import run_benchmark
    from mjcodesign.cli.progress import StageProgress
    from mjcodesign.evaluation import parse_design_groups

    designs = tuple(v.strip() for v in args.designs.split(",") if v.strip())
    parse_design_groups(",".join(designs))  # a bad design is refused before any object is loaded
    with StageProgress("bench labels") as bars:
        res = run_benchmark(
            "labels",
            command=args.command_line,
            out=args.out,
            objects=args.objects,
            poses=args.poses,
            designs=designs,
            draws=args.draws,
            seed=args.seed,
            cache_dir=user_cache_dir(),
            progress=bars,
            warn=bars.note,
        )
    if args.json:
        print(json.dumps(res))
    else:
        emit(_rows(res), False)
    return 0


def _rows(res: dict) -> list[dict]:
    """One row per design group and one for every cell: all-agree shares, p, draws needed, adaptive cost."""
    rows = []
    for name, b in [("all", res["overall"]), *res["by_group"].items()]:
        rows.append(
            {
                "group": name,
                "cells": b["cells"],
                **{f"agree@{k}": round(v, 3) for k, v in b["agree"].items()},
                "mean p": round(b["mean_p"], 3),
                "0<p<1": round(b["share_between"], 3),
                "draws for SE<=0.1 (median)": b["median_draws_needed"],
                "adaptive rollouts/cell": None
                if b["adaptive_rollouts_per_cell"] is None
                else round(b["adaptive_rollouts_per_cell"], 2),
            }
        )
    return rows


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench labels`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "labels",
        help="how often repeated perturbed rollouts of one (object, pose, design) agree, under the real "
        "regime at published masses; the draws a success-probability label needs",
    )
    p.add_argument(
        "--objects",
        type=int_at_least(1),
        default=12,
        help="the first N in-domain objects of the suite with a published mass, in suite order",
    )
    p.add_argument("--poses", type=int_at_least(1), default=3, help="the first P suite poses of each object")
    p.add_argument(
        "--designs",
        default=_DESIGNS,
        help="comma-separated designs: presets, random:SEED, joint:FILE",
    )
    p.add_argument(
        "--draws",
        type=int_at_least(1),
        default=16,
        help="perturbed rollouts per (object, pose, design); fewer draws are the first of these",
    )
    p.add_argument("--seed", type=int_at_least(0), default=0, help="seed of the perturbation draws")
    p.add_argument("--out", type=output_file, default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_labels)
