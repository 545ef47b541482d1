"""``mjcodesign crosscheck`` and ``mjcodesign bench fem``: the MuJoCo finger models against the Warp FEM.

One subcommand per scenario, each with only its own flags: ``crosscheck cantilever``, ``curl`` and
``press`` print rows (``--json``: a list of them) with ``scenario``, ``model``, ``design``, ``metric``,
``value``, ``reference``, ``rel_diff``; ``crosscheck grasp`` is the grasp agreement study
(`mjcodesign.crosscheck.grasp`): one line per case as it finishes on stderr, then the summary
(``--json``: the whole report, cases and summary). The older form ``crosscheck --scenario NAME ...``
still runs (a deprecated alias: a note on stderr names the new form). The comparisons are
`mjcodesign.crosscheck`; the FEM's speed benchmark is `mjcodesign.bench.fem`. This module parses the
flags, calls them and prints.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from mjcodesign.cli.common import (
    choice_list,
    emit,
    finite_float,
    finite_floats,
    int_at_least,
    output_file,
)
from mjcodesign.cli.viz import add_recording_flags, open_recorder
from mjcodesign.crosscheck import (
    GRASP_CASES,
    GRASP_MODELS,
    MODELS,
    TOL_CROSS,
    crosscheck,
    grasp_study,
    parse_sweep,
    plot_curves,
    short_settings,
)
from mjcodesign.design.tendon_law import TENDON_VARIANTS

# `mjcodesign.models.types.TENDON_LEVERS` and `ROUTINGS`, repeated so that registering the command imports
# no MuJoCo (a test keeps them equal).
_TENDON_LEVERS = ("constant", "path")
_ROUTINGS = ("guided", "printed")

__all__ = ["add_parser", "add_bench_parser"]


def _fem_options(args):
    from mjcodesign.sim.fem import FemOptions

    return FemOptions(h=args.fem_h, spine_layers=args.fem_layers, order=args.fem_order)


def _note(line: str) -> None:
    print(line, file=sys.stderr)


def _cmd_grasp(args) -> int:
    import time
    from pathlib import Path

    from mjcodesign.cli.common import user_cache_dir
    from mjcodesign.errors import DesignError

    if args.tensions is not None and (args.authors_case or len(args.tensions) != 1):
        what = (
            "the authors' case keeps its mapped 4 N"
            if args.authors_case
            else "the grasp study takes one tension"
        )
        raise DesignError(f"--tensions: {what}, got {len(args.tensions)} value(s)")
    if args.authors_case and args.routing != _ROUTINGS[0]:
        raise DesignError(f"--routing {args.routing}: the authors' case runs their guided tendon only")
    if args.authors_case:
        from mjcodesign.crosscheck.authors_case import authors_case

        fem_mesh = _grasp_mesh(args)
        dyn = _fem_dynamics(args)
        _deprecation_note(args)
        if args.authors_poses is None:
            raise DesignError("--authors-case needs --authors-poses: the authors' 006_mustard_bottle.npz")
        rows = authors_case(
            args.models,
            pose_file=args.authors_poses,
            fem_options=fem_mesh,
            fem_dynamics=dyn,
            cache_dir=user_cache_dir(),
            start=args.authors_start,
        )
        if args.out:
            Path(args.out).write_text(json.dumps(_plain(rows)))
        emit(_plain(rows), True)
        return 0
    if args.short:
        settings = short_settings()
        settings["fem_options"] = dataclasses.replace(settings["fem_options"], routing=args.routing)
    else:
        settings = {"cases": GRASP_CASES, "fem_options": _grasp_mesh(args)}
        if (dyn := _fem_dynamics(args)) is not None:  # the FEM substep and contact of the study
            settings["fem_dynamics"] = dyn
    if args.cases is not None:
        settings["cases"] = select_cases(settings["cases"], args.cases)
    if args.tensions is not None:  # the study's scenario at another tension (the CI version's phases kept)
        from mjcodesign.scenarios.drive import TendonForce
        from mjcodesign.scenarios.grasp import GraspScenario

        base = settings.get("scenario") or GraspScenario()
        settings["scenario"] = dataclasses.replace(base, tendon=TendonForce(tension=args.tensions[0]))
    _deprecation_note(args)

    done: list[dict] = []

    def follow(rec: dict) -> None:
        models = [m for m in args.models if m in rec]
        parts = [f"{m} {'ok' if rec[m]['success'] else rec[m]['reason']}" for m in models] or [
            rec["bad_pose"]
        ]
        _note(f"{rec['case']}: " + " | ".join(parts))
        done.append(rec)
        if args.out:  # a long study keeps what it has finished
            Path(args.out).write_text(json.dumps({"partial": True, "cases": _plain(done)}))

    t0 = time.perf_counter()
    records, summary = grasp_study(
        models=args.models, routing=args.routing, cache_dir=user_cache_dir(), on_case=follow, **settings
    )
    report = {"wall_time_s": time.perf_counter() - t0, "summary": summary, "cases": _plain(records)}
    if args.out:
        Path(args.out).write_text(json.dumps(report))
    emit(report if args.json else summary, args.json)
    return 0


def _grasp_mesh(args):
    """The FEM grasp's mesh from the ``--fem-*`` mesh flags (linear tets, no waypoint layers)."""
    from mjcodesign.sim.fem import FemOptions

    return FemOptions(
        h=args.fem_h,
        h_flexure=args.fem_h_flexure,
        spine_layers=args.fem_layers,
        waypoint_layers=False,
        locking_correction=args.fem_locking_correction,
        tendon_law=args.fem_tendon_law,
        routing=args.routing,
    )


