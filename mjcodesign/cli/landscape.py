"""``mjcodesign bench landscape`` and ``mjcodesign bench calibration``: parsing and printing.

The benchmarks are `mjcodesign.bench.landscape` (the grasp landscape over designs, poses, densities and
tendon drives) and `mjcodesign.bench.calibration` (the finger models against recorded FEM numbers).
"""

from __future__ import annotations

import json
import sys

from mjcodesign.cli.common import add_mass_mode, emit, int_at_least, path_text
from mjcodesign.cli.finger_flags import grasp_model_name
from mjcodesign.errors import DesignError

__all__ = ["add_bench_parser"]

_TENDONS = "force:10,position:1000"
_DENSITIES = "light,heavy"


def _names(text: str) -> tuple[str, ...]:
    return tuple(v.strip() for v in text.split(",") if v.strip())


def _note(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _cmd_landscape(args) -> int:
    from mjcodesign.bench import run_benchmark
    from mjcodesign.bench.landscape import CI, DESIGNS, REAL
    from mjcodesign.bench.landscape_real import CI_REAL

    real = args.regime == REAL
    kw = dict(regime=args.regime, poses=args.poses, designs=DESIGNS, sweep=not args.no_sweep)
    if args.ci:
        ci = CI_REAL if real else CI
        kw.update(objects=ci["objects"], poses=ci["poses"], designs=ci["designs"], sweep=real)
    if args.objects:
        kw["objects"] = _names(args.objects)
    if args.designs:
        kw["designs"] = _names(args.designs)
    if args.sensitivity_designs:
        kw["sensitivity_designs"] = _names(args.sensitivity_designs)
    if real and (args.tendons is not None or args.densities is not None):
        raise DesignError(
            "--tendons and --densities are the paper regime's: the real regime runs the XL330 servo on every "
            "object at its published mass"
        )
    if not real:
        kw.update(
            tendons=_names(args.tendons or _TENDONS),
            densities=("real",) if args.mass == "real" else _names(args.densities or _DENSITIES),
        )
    res = run_benchmark(
        "landscape",
        command=args.command_line,
        out=args.out,
        **kw,
        model=args.model,
        seed=args.seed,
        on_progress=_note,
    )
    if args.json:
        print(json.dumps(res))
    elif real:
        emit(_real_rows(res), False)
    else:
        emit([_flat(b) for b in res["blocks"] + res.get("sweep", [])], False)
    return 0


def _real_rows(res: dict) -> list[dict]:
    """One row per design group: success over objects with its interval, and the disagreeing pairs."""
    rows = []
    for label, block in [("real", res)] + [(f"{r['setting']}={r['value']:g}", r) for r in res["sensitivity"]]:
        for g, st in block["success"].items():
            o = st.get("objects", st["rollouts"])
            rows.append(
                {
                    "setting": label,
                    "group": g,
                    "success": round(o["value"], 3),
                    "interval": f"[{o['low']:.3f}, {o['high']:.3f}]",
                    "mixed pairs": round(block["pairs"]["mixed_share"]["value"], 3),
                }
            )
    return rows


def _flat(block: dict) -> dict:
    keep = ("label", "rollouts", "success_all", "implausible", "diverged", "far", "far_implausible", "nan")
    keep += ("cpu_s_per_rollout",)
    row = {k: block[k] for k in keep}
    row.update({f"success[{g}]": v for g, v in block["success"].items()})
    row["pairs all/mixed/none"] = "/".join(str(block["pairs"][k]) for k in ("all", "mixed", "none"))
    return row


def _cmd_calibration(args) -> int:
    from mjcodesign.bench import run_benchmark

    kw = {"models": _names(args.models)}
    if args.reference:
        kw["references"] = (args.reference,)
    if args.designs:
        kw["designs"] = _names(args.designs)
    res = run_benchmark("calibration", command=args.command_line, out=args.out, on_progress=_note, **kw)
    if args.json:
        print(json.dumps(res))
    else:
        emit(
            [
                {"fem_mesh": mesh, "model": m, "metric": k, **v}
                for mesh, models in res["summary"].items()
                for m, kinds in models.items()
                for k, v in kinds.items()
            ],
            False,
        )
    return 0


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench landscape`` and ``bench calibration`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "landscape", help="grasp success and its spread over designs, poses, densities and tendon drives"
    )
    p.add_argument(
        "--objects", default=None, help="comma-separated objects (default: 8 in-domain YCB objects)"
    )
    p.add_argument(
        "--regime",
        choices=("paper", "real"),
        default="real",
        help="paper: blocks over densities and tendon drives (the paper's relative scale); real: the suite's "
        "in-domain objects at their real masses under the hardware's grasp, with intervals and sensitivity",
    )
    p.add_argument(
        "--poses",
        type=int_at_least(1),
        default=None,
        help="poses per object (paper: sampler poses, default 4; real: the suite's first, default all 10)",
    )
    p.add_argument(
        "--designs", default=None, help="comma-separated designs (default: 3 presets and random:0-7)"
    )
    p.add_argument("--tendons", default=None, help=f"comma-separated tendon drives (default {_TENDONS})")
    p.add_argument(
        "--densities",
        default=None,
        help=f"comma-separated densities: presets of the paper's relative scale, kg/m³, or real (default {_DENSITIES})",
    )
    add_mass_mode(p, "in place of --densities (objects without one are skipped)")
    p.add_argument("--model", choices=("chain",), default="chain", type=grasp_model_name)
    p.add_argument("--seed", type=int, default=0, help="pose sampler and CoACD seed")
    p.add_argument(
        "--no-sweep",
        action="store_true",
        help="skip the tendon / density / impulse sweep (real: the sensitivity table)",
    )
    p.add_argument(
        "--sensitivity-designs",
        default=None,
        help="real: comma-separated designs of the sensitivity table (default: the --designs)",
    )
    p.add_argument(
        "--ci",
        action="store_true",
        help="the short version the tests run (paper: 1 object, 2 poses, 3 designs; real: 1 object, 2 poses, "
        "soft and semi-rigid, with the sensitivity table)",
    )
    p.add_argument("--out", type=path_text, default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_landscape)

    c = bench_subparsers.add_parser(
        "calibration", help="finger models against recorded converged-FEM numbers"
    )
    c.add_argument("--models", default="chain,flex,flex-quadratic", help="comma-separated MuJoCo models")
    c.add_argument("--designs", default=None, help="comma-separated design names of the reference file")
    c.add_argument("--reference", type=path_text, default=None, help="recorded FEM numbers (JSON)")
    c.add_argument("--out", type=path_text, default=None, help="also write the JSON to this file")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=_cmd_calibration)
