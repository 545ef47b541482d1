"""``mjcodesign crosscheck`` and ``mjcodesign bench fem``: the MuJoCo finger models against the Warp FEM.

Rows (``--json`` prints a list of them): ``scenario``, ``model``, ``design``, ``metric``, ``value``,
``reference``, ``rel_diff``. The comparisons are `mjcodesign.crosscheck`; the FEM's speed benchmark is
`mjcodesign.bench.fem`. This module parses the flags, calls them and prints.
"""

from __future__ import annotations

import json
import sys

from mjcodesign.cli.common import emit
from mjcodesign.cli.viz import add_recording_flags, open_recorder
from mjcodesign.crosscheck import MODELS, SCENARIOS, TOL_CROSS, crosscheck, plot_curves

__all__ = ["add_parser", "add_bench_parser"]


def _fem_options(args):
    from mjcodesign.sim.fem import FemOptions

    return FemOptions(h=args.fem_h, spine_layers=args.fem_layers, order=args.fem_order)


def _note(line: str) -> None:
    print(line, file=sys.stderr)


def _cmd_crosscheck(args) -> int:
    tensions = [float(v) for v in args.tensions.split(",")] if args.tensions else None
    rec = open_recorder(args)
    try:
        rows, curves = crosscheck(
            args.scenario,
            args.models.split(","),
            args.design,
            fem_options=_fem_options(args),
            tensions=tensions,
            observer=rec,
            on_note=_note,
        )
    finally:
        if rec is not None:
            rec.close()
    if args.plot:
        plot_curves(curves, args.plot)
    emit(rows, args.json)
    for r in rows:
        if r["model"] != "fem" and r["rel_diff"] is not None and r["rel_diff"] > TOL_CROSS:
            _note(
                f"note: {r['model']} misses the FEM by {r['rel_diff']:.0%} (> {TOL_CROSS:.0%}) on {r['metric']}"
            )
    return 0


def _cmd_bench_fem(args) -> int:
    if args.fem_order != 1:
        from mjcodesign.errors import DesignError

        raise DesignError("bench fem times explicit dynamics, which needs --fem-order 1")
    from mjcodesign.bench.fem import bench_fem

    res = bench_fem(
        h=args.fem_h, spine_layers=args.fem_layers, dyn_steps=args.steps, grasp_horizon=args.grasp_horizon
    )
    if args.out:
        from pathlib import Path

        Path(args.out).write_text(json.dumps(res))
    if args.json:
        print(json.dumps(res))
    else:
        emit(res, False)
    return 0


def _fem_flags(p, *, h: float, layers: int, order: int) -> None:
    p.add_argument("--fem-h", type=float, default=h, help="FEM cell size in the segments [m]")
    p.add_argument("--fem-layers", type=int, default=layers, help="FEM layers through the 2 mm spine (even)")
    p.add_argument("--fem-order", type=int, choices=(1, 2), default=order, help="FEM tet order")


def add_parser(subparsers) -> None:
    """Register ``crosscheck`` on the top-level sub-parsers."""
    p = subparsers.add_parser("crosscheck", help="run one case in every backend (MuJoCo models, Warp FEM)")
    p.add_argument("--scenario", choices=SCENARIOS, required=True)
    p.add_argument("--models", default="chain,flex,fem", help=f"comma-separated, from {MODELS}")
    p.add_argument(
        "--design", default="paper-optimized", help="preset name, random:SEED or 11/22 comma-separated log E"
    )
    p.add_argument("--tensions", default=None, help="curl tensions [N], comma-separated (press: the first)")
    p.add_argument("--plot", default=None, help="curl: write tip paths and bend against tension to this PNG")
    # Quadratic tets, 2 spine layers: within 4% of Euler–Bernoulli on the cantilever (mjcodesign.sim.fem).
    _fem_flags(p, h=4e-3, layers=2, order=2)
    add_recording_flags(p, decimation=False)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_crosscheck)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench fem`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "fem", help="Warp FEM steps/s on the CPU and static solve + gradient time"
    )
    _fem_flags(p, h=3e-3, layers=4, order=1)
    p.add_argument("--steps", type=int, default=2000, help="explicit substeps to time")
    p.add_argument("--grasp-horizon", type=float, default=0.2, help="dynamic grasp to time [s]")
    p.add_argument("--out", default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_fem)