def _plain(obj):
    """JSON-ready copy (arrays to lists)."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return obj


def _chain_options(args):
    from mjcodesign.models.types import SimOptions

    return SimOptions(
        hinges_per_block=getattr(args, "hinges_per_block", 1),
        tendon_lever=getattr(args, "tendon_lever", "constant"),
    )


_MAX_SWEEP = 1000
"""Designs in one ``random:A..B`` sweep: each runs every model (seconds to minutes with the FEM), so a
thousand is already hours; a longer sweep is several runs."""


def _check_designs(text: str) -> None:
    """Parse ``--design`` (one design or a sweep) before any work: :class:`DesignError` if it is bad."""
    import re

    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError

    span = re.fullmatch(r"\s*random:(\d+)\.\.(\d+)\s*", text)
    if span is not None:
        count = int(span.group(2)) - int(span.group(1)) + 1
        if count > _MAX_SWEEP:
            raise DesignError(f"--design {text}: a sweep of {count} designs; at most {_MAX_SWEEP} per run")
        names = parse_sweep(text)
    else:
        names = [text]
    for name in names:
        Stiffness.parse(name)


def _cmd_crosscheck(args) -> int:
    """``crosscheck cantilever|curl|press``: the rows of one scenario."""
    _check_designs(args.design)
    plot = getattr(args, "plot", None)
    if plot and parse_sweep(args.design) is not None:
        from mjcodesign.errors import DesignError

        raise DesignError("--plot draws one design's curves; give --design a single design, not a sweep")
    fem_options, chain = _fem_options(args), _chain_options(args)
    rec = open_recorder(args)
    _deprecation_note(args)
    try:
        rows, curves = crosscheck(
            args.scenario,
            args.models,
            args.design,
            fem_options=fem_options,
            tensions=getattr(args, "tensions", None),
            observer=rec,
            on_note=_note,
            chain=chain,
        )
    finally:
        if rec is not None:
            rec.close()
    if plot:
        plot_curves(curves, plot)
    emit(rows, args.json)
    reference = "the FEM" if "fem" in args.models else "its reference (no FEM run)"
    for r in rows:
        if r["model"] != "fem" and r["rel_diff"] is not None and r["rel_diff"] > TOL_CROSS:
            _note(
                f"note: {r['model']} misses {reference} by {r['rel_diff']:.0%} (> {TOL_CROSS:.0%}) "
                f"on {r['metric']} ({r['design']})"
            )
    return 0


def _cmd_bench_fem(args) -> int:
    if args.fem_order != 1:
        from mjcodesign.errors import DesignError

        raise DesignError("bench fem times explicit dynamics, which needs --fem-order 1")
    from mjcodesign.bench.fem import bench_fem

    res = bench_fem(
        h=args.fem_h,
        spine_layers=args.fem_layers,
        dyn_steps=args.steps,
        grasp_horizon=args.grasp_horizon,
        gripper=None if args.gripper == "none" else args.gripper,
        gradient=not args.no_gradient,
        gripper_only=args.gripper_only,
        gripper_dt=args.gripper_dt,
    )
    if args.out:
        from pathlib import Path

        Path(args.out).write_text(json.dumps(res))
    if args.json:
        print(json.dumps(res))
    else:
        emit(res, False)
    return 0


def _fem_dynamics(args):
    """`FemDynamics` from the ``--fem-dt`` and ``--fem-contact-*`` flags (None: none given, the defaults)."""
    from mjcodesign.sim.fem import FemDynamics

    given = {
        "dt": args.fem_dt,
        "contact_ke": args.fem_contact_ke,
        "contact_damping_ratio": args.fem_contact_damping_ratio,
    }
    given = {k: v for k, v in given.items() if v is not None}
    return FemDynamics(**given) if given else None


def select_cases(cases: tuple, text: str) -> tuple:
    """``--cases``: ``N`` (the first N), ``A:B`` (a slice) or ``I,J,K`` (those indices, in that order)."""
    from mjcodesign.errors import DesignError

    first, _, last = text.rpartition(":")
    try:
        picked = [int(v) for v in text.split(",")] if "," in text else None
        span = None if picked else (int(first or 0), int(last))
    except ValueError:
        raise DesignError(f"--cases takes N, A:B or I,J,K (integers), got {text!r}") from None
    if picked is not None:
        if not all(0 <= i < len(cases) for i in picked):
            raise DesignError(f"--cases indices must be in 0..{len(cases) - 1}, got {text!r}")
        return tuple(cases[i] for i in picked)
    chosen = cases[span[0] : span[1]]
    if not chosen:
        raise DesignError(f"--cases {text!r} selects none of the {len(cases)} cases")
    return chosen


def _fem_flags(p, *, h: float, layers: int, order: int | None) -> None:
    """``--fem-h``, ``--fem-layers`` and, unless ``order`` is None (the grasp's linear tets), ``--fem-order``."""
    p.add_argument("--fem-h", type=float, default=h, help="FEM cell size in the segments [m]")
    p.add_argument("--fem-layers", type=int, default=layers, help="FEM layers through the 2 mm spine (even)")
    if order is not None:
        p.add_argument("--fem-order", type=int, choices=(1, 2), default=order, help="FEM tet order")


_SCENARIO_HELP = {
    "cantilever": "tip deflection under a tip load: every model against the FEM (or Euler-Bernoulli)",
    "curl": "bend and tip of the tendon curl at each tension: every model against the FEM",
    "press": "the finger pressed on a plate by its tendon: contact force spread against the FEM",
    "grasp": "the grasp agreement study (chain against the Warp FEM), or the authors' one case",
}


class _LegacyScenario(argparse.Action):
    """``--scenario NAME REST...``: the deprecated form, parsed by subcommand NAME's own parser.

    The scenario's flags follow ``--scenario``, as in every recorded command (a flag before it is not
    the ``crosscheck`` parser's, and is refused). The note that names the new form is printed once the
    command's input is checked (:func:`_deprecation_note`), so that a refused command writes one line.
    """

    def __init__(self, option_strings, dest, parsers=None, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=argparse.REMAINDER, **kwargs)
        self.parsers = parsers

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        if not values or values[0] not in self.parsers:
            got = repr(values[0]) if values else "nothing"
            parser.error(f"argument --scenario: choose from {', '.join(self.parsers)}, got {got}")
        sub = self.parsers[values[0]].parse_args(values[1:])
        for key, value in vars(sub).items():
            setattr(namespace, key, value)
        namespace.scenario = values[0]
        namespace.legacy_scenario = True


def _deprecation_note(args) -> None:
    """The one-line note of the deprecated ``crosscheck --scenario NAME`` form (nothing for the new form)."""
    if getattr(args, "legacy_scenario", False):
        _note(
            f"note: 'crosscheck --scenario {args.scenario}' is deprecated; run 'crosscheck {args.scenario}'"
        )


def _no_scenario(args) -> int:
    from mjcodesign.errors import DesignError

    raise DesignError(f"crosscheck needs a scenario: {', '.join(_SCENARIO_HELP)} (see crosscheck --help)")


def _models_flag(p, models: tuple, default: list[str]) -> None:
    p.add_argument(
        "--models",
        type=choice_list(models, "model"),
        default=default,
        help=f"comma-separated, from {', '.join(models)}; default {','.join(default)}",
    )


def _rows_flags(p, *, tensions: str | None) -> None:
    """The flags of every rows scenario (cantilever, curl, press): models, design, FEM mesh, recording."""
    _models_flag(p, MODELS, ["chain", "flex", "fem"])
    p.add_argument(
        "--design",
        default="paper-optimized",
        help="preset name, random:SEED, 11/22 comma-separated log E, or random:A..B (a sweep of seeds A to B, "
        "ending with per-model worst and median |rel_diff| rows)",
    )
    if tensions is not None:
        p.add_argument("--tensions", type=finite_floats(0.0, strict=True), default=None, help=tensions)
    # Quadratic tets, 2 spine layers: within 4% of Euler–Bernoulli on the cantilever (mjcodesign.sim.fem).
    _fem_flags(p, h=4e-3, layers=2, order=2)
    add_recording_flags(p, decimation=False)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_crosscheck)


