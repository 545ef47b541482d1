"""``mjcodesign bench oracle``: CMA-ES on the simulator alone, on the evaluation's objective.

The upper bound of what one design reaches on a suite's objects (:mod:`mjcodesign.evaluation.oracle`).
Every input is checked before anything runs; the folder (``design.json``, ``oracle.json``,
``curve.png``) lands in ``--out`` only when the search finished.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from mjcodesign.cli.common import add_regime, emit, finite_float, int_at_least, path_text, user_cache_dir
from mjcodesign.cli.progress import StageProgress

__all__ = ["add_bench_parser", "run_bench"]

_SPLITS = ("in-domain", "out-of-domain", "all")


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench oracle``."""
    b = bench_subparsers.add_parser(
        "oracle",
        help="CMA-ES on the simulator alone, on the evaluation's success: the best one design reaches",
    )
    b.add_argument("--suite", default="default", help="suite file (JSON) or 'default' (the shipped one)")
    b.add_argument("--split", choices=_SPLITS, default="in-domain", help="the suite's objects to optimise on")
    b.add_argument(
        "--only",
        default=None,
        help="keep only these objects of --split: comma-separated names, or a text file of names (commas or lines)",
    )
    b.add_argument(
        "--candidates", type=int_at_least(1), default=None, help="use only each object's first N suite poses"
    )
    b.add_argument(
        "--perturbations",
        type=int_at_least(1),
        default=2,
        help="draws per pose: the evaluation's first N draws (same seed, same draws)",
    )
    b.add_argument(
        "--policy",
        choices=("all", "oracle"),
        default="all",
        help="success over every pose, or at each object's best pose for the design",
    )
    b.add_argument("--budget", type=int_at_least(1), default=40_000, help="most rollouts")
    b.add_argument(
        "--population", type=int_at_least(4), default=None, help="designs a generation (default 13)"
    )
    b.add_argument(
        "--sigma", type=finite_float(0.0, strict=True), default=1.0, help="CMA-ES's first step in z"
    )
    b.add_argument(
        "--start",
        default="semi-rigid",
        help="the first generation's centre: a preset or joint:FILE; several (comma-separated, e.g. a "
        "surrogate's designs from optimize) are each scored first and the search starts from the best",
    )
    add_regime(b)
    b.add_argument("--seed", type=int_at_least(0), default=0, help="seed of the draws and of CMA-ES")
    b.add_argument("--out", type=path_text, required=True, help="folder: design.json, oracle.json, curve.png")
    b.add_argument(
        "--overwrite", action="store_true", help="write into a non-empty folder, keeping its other files"
    )
    b.add_argument("--json", action="store_true", help="print the result as JSON")
    b.set_defaults(func=run_bench)


def _only(text: str | None) -> set[str] | None:
    from mjcodesign.errors import DesignError
    from mjcodesign.evaluation import parse_list

    if text is None:
        return None
    p = Path(text)
    try:
        is_file = p.is_file()
    except OSError:  # a long list of names is no path the system can stat (ENAMETOOLONG)
        is_file = False
    if is_file:
        try:
            text = p.read_text(encoding="utf-8")
            names = [s.strip() for s in text.replace(",", "\n").splitlines() if s.strip()]
        except (OSError, UnicodeDecodeError) as exc:
            raise DesignError(f"--only {text}: cannot read it ({exc})") from None
        if not names:
            raise DesignError(f"--only {text}: the file names no object")
        return set(names)
    return set(parse_list(text, "only"))


