"""``mjcodesign bench landscape`` and ``mjcodesign bench calibration``: parsing and printing.

The benchmarks are `mjcodesign.bench.landscape` (the grasp landscape over designs, poses, densities and
tendon drives) and `mjcodesign.bench.calibration` (the finger models against recorded FEM numbers).
"""

from __future__ import annotations

import json
import sys

from mjcodesign.cli.common import add_mass_mode, emit, int_at_least, path_text

__all__ = ["add_bench_parser"]


def _names(text: str) -> tuple[str, ...]:
    return tuple(v.strip() for v in text.split(",") if v.strip())


def _note(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _cmd_landscape(args) -> int:
    from mjcodesign.bench import run_benchmark
    from mjcodesign.bench.landscape import CI, DESIGNS, OBJECTS

    kw = dict(objects=OBJECTS, poses=args.poses, designs=DESIGNS, sweep=not args.no_sweep)
    if args.ci:
        kw.update(objects=CI["objects"], poses=CI["poses"], designs=CI["designs"], sweep=CI["sweep"])
    if args.objects:
        kw["objects"] = _names(args.objects)
    if args.designs:
        kw["designs"] = _names(args.designs)
    res = run_benchmark(
        "landscape",
        command=args.command_line,
        out=args.out,
        **kw,
        tendons=_names(args.tendons),
        densities=("real",) if args.mass == "real" else _names(args.densities),
        model=args.model,
        seed=args.seed,
        on_progress=_note,
    )
    if args.json:
        print(json.dumps(res))
    else:
        emit([_flat(b) for b in res["blocks"] + res.get("sweep", [])], False)
    return 0


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
    p.add_argument("--poses", type=int_at_least(1), default=4, help="sampler poses per object")
    p.add_argument(
        "--designs", default=None, help="comma-separated designs (default: 3 presets and random:0-7)"
    )
    p.add_argument("--tendons", default="force:10,position:1000", help="comma-separated tendon drives")
    p.add_argument(
        "--densities",
        default="light,heavy",
        help="comma-separated densities: presets of the paper's relative scale, kg/m³, or real",
    )
    add_mass_mode(p, "in place of --densities (objects without one are skipped)")
    p.add_argument("--model", choices=("chain", "flex"), default="chain")
    p.add_argument("--seed", type=int, default=0, help="pose sampler and CoACD seed")
    p.add_argument("--no-sweep", action="store_true", help="skip the tendon / density / impulse sweep")
    p.add_argument(
        "--ci", action="store_true", help="the short version the tests run (1 object, 2 poses, 3 designs)"
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