def _hinges_flag(p) -> None:
    p.add_argument(
        "--hinges-per-block",
        type=int,
        choices=(1, 2),
        default=1,
        help="chain hinges per block (2: at its quarter points, without stops; an experiment option, "
        "docs/validation/experiment-options.md)",
    )


def _grasp_flags(p) -> None:
    _models_flag(p, GRASP_MODELS, list(GRASP_MODELS))
    p.add_argument(
        "--tensions",
        type=finite_floats(0.0, strict=True),
        default=None,
        help="the study's one tendon tension [N] (default 4)",
    )
    p.add_argument(
        "--cases",
        default=None,
        help="run the study's cases N (the first N), A:B (a slice of them) or I,J,K (those indices)",
    )
    p.add_argument(
        "--short", action="store_true", help="the CI version (two cases, short horizon, coarse mesh)"
    )
    p.add_argument("--out", type=output_file, default=None, help="also write the JSON report to this file")
    _fem_flags(p, h=4e-3, layers=2, order=None)  # linear tets (mjcodesign.sim.fem.gripper)
    p.add_argument("--fem-h-flexure", type=float, default=None, help="FEM cell size in flexures and cuts [m]")
    p.add_argument("--fem-dt", type=float, default=None, help="FEM substep [s] (default the paper's 2.5e-6)")
    p.add_argument(
        "--fem-contact-ke",
        type=finite_float(0.0, strict=True),
        default=None,
        help="FEM penalty contact stiffness [Pa/m] (default the paper's 1e3 N/m per cm², 1e7)",
    )
    p.add_argument(
        "--fem-contact-damping-ratio",
        type=finite_float(0.0, strict=True),
        default=None,
        help="damp every FEM finger contact at this ratio of critical instead of the paper's kd",
    )
    p.add_argument(
        "--fem-locking-correction",
        action="store_true",
        help="lower the linear tets' block moduli to the converged FEM's block compliances "
        "(the coarse mesh's flexures are 5x too stiff)",
    )
    p.add_argument(
        "--fem-tendon-law",
        choices=TENDON_VARIANTS,
        default="frictionless",
        help="the FEM tendon's force, a frictionless tendon's (it compresses the finger) or the "
        "authors' law (across each section, a push at the tip)",
    )
    p.add_argument(
        "--routing",
        choices=_ROUTINGS,
        default=_ROUTINGS[0],
        help="the tendon's path on both sides: guided (default; one waypoint per block) or printed (through "
        "the printed finger's channels, straight across each flexure gap: the chain's and the FEM's "
        "routing='printed'); recorded in every case",
    )
    p.add_argument(
        "--authors-case",
        action="store_true",
        help="the authors' simulator's one case instead (mustard bottle at their pose 0, ln E 13.5/15/16.5)",
    )
    p.add_argument(
        "--authors-poses",
        type=Path,
        default=None,
        metavar="NPZ",
        help="--authors-case: the authors' AnyGrasp poses of the mustard bottle (006_mustard_bottle.npz)",
    )
    p.add_argument(
        "--authors-start",
        choices=("refined", "sweep"),
        default="refined",
        help="--authors-case: fingers start at the refined openings (theirs) or outside the object (ours)",
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_grasp)


