"""``mjcodesign evaluate``: designs compared by re-simulation on a frozen suite, with intervals.

Every input is checked before anything runs or is written; a refused command exits 2 with one line and
leaves no folder behind. The report lands in ``--out`` only when the run finished.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from mjcodesign.cli.common import (
    FRICTION_HELP,
    add_mass_mode,
    add_regime,
    emit,
    finite_float,
    int_at_least,
    path_text,
    scenario_physics,
    user_cache_dir,
)
from mjcodesign.cli.finger_flags import add_routing, grasp_model_name, routing_options
from mjcodesign.cli.progress import StageProgress

__all__ = ["add_bench_parser", "add_parser", "run", "run_bench"]

_RECORDED_PER_DESIGN = 2  # best and worst rollouts per design re-run into --rrd
_QUICK_OBJECTS = "012_strawberry,013_apple,025_mug,egad-like:1,egad-like:7"  # 3 in-domain, 2 out
_QUICK_POSES = 2
_QUICK_PERTURBATIONS = 2
_EGAD_DEFAULT = 60  # egad-like shapes of a bare --egad-like: about the in-domain count, for a like interval


def add_parser(subparsers) -> None:
    """Register ``evaluate`` on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "evaluate",
        help="compare designs by re-simulation on a frozen suite: success with intervals, paired tests",
    )
    p.add_argument(
        "--suite",
        default=None,
        help="suite file (JSON) or 'default' (the shipped one: 46 in-domain + 42 out-of-domain objects, "
        "10 poses each); without it, --objects builds an ad-hoc suite; with neither, 'default'",
    )
    p.add_argument(
        "--objects",
        default=None,
        help="instead of --suite: comma-separated sets (ycb-in-domain, ycb-ood, egad-like, ood), folders, "
        "YCB names or mesh files, posed now (--poses-per-object)",
    )
    p.add_argument(
        "--poses-per-object", type=int_at_least(1), default=10, help="poses sampled per object of --objects"
    )
    p.add_argument("--save-suite", type=path_text, default=None, help="also write the ad-hoc suite here")
    p.add_argument(
        "--designs",
        default="soft,semi-rigid,paper-optimized",
        help="comma-separated: presets, random:SEED, joint:FILE (a design file), individual:DIR (OBJECT.json files)",
    )
    p.add_argument(
        "--pose-sampling",
        default="fixed,oracle",
        help="comma-separated pose policies: fixed (first pose), surrogate (--ckpt's network), oracle (the "
        "simulator's best); every report also gives 'all' (every pose)",
    )
    p.add_argument(
        "--perturbations",
        type=int_at_least(1),
        default=8,
        help="perturbed rollouts per (object, pose, design)",
    )
    p.add_argument(
        "--palm-mm", type=finite_float, default=2.0, help="ad-hoc suite: palm position error ± [mm]"
    )
    p.add_argument(
        "--palm-deg", type=finite_float, default=2.0, help="ad-hoc suite: palm rotation error ± [deg]"
    )
    p.add_argument(
        "--mass-range", type=finite_float, default=0.10, help="ad-hoc suite: object mass error ± [-]"
    )
    p.add_argument(
        "--friction-range",
        type=finite_float,
        default=0.20,
        help="ad-hoc suite: finger–object friction error ± [-]",
    )
    p.add_argument(
        "--tendon",
        default=None,
        help="tendon drive of every rollout: force:N (tension per finger [N]) or position:TICKS (the XL330 "
        "servo's goal, e.g. position:1000 as the paper's hardware); default: the scenario's",
    )
    p.add_argument(
        "--tendon-range",
        type=finite_float,
        default=0.05,
        help="ad-hoc suite: tendon tension / servo gain error ± [-]",
    )
    p.add_argument(
        "--quick", action="store_true", help=f"a small suite for CI ({_QUICK_OBJECTS}; 2 poses, 2 draws)"
    )
    p.add_argument(
        "--ckpt",
        type=path_text,
        default=None,
        help="surrogate checkpoint for --pose-sampling surrogate (default: the shipped weights)",
    )
    add_regime(p)
    p.add_argument(
        "--density",
        default=None,
        help="comma-separated densities: light, heavy, ycb-median or kg/m³ (default: the regime's; real: "
        "ycb-median for the objects without a published mass; paper: light)",
    )
    add_mass_mode(p, "one regime 'real' in place of --density (an object without one is refused up front)")
    p.add_argument(
        "--egad-like",
        type=int_at_least(0),
        nargs="?",
        const=_EGAD_DEFAULT,
        default=0,
        metavar="N",
        help=f"add N procedural egad-like shapes (N: {_EGAD_DEFAULT} when omitted) to the out-of-domain split, "
        "posed now with the suite's seed; their indices follow the suite's own egad-like shapes",
    )
    p.add_argument(
        "--impulse", default="0.1", help="disturbances in the paper's units [N s], comma-separated (a sweep)"
    )
    p.add_argument(
        "--candidates", type=int_at_least(1), default=None, help="use only each object's first N suite poses"
    )
    p.add_argument(
        "--anygrasp",
        type=path_text,
        default=None,
        help="ad-hoc suite: folder of the authors' AnyGrasp OBJECT.npz poses",
    )
    p.add_argument("--model", choices=("chain",), default="chain", type=grasp_model_name)
    add_routing(p)
    p.add_argument("--friction", default=None, help=FRICTION_HELP)
    p.add_argument(
        "--seed", type=int_at_least(0), default=0, help="seed of the perturbation draws (and ad-hoc poses)"
    )
    p.add_argument(
        "--out",
        type=path_text,
        required=True,
        help="report folder (results.json, summary.json, table.md, paired.md, per_object.csv, forest.png)",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="write into a non-empty folder, keeping its other files"
    )
    p.add_argument(
        "--rrd",
        type=path_text,
        default=None,
        help="also record the best and worst grasps per design for Rerun",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    p.set_defaults(func=run)


def _names(text: str) -> tuple[str, ...]:
    from mjcodesign.data import resolve_objects
    from mjcodesign.evaluation import parse_list

    names: list[str] = []
    for item in parse_list(text, "objects"):
        for n in resolve_objects(item):
            if n not in names:
                names.append(n)
    return names


def _floats(text: str, flag: str) -> tuple[float, ...]:
    from mjcodesign.errors import DesignError
    from mjcodesign.evaluation import parse_list

    try:
        return tuple(float(v) for v in parse_list(text, flag))
    except ValueError:
        raise DesignError(f"--{flag}: numbers, comma-separated, got {text!r}") from None


def _run_config(args: argparse.Namespace):
    from mjcodesign.evaluation import parse_design_groups, parse_list
    from mjcodesign.evaluation.rollouts import SuiteRun
    from mjcodesign.objects import parse_density
    from mjcodesign.scenarios import get_regime, parse_tendon

    regime = get_regime(args.regime)
    if args.mass == "real" and args.density is not None:
        from mjcodesign.errors import DesignError

        raise DesignError("--mass real sets each object's density from its published mass: drop --density")
    density, mass = regime.masses(args.density, args.mass)
    densities = parse_list(density, "density")
    for d in densities:
        parse_density(d)
    scenario = dataclasses.replace(regime.scenario, **scenario_physics(None, args.friction))
    if args.tendon is not None:
        scenario = dataclasses.replace(scenario, tendon=parse_tendon(args.tendon))
    return SuiteRun(
        scenario=scenario,
        mass=mass,
        designs=parse_design_groups(args.designs),
        perturbations=_QUICK_PERTURBATIONS if args.quick else args.perturbations,
        densities=densities,
        impulses=_floats(args.impulse, "impulse"),
        pose_policies=parse_list(args.pose_sampling, "pose-sampling"),
        model=args.model,
        options=routing_options(args),
        seed=args.seed,
    )


def _suite_source(args: argparse.Namespace):
    """('file', suite) or ('build', (names, poses per object, perturbation model)), all checked."""
    from mjcodesign.errors import DesignError
    from mjcodesign.evaluation.suite import PerturbationModel, egad_sources, load_suite

    adhoc = args.objects is not None or args.quick
    if sum((args.suite is not None, args.objects is not None, args.quick)) > 1:
        raise DesignError("give one of --suite, --objects and --quick")
    if args.anygrasp is not None and not Path(args.anygrasp).is_dir():
        from mjcodesign.errors import PoseError

        raise PoseError(f"--anygrasp: {args.anygrasp} is not a folder")
    ranges = PerturbationModel(
        palm_position_m=args.palm_mm / 1000.0,
        palm_rotation_deg=args.palm_deg,
        mass=args.mass_range,
        friction=args.friction_range,
        tendon=args.tendon_range,
    )
    if not adhoc:
        if ranges != PerturbationModel():
            raise DesignError(
                "a frozen suite fixes its perturbation ranges: build an ad-hoc one with --objects"
            )
        return "file", load_suite(args.suite or "default")
    names = _names(_QUICK_OBJECTS if args.quick else args.objects)
    poses = _QUICK_POSES if args.quick else args.poses_per_object
    return "build", ((*names, *egad_sources(args.egad_like, names)), poses, ranges)


def _trim(suite, n: int | None):
    if n is None:
        return suite
    objects = tuple(
        dataclasses.replace(o, poses=o.poses[:n], source_index=o.source_index[:n]) for o in suite.objects
    )
    return dataclasses.replace(suite, objects=objects)


def run(args: argparse.Namespace) -> int:
    """Run ``evaluate``; library errors propagate (exit 2 there)."""
    from mjcodesign.errors import DesignError, OutputError
    from mjcodesign.evaluation.analysis import analyse
    from mjcodesign.evaluation.rollouts import check_real_masses, record_suite_examples, run_suite
    from mjcodesign.evaluation.suite import add_objects, build_suite, egad_sources
    from mjcodesign.evaluation.suite_report import suite_header, write_suite_report
    from mjcodesign.outputs import OutputKind, check_output
    from mjcodesign.scenarios import regime_name

    run_cfg = _run_config(args)
    kind, source = _suite_source(args)
    if run_cfg.mass == "real":  # refused before any folder or work
        check_real_masses(source[0] if kind == "build" else [o.source for o in source.objects])
        if kind == "file" and args.egad_like:
            check_real_masses(egad_sources(args.egad_like, [o.source for o in source.objects]))
    ckpt = args.ckpt
    if run_cfg.needs_surrogate:  # refused in one line, before any folder, while no weights ship
        from mjcodesign.surrogate.shipped import checkpoint_or_shipped

        ckpt = checkpoint_or_shipped(args.ckpt)
    folder = check_output(
        args.out,
        OutputKind.EVALUATION,
        overwrite=args.overwrite,
        inputs={"--ckpt": ckpt, "--anygrasp": args.anygrasp, "--suite": args.suite},
    )
    if args.rrd is not None and not Path(args.rrd).resolve().parent.is_dir():
        raise OutputError(f"--rrd {args.rrd}: folder {Path(args.rrd).parent} does not exist")
    if args.save_suite is not None and kind != "build":
        raise DesignError("--save-suite writes an ad-hoc suite: give --objects")
    if args.save_suite is not None and not Path(args.save_suite).resolve().parent.is_dir():
        raise OutputError(f"--save-suite {args.save_suite}: its folder does not exist")
    surrogate, n_points = None, 1024
    if run_cfg.needs_surrogate:
        from mjcodesign.surrogate import load_any

        surrogate = load_any(ckpt)  # one checkpoint, or the K networks of `train --folds`
        n_points = int(surrogate.meta["dataset"]["cloud_points"])
    cache = user_cache_dir()
    t0 = time.perf_counter()
    with StageProgress("evaluate") as progress:
        if kind == "build":
            names, poses, ranges = source
            suite = build_suite(
                names,
                name="quick" if args.quick else "adhoc",
                poses_per_object=poses,
                seed=args.seed,
                perturbation=ranges,
                anygrasp=args.anygrasp,
                cache_dir=cache,
                progress=lambda s, d, t: progress("posing objects", d, t),
                warn=_warn,
            )
            if args.save_suite:
                suite = suite.save(args.save_suite)
        else:
            suite = source
            if args.egad_like:
                sources = egad_sources(args.egad_like, [o.source for o in suite.objects])
                suite = add_objects(
                    suite,
                    sources,
                    label=f"egad-like:{args.egad_like}",
                    cache_dir=cache,
                    progress=lambda s, d, t: progress("posing egad-like objects", d, t),
                    warn=_warn,
                )
        suite = _trim(suite, args.candidates)
        result = run_suite(
            suite,
            run_cfg,
            surrogate=surrogate,
            n_points=n_points,
            cache_dir=cache,
            progress=lambda s, d, t: progress("rollouts by object", d, t),
            warn=_warn,
        )
    if not result["rows"]:
        raise DesignError("no object could be loaded and simulated (see the warnings above)")
    labels = [g.label for g in run_cfg.designs]
    analysis = analyse(result, labels, list(run_cfg.pose_policies), seed=args.seed)
    wall = time.perf_counter() - t0
    meta = {
        "designs": labels,
        "perturbations": run_cfg.perturbations,
        "densities": ["real"] if run_cfg.mass != "density" else list(run_cfg.densities),
        "impulses_paper_ns": list(run_cfg.impulses),
        "pose_policies": list(run_cfg.pose_policies),
        "model": run_cfg.model,
        "routing": args.routing,
        "seed": run_cfg.seed,
        "tendon": run_cfg.scenario.tendon.text(),
        "perturbation_model": suite.perturbation.as_dict(),
        "checkpoint": None if ckpt is None else str(ckpt),
        "mass": run_cfg.mass,
        "regime": regime_name(run_cfg.scenario, run_cfg.mass),
        "scenario": run_cfg.scenario.as_dict(),
        "command": args.command_line,
        "wall_time_s": wall,
        "rollout_wall_time_s": result["wall_time_s"],
        "rollouts_per_s": len(result["rows"]) / max(result["wall_time_s"], 1e-9),
    }
    if hasattr(surrogate, "for_object"):
        meta["checkpoint_folds"] = _fold_use(result["surrogate_choice"], suite, len(surrogate.surrogates))
    if args.rrd:
        from mjcodesign.cli.viz import open_recorder

        recorder = open_recorder(args)
        try:
            meta["recorded"] = record_suite_examples(
                suite, run_cfg, result["rows"], recorder, per_design=_RECORDED_PER_DESIGN, cache_dir=cache
            )
        except BaseException:
            recorder.close(discard=True)
            raise
        recorder.close()
    summary = write_suite_report(folder, result, analysis, labels, suite_header(suite), meta)
    summary["out"] = str(args.out)
    emit(summary if args.json else _flat(summary), args.json)
    return 0


def _fold_use(choice: dict, suite, folds: int) -> dict:
    """Per domain: objects scored by a fold network that held them out, and objects no fold trained on."""
    out = {"folds": folds}
    for o in suite.objects:
        entries = [e for per_density in choice.get(o.name, {}).values() for e in per_density.values()]
        if entries:
            d = out.setdefault(o.domain, {"held_out": 0, "unseen": 0})
            d["held_out" if entries[0]["held_out"] else "unseen"] += 1
    return out


def _warn(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr, flush=True)


def _flat(summary: dict) -> list[dict]:
    rows = []
    for reg in summary["regimes"]:
        for policy, entry in reg["policies"].items():
            for d, splits in entry["designs"].items():
                row = {
                    "density": reg["density"],
                    "impulse": reg["impulse_paper_ns"],
                    "pose": policy,
                    "design": d,
                }
                for split, iv in splits.items():
                    row[split] = (
                        "—"
                        if iv is None
                        else f"{100 * iv['value']:.1f}% [{100 * iv['low']:.1f}, {100 * iv['high']:.1f}] n={iv['n']}"
                    )
                rows.append(row)
    return rows


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench evaluate``: raw ``mujoco.rollout`` against the suite pipeline, same scenes."""
    b = bench_subparsers.add_parser(
        "evaluate",
        help="suite evaluation throughput against raw mujoco.rollout on the same scenes (JSON)",
    )
    b.add_argument("--objects", default="013_apple,025_mug,egad-like:3", help="comma-separated objects")
    b.add_argument("--poses-per-object", type=int_at_least(1), default=10)
    b.add_argument("--perturbations", type=int_at_least(1), default=8)
    b.add_argument("--designs", default="soft,semi-rigid,paper-optimized,random:1")
    add_regime(b)
    b.add_argument("--repeats", type=int_at_least(1), default=2, help="pipeline/raw pairs, back to back")
    b.add_argument("--out", type=path_text, default=None, help="also write the record here")
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench evaluate``."""
    from mjcodesign.bench import run_benchmark
    from mjcodesign.evaluation import parse_design_groups

    parse_design_groups(args.designs)
    res = run_benchmark(
        "evaluate",
        command=args.command_line,
        out=args.out,
        objects=_names(args.objects),
        poses_per_object=args.poses_per_object,
        perturbations=args.perturbations,
        designs=args.designs,
        regime=args.regime,
        repeats=args.repeats,
        cache_dir=user_cache_dir(),
    )
    emit(res, args.json)
    return 0