def _objects(suite, split: str, only: set[str] | None):
    from mjcodesign.errors import DesignError

    objects = [o for o in suite.objects if split == "all" or o.domain == split]
    if only is not None:
        missing = sorted(only - {o.name for o in objects})
        if missing:
            raise DesignError(
                f"--only: {len(missing)} object(s) not in the suite's {split} split: {', '.join(missing[:4])}"
            )
        objects = [o for o in objects if o.name in only]
    if not objects:
        raise DesignError(f"the suite holds no {split} object")
    return tuple(objects)


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench oracle``; library errors propagate (exit 2 there)."""
    from mjcodesign.bench.record import provenance
    from mjcodesign.design.stiffness import Stiffness, write_design_file
    from mjcodesign.evaluation import parse_design_groups
    from mjcodesign.evaluation.oracle import OracleConfig, oracle_search
    from mjcodesign.evaluation.rollouts import SuiteRun
    from mjcodesign.evaluation.suite import load_suite
    from mjcodesign.outputs import OutputKind, check_output, staged, write_atomic
    from mjcodesign.scenarios import get_regime, regime_name

    config = OracleConfig(
        budget=args.budget, policy=args.policy, sigma=args.sigma, population=args.population, seed=args.seed
    )
    starts = parse_design_groups(args.start)
    regime = get_regime(args.regime)
    density, mass = regime.masses(None, None)
    run = SuiteRun(
        designs=starts[:1],
        perturbations=args.perturbations,
        densities=(density,),
        mass=mass,
        scenario=regime.scenario,
        seed=args.seed,
    )
    suite = load_suite(args.suite)
    objects = _objects(suite, args.split, _only(args.only))
    if args.candidates is not None:
        objects = tuple(
            dataclasses.replace(
                o, poses=o.poses[: args.candidates], source_index=o.source_index[: args.candidates]
            )
            for o in objects
        )
    suite = dataclasses.replace(suite, objects=objects)
    folder = check_output(
        args.out,
        OutputKind.ORACLE,
        overwrite=args.overwrite,
        inputs={"--suite": args.suite, "--only": args.only},
    )
    with StageProgress("bench oracle") as progress:
        result = oracle_search(
            suite, run, config, start=starts, cache_dir=user_cache_dir(), progress=progress
        )
    summary = {
        "provenance": provenance("oracle", command=args.command_line),
        "suite": {"name": suite.name, "digest": suite.digest, "split": args.split, "objects": len(objects)},
        "regime": regime_name(run.scenario, run.mass),
        "scenario": run.scenario.as_dict(),
        "mass": run.mass,
        "density": density,
        "poses_per_object": max(len(o.poses) for o in objects),
        "perturbations": args.perturbations,
        "seed": args.seed,
        "config": dataclasses.asdict(config),
        **result.summary(),
        "out": str(args.out),
    }
    with staged(folder) as tmp:
        write_design_file(
            tmp / "design.json",
            Stiffness(result.design),
            source="bench oracle",
            success=result.success,
            objects=len(objects),
        )
        write_atomic(tmp / "oracle.json", _dumps(summary))
        _plot(result, tmp / "curve.png")
    emit(summary if args.json else _flat(summary), args.json)
    return 0


def _dumps(summary: dict) -> str:
    import json

    return json.dumps(summary, indent=1) + "\n"


def _flat(summary: dict) -> dict:
    return {
        "objects": summary["suite"]["objects"],
        "proposals": ", ".join(f"{p['label']} {100 * p['success']:.1f}%" for p in summary["proposals"]),
        "start": f"{summary['start']} {100 * summary['start_success']:.1f}%",
        "oracle": f"{100 * summary['success']:.1f}%",
        "rollouts": summary["rollouts"],
        "generations": summary["generations"],
        "out": summary["out"],
    }


def _plot(result, path: Path) -> None:
    """The best score so far and each generation's mean against the rollouts spent."""
    from mjcodesign.outputs import new_figure, save_figure

    fig = new_figure((6.0, 3.6), unavailable="bench oracle's curve.png needs matplotlib")
    ax = fig.add_subplot(1, 1, 1)
    x = [c["rollouts"] for c in result.curve]
    ax.axhline(100 * result.start_success, color="0.5", ls="--", label=f"start ({result.start})")
    ax.plot(x, [100 * c["best_so_far"] for c in result.curve], "o-", label="best so far")
    ax.plot(x, [100 * c["mean"] for c in result.curve], ".:", label="generation mean")
    ax.set_xlabel("rollouts")
    ax.set_ylabel("success over objects [%]")
    ax.legend(loc="lower right")
    save_figure(fig, path, dpi=110)