def add_parser(subparsers) -> None:
    """Register ``crosscheck`` and its scenarios on the top-level sub-parsers."""
    p = subparsers.add_parser(
        "crosscheck",
        help="run one case in every backend (MuJoCo models, Warp FEM)",
        description="Run one scenario in every backend. Each scenario is a subcommand with its own flags; "
        "the older form 'crosscheck --scenario NAME ...' still runs, with a note on stderr.",
    )
    sub = p.add_subparsers(dest="scenario", metavar="SCENARIO")
    parsers = {
        name: sub.add_parser(name, help=text, description=text) for name, text in _SCENARIO_HELP.items()
    }
    _rows_flags(parsers["cantilever"], tensions=None)
    _hinges_flag(parsers["cantilever"])
    _rows_flags(
        parsers["curl"],
        tensions="curl tensions [N], comma-separated (default: three, scaled to the design's compliance)",
    )
    _hinges_flag(parsers["curl"])
    parsers["curl"].add_argument(
        "--tendon-lever",
        choices=_TENDON_LEVERS,
        default="constant",
        help="the chain tendon's lever on each hinge, held at the straight finger's (constant, the "
        "default) or following the waypoints (path: an experiment option, docs/validation/experiment-options.md)",
    )
    parsers["curl"].add_argument(
        "--plot", default=None, help="write tip paths and bend against tension to this PNG"
    )
    _rows_flags(
        parsers["press"],
        tensions="the press's tendon tension [N]: the first value (default: scaled to the design's compliance)",
    )
    _grasp_flags(parsers["grasp"])
    p.add_argument("--scenario", action=_LegacyScenario, parsers=parsers, help=argparse.SUPPRESS)
    p.set_defaults(func=_no_scenario)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench fem`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "fem", help="Warp FEM steps/s on the CPU and static solve + gradient time"
    )
    _fem_flags(p, h=3e-3, layers=4, order=1)
    p.add_argument("--steps", type=int_at_least(1), default=2000, help="explicit substeps to time")
    p.add_argument(
        "--grasp-horizon",
        type=finite_float(0.0, strict=True),
        default=0.2,
        help="dynamic grasp to time [s]",
    )
    p.add_argument(
        "--gripper",
        choices=("none", "coarse", "default", "fine", "corrected"),
        default="coarse",
        help="mesh of the whole two-finger grasp to time (mjcodesign.bench.fem.GRIPPER_MESHES), or none",
    )
    p.add_argument("--no-gradient", action="store_true", help="time the two-finger grasp forward only")
    p.add_argument("--gripper-only", action="store_true", help="time only the two-finger grasp")
    p.add_argument(
        "--gripper-dt",
        type=finite_float(0.0, strict=True),
        default=None,
        help="two-finger grasp substep [s] (default 2.5e-6)",
    )
    p.add_argument("--out", type=output_file, default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_fem)
