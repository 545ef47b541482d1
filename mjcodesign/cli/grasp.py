"""``mjcodesign grasp`` and ``mjcodesign bench grasp``: parsing and printing around :mod:`mjcodesign.jobs`.

``--design`` takes one design (a preset, or 11/22 comma-separated ln E) or several presets separated by
commas (``soft,semi-rigid,paper-optimized``): each is run on the same object and pose, ``--json`` then
prints a list of outcome objects, each with its ``design``, and ``--rrd``/``--spawn`` record them side by
side.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

from mjcodesign.cli.common import (
    FRICTION_HELP,
    add_regime,
    int_at_least,
    path_text,
    scenario_physics,
    user_cache_dir,
)
from mjcodesign.cli.finger_flags import add_routing, grasp_model_name, routing_options
from mjcodesign.optional import WARP_DEVICES

__all__ = [
    "add_parser",
    "add_bench_parser",
    "run",
    "prepare_object",
    "run_bench",
    "grasp",
    "split_designs",
    "object_sources",
    "check_pose_file",
]

_MODELS = ("chain", "flex", "fem")
"""``fem``: the Warp FEM grasp (its own simulator; it reads the object, pose and design from a chain scene)."""
_BACKENDS = ("mujoco", "mjwarp")


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--object",
        required=True,
        type=path_text,
        help="YCB name (e.g. 025_mug), egad-like:N or an OBJ/STL/PLY file; or several: a named set "
        "(ycb-in-domain, ycb-ood, egad-like) or a folder of OBJ/STL/PLY files, printed as a JSON list",
    )
    p.add_argument(
        "--design",
        default="paper-optimized",
        help="stiffness preset, 11/22 comma-separated ln(E/Pa), or several comma-separated presets",
    )
    p.add_argument("--model", choices=_MODELS, default="chain", type=grasp_model_name)
    add_routing(p)
    add_regime(p)
    p.add_argument(
        "--density",
        default=None,
        help="object density [kg/m³] or a preset: light (100), heavy (400) (the paper's relative scale, "
        "not real objects), ycb-median (680); default: the regime's (real: the published mass, else "
        "ycb-median; paper: light)",
    )
    p.add_argument(
        "--mass",
        default=None,
        help="real: a YCB object at its published mass (the YCB object list; refused for objects without "
        "one); or a mass [kg] (for egad-like and mesh files too). The density becomes mass / volume, "
        "uniform, and the inertia is the uniformly filled mesh's; auto: real where the object has a published "
        "mass, else --density. Default: the regime's (real: auto; paper: from --density; --density given: "
        "from it)",
    )
    p.add_argument(
        "--pose",
        default="auto",
        type=path_text,
        help="auto (top-down), best (top-ranked of `mjcodesign poses`), an .npz from `poses --out` (its "
        "first row, the best; FILE.npz:ROW for row ROW from 0) or a JSON file "
        '{"pose": 4x4 palm pose [m], "openings": [s1, s2] [m]}; the '
        "object's COM is at world x = y = 0 with the object resting on the ground (z = 0)",
    )
    p.add_argument(
        "--impulse",
        type=float,
        default=None,
        help="downward disturbance impulse [N s] whatever the mass, in place of the regime's disturbance "
        "(real: --delta-v paper; paper: 0.0179, the paper's 0.1 N s on its 5x larger scene mapped to real "
        "size; its 0.2 and 0.4 map to 0.036 and 0.072)",
    )
    p.add_argument(
        "--delta-v",
        default=None,
        help="the disturbance as a downward velocity change of the object [m/s] (impulse m dv, whatever "
        "the mass), instead of --impulse; 'paper': the paper's 0.1 N s relative to a hand-sized object, "
        "0.51 m/s",
    )
    p.add_argument(
        "--friction",
        default=None,
        help=FRICTION_HELP,
    )
    p.add_argument("--tension", type=float, default=None, help="tendon tension per finger [N]")
    # --tendon: the tendon drive, parsed by mjcodesign.scenarios.parse_tendon.
    p.add_argument(
        "--tendon",
        default=None,
        help="force:N (tension per finger [N], the paper's simulator) or position:TICKS (the XL330 "
        "servo's goal [ticks of 4096], the hardware; the paper pulls 1000); default: the regime's "
        "(real: position:1000; paper: force:10)",
    )
    p.add_argument(
        "--lift",
        type=float,
        default=None,
        help="lift distance [m] (default: the regime's, real 0.10, paper 0.03)",
    )
    p.add_argument(
        "--backend",
        default="mujoco",
        help="mujoco or mjwarp; several comma-separated (mujoco,mjwarp) run side by side",
    )
    p.add_argument(
        "--device",
        choices=WARP_DEVICES,
        default="auto",
        help="mjwarp and --model fem: Warp device (auto: CUDA when present, else the CPU)",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seeds CoACD and egad-like shapes; MuJoCo is deterministic"
    )
    p.add_argument(
        "--allow-open", action="store_true", help="use the convex hull of a mesh that cannot be repaired"
    )
    p.add_argument("--json", action="store_true")
    from mjcodesign.cli.viz import add_recording_flags

    add_recording_flags(p)


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``grasp`` on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "grasp",
        help="simulate the fixed grasp motion (close, tighten, lift, hold, impulse, hold) on one object",
    )
    _arguments(p)
    p.set_defaults(func=run)
    return p


def add_bench_parser(bench_subparsers) -> argparse.ArgumentParser:
    """Register ``grasp`` on the ``bench`` command's subparsers object."""
    p = bench_subparsers.add_parser(
        "grasp", help="grasp rollouts/s: raw mujoco.rollout and the full pipeline"
    )
    p.add_argument("--model", choices=_MODELS[:2], default="chain", type=grasp_model_name)
    p.add_argument(
        "--object",
        type=path_text,
        default="010_potted_meat_can",
        help="object (convex-decomposed, cached)",
    )
    p.add_argument(
        "--rollouts",
        type=int_at_least(1),
        default=None,
        help="rollouts per measurement (default 32 chain, 2 flex)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_bench)
    return p


def grasp(
    source: str,
    design: str = "paper-optimized",
    model: str = "chain",
    density: str | None = None,
    pose: str = "auto",
    *,
    regime: str = "real",
    mass: str | float | None = None,
    impulse: float | None = None,
    delta_v: str | float | None = None,
    friction: str | float | None = None,
    tension: float | None = None,
    tendon: str | None = None,
    lift: float | None = None,
    backend: str = "mujoco",
    device: str = "auto",
    seed: int = 0,
    allow_open: bool = False,
    cache_dir: Path | None = None,
    observer=None,
    label: str | None = None,
    prepared: tuple | None = None,
    options=None,
) -> dict:
    """One grasp rollout (a :class:`~mjcodesign.jobs.GraspJob`); the JSON-ready outcome plus the object's facts.

    ``regime`` (:data:`~mjcodesign.scenarios.REGIMES`) gives the scenario and, where ``density`` and
    ``mass`` are None, the mass rule; the other arguments replace the settings they name. ``mass``:
    ``"density"`` (from ``density``), ``"real"`` (a YCB object's published mass), ``"auto"`` (real where
    published, else the density) or a mass [kg] (:func:`mjcodesign.jobs.load_grasp_object`). ``observer`` (:mod:`mjcodesign.sim.observe`) receives
    the rollout as ``label``. ``prepared``: the result of :func:`prepare_object` for these ``source``,
    ``density``, ``pose`` and ``mass`` arguments, so that several designs or backends on one object
    load, decompose and pose it once. ``options``: the chain's :class:`~mjcodesign.models.types.SimOptions`
    (None: the defaults).
    """
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError
    from mjcodesign.jobs import GraspJob, run_jobs
    from mjcodesign.models.types import FingerModel
    from mjcodesign.scenarios import get_regime, regime_name
    from mjcodesign.sim.protocol import get_backend

    stiffness = Stiffness.parse(design)
    if backend not in _BACKENDS:
        raise DesignError(f"unknown backend {backend!r}: choose from {', '.join(_BACKENDS)}")
    if model == "fem":
        if options is not None:
            raise DesignError("--model fem routes its tendon itself: leave --routing at guided")
        if backend != "mujoco":
            raise DesignError("--model fem is a simulator of its own: leave --backend at mujoco")
        from mjcodesign.sim.fem import GRASP_OPTIONS

        # --device: the FEM's Warp device too (auto: CUDA when present, else the CPU)
        fem_options = replace(GRASP_OPTIONS, device=_warp_device(device, FingerModel.CHAIN))
        sim, model = get_backend("fem", grasp_options=fem_options), "chain"
    elif backend == "mjwarp":
        sim = get_backend(backend, device=_warp_device(device, FingerModel(model)))
    else:
        sim = get_backend(backend)
    the_regime = get_regime(regime)
    density, mass = the_regime.masses(density, mass)
    if prepared is None:
        prepared = prepare_object(
            source, density, pose, mass=mass, seed=seed, allow_open=allow_open, cache_dir=cache_dir
        )
    obj, rho, gripper_pose = prepared
    kwargs = {k: v for k, v in (("lift", lift), ("impulse", impulse)) if v is not None}
    if impulse is not None:
        kwargs["delta_v"] = None  # an impulse [N s] replaces the regime's velocity change
    kwargs.update(scenario_physics(delta_v, friction))
    if tendon is not None:  # --tendon
        from mjcodesign.scenarios import parse_tendon

        if tension is not None:
            raise DesignError("give --tension or --tendon, not both")
        kwargs["tendon"] = parse_tendon(tendon)
    elif tension is not None:  # --tension
        from mjcodesign.scenarios import TendonForce

        kwargs["tendon"] = TendonForce(tension=tension)
    scenario = replace(the_regime.scenario, **kwargs)
    job = GraspJob(
        obj=obj,
        pose=gripper_pose,
        design=stiffness,
        finger_model=FingerModel(model),
        scenario=scenario,
        seed=seed,
        label=label or design,
        options=options,
    )
    out = run_jobs([job], sim, observer, strict=True)[0].as_dict()
    out.update(
        object=obj.name,
        mass_kg=obj.mass,
        density_kg_m3=rho,
        regime=regime_name(scenario, "density" if mass is None else str(mass)),
        **_mass_facts(source, mass),
        impulse_ns=scenario.impulse_on(obj.mass),
        delta_v_m_s=scenario.delta_v,
        friction=scenario.friction,
        repaired=obj.repaired,
        fallback=obj.fallback,
        hulls=len(obj.hulls),
        openings=list(gripper_pose.openings),
        palm_position=list(gripper_pose.position),
    )
    return out


_MJWARP_FLEX_NOTE = (
    "note: MJWarp 4.0's flex does not track MuJoCo C's (flex nodes 0.70 mm apart after 13 steps on the "
    "CPU; tests/test_mjwarp_parity.py): compare its flex outcomes with --backend mujoco"
)


def _warp_device(device: str, model) -> str:
    """The Warp device for ``--device`` (auto: CUDA when present); flex needs CUDA.

    Raises :class:`UnsupportedError` for flex on the CPU: one grasp step of the flex fingers took 3.3 s
    on Warp's CPU device (a rollout ~20 min), so the command refuses rather than seem to hang.
    """
    from mjcodesign.errors import DesignError, UnsupportedError
    from mjcodesign.optional import warp_device

    try:
        chosen = warp_device(device)
    except ImportError as exc:
        raise DesignError("the mjwarp backend needs mujoco-warp and warp-lang") from exc
    if model.is_flex:
        if chosen == "cpu":
            raise UnsupportedError(
                "mjwarp flex on Warp's CPU device takes ~20 min a rollout (3.3 s a step): "
                "use --backend mujoco, or a CUDA device"
            )
        print(_MJWARP_FLEX_NOTE, file=sys.stderr)
    return chosen


def prepare_object(
    source: str,
    density: str = "light",
    pose: str = "auto",
    *,
    mass: str | float | None = None,
    seed: int = 0,
    allow_open: bool = False,
    cache_dir: Path | None = None,
) -> tuple:
    """(object with its convex decomposition, density [kg/m³], gripper pose) for :func:`grasp`.

    ``mass``: see :func:`mjcodesign.jobs.load_grasp_object` (the density is then mass / volume).
    """
    from mjcodesign.jobs import load_grasp_object, resolve_pose

    check_pose_file(pose)
    obj = load_grasp_object(source, density, mass=mass, seed=seed, allow_open=allow_open, cache_dir=cache_dir)
    return obj, obj.density, resolve_pose(pose, obj, seed=seed)


def _mass_facts(source: str, mass: str | float | None) -> dict:
    """How the object's mass was set: ``mass_mode`` (density, real, given) and the published source.

    The ``auto`` rule reports what it chose for this object: ``real`` with the source, or ``density``.
    """
    from mjcodesign.objects import mass_by_rule, parse_mass

    mode = parse_mass(mass)
    if mode is None or mode in ("real", "auto"):
        found = None if mode is None else mass_by_rule(str(source), mode)
        if found is None:
            return {"mass_mode": "density", "mass_source": None}
        return {"mass_mode": "real", "mass_source": found.source}
    return {"mass_mode": "given", "mass_source": None}


def check_pose_file(pose: str) -> None:
    """Raise :class:`PoseError` if ``pose`` is a JSON pose file whose 4x4 ``pose`` has no rotation block.

    :func:`mjcodesign.jobs.resolve_pose` turns the block into a quaternion with ``mju_mat2Quat``, which
    normalises whatever it is given, so a zero or scaled block would run as some other pose. Everything
    else about the file (missing, unreadable, wrong keys or shapes) is left to ``resolve_pose``.
    """
    import numpy as np

    from mjcodesign.errors import PoseError
    from mjcodesign.jobs import POSE_RULES
    from mjcodesign.models.types import GripperPose

    path = Path(pose)
    if pose in POSE_RULES or path.suffix == ".npz" or not path.is_file():
        return
    try:
        matrix = np.asarray(json.loads(path.read_text(encoding="utf-8"))["pose"], dtype=float)
    except (OSError, ValueError, KeyError, TypeError):
        return
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        return
    try:
        GripperPose.from_matrix(matrix)
    except PoseError as exc:
        raise PoseError(f"{path}: {exc}") from None


def split_designs(text: str) -> list[str]:
    """Several comma-separated presets, or one design (a preset or comma-separated ln E values)."""
    from mjcodesign.design.stiffness import PRESETS

    parts = [p.strip() for p in text.split(",")]
    return parts if len(parts) > 1 and all(p in PRESETS for p in parts) else [text]


def object_sources(text: str) -> list[str] | None:
    """The objects of a named set or a folder (sorted mesh files), or None for a single object.

    Raises :class:`MeshError` for a folder without OBJ/STL/PLY files.
    """
    from mjcodesign.errors import MeshError
    from mjcodesign.objects import MESH_SUFFIXES, OBJECT_SETS, named_set

    if text in OBJECT_SETS:
        return list(named_set(text))
    folder = Path(text)
    if not folder.is_dir():
        return None
    files = sorted(str(p) for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise MeshError(f"{folder}: no {', '.join(MESH_SUFFIXES)} files")
    return files


def _source_name(source: str) -> str:
    """An object's name in a multi-object run, as the library names it (:func:`~mjcodesign.objects.object_name`).

    A file's stem, or its whole name when another mesh in its folder has the same stem (``empty.obj``
    and ``empty.stl`` are two objects); a set's entry as it is (a YCB name, ``egad-like:N``).
    """
    from mjcodesign.objects import object_name

    return object_name(source)


def _failed_object(source: str, exc: Exception) -> dict:
    """The record of an object that could not be simulated in a multi-object run (never NaN)."""
    return {
        "object": _source_name(source),
        "success": False,
        "body_force": [0.0] * 6,
        "displacement": [0.0] * 3,
        "ground_contact": False,
        "reason": f"error: {exc}",
        "wall_time_s": 0.0,
    }


def _variants(args: argparse.Namespace) -> list[tuple[str, str, str, dict]]:
    """(design, backend, label, keys) of every design on every backend; keys tell runs apart in JSON."""
    from mjcodesign.errors import DesignError, StiffnessError

    designs = split_designs(args.design)
    if len(set(designs)) != len(designs):
        raise StiffnessError(f"--design lists a preset twice: {args.design}")
    backends = [b.strip() for b in args.backend.split(",")]
    for b in backends:
        if b not in _BACKENDS:
            raise DesignError(f"unknown backend {b!r}: choose from {', '.join(_BACKENDS)}")
    if len(set(backends)) != len(backends):
        raise DesignError(f"--backend lists a backend twice: {args.backend}")
    variants = []
    for design in designs:
        for backend in backends:
            keys = {"design": design} if len(designs) > 1 else {}
            keys.update({"backend": backend} if len(backends) > 1 else {})
            label = "/".join([design] + ([backend] if len(backends) > 1 else []))
            variants.append((design, backend, label, keys))
    return variants


class _Runner:
    """One ``grasp`` invocation: its arguments, recorder and cache, for every object and variant."""

    def __init__(self, args: argparse.Namespace, recorder):
        self.args = args
        self.recorder = recorder
        self.cache = user_cache_dir()

    def prepare(self, source: str) -> tuple:
        from mjcodesign.scenarios import get_regime

        a = self.args
        density, mass = get_regime(a.regime).masses(a.density, a.mass)
        return prepare_object(
            source, density, a.pose, mass=mass, seed=a.seed, allow_open=a.allow_open, cache_dir=self.cache
        )

    def one(self, source: str, variant: tuple, prepared: tuple, prefix: str = "") -> dict:
        design, backend, label, keys = variant
        a = self.args
        out = grasp(
            source,
            design,
            a.model,
            a.density,
            a.pose,
            regime=a.regime,
            mass=a.mass,
            impulse=a.impulse,
            delta_v=a.delta_v,
            friction=a.friction,
            tension=a.tension,
            tendon=a.tendon,
            lift=a.lift,
            backend=backend,
            device=a.device,
            seed=a.seed,
            allow_open=a.allow_open,
            cache_dir=self.cache,
            observer=self.recorder,
            label=prefix + label,
            prepared=prepared,
            options=routing_options(a),
        )
        return {**keys, **out}

    def many(self, sources: list[str], variants: list[tuple], results: list[dict]) -> None:
        """Every object of a set or folder; an object that fails is a failed record, never a stop."""
        from rich.console import Console
        from rich.progress import Progress

        from mjcodesign.errors import MjcodesignError

        with Progress(console=Console(stderr=True), transient=True) as bar:
            task = bar.add_task(f"grasp {self.args.object}", total=len(sources) * len(variants))
            for source in sources:
                name = _source_name(source)
                bar.update(task, description=f"grasp {name} (loading)")
                try:
                    prepared = self.prepare(source)
                except MjcodesignError as exc:  # every variant fails alike on an object that does not load
                    results += [{**v[3], **_failed_object(source, exc)} for v in variants]
                    bar.advance(task, len(variants))
                    continue
                for variant in variants:
                    bar.update(task, description=f"grasp {name} ({variant[2]})")
                    try:
                        out = self.one(source, variant, prepared, f"{name}/")
                    except MjcodesignError as exc:
                        out = {**variant[3], **_failed_object(source, exc)}
                    results.append(out)
                    bar.advance(task)


def run(args: argparse.Namespace) -> int:
    """Run ``grasp``; library errors propagate to the caller (exit 2 there).

    Several designs run on the same object side by side. A named set or a folder runs every object
    (for every design) and prints a JSON list (one object per line); an object that fails to load,
    decompose or pose is a failed entry with ``reason`` "error: ...". Interrupted (SIGINT) during a
    set or folder, it prints the entries finished so far, then lets the interruption through.

    A refused run leaves no recording behind (``--rrd``): the recorder is closed without writing.
    """
    from mjcodesign.cli.viz import open_recorder

    variants = _variants(args)
    sources = object_sources(args.object)
    check_pose_file(args.pose)
    recorder = open_recorder(args)
    runner = _Runner(args, recorder)
    results: list[dict] = []
    keep = False  # whether the recording holds what this run is reporting
    try:
        if sources is None:
            prepared = runner.prepare(args.object)
            outs = [runner.one(args.object, v, prepared) for v in variants]
            keep = True
            _print_runs(outs, args.json, listed=len(outs) > 1)
            return 0
        try:
            runner.many(sources, variants, results)
        except KeyboardInterrupt:
            keep = True  # the recording holds the entries printed below
            _print_many(results, args.json)
            raise
        keep = True
    finally:
        if recorder is not None:
            recorder.close(discard=not keep)
    _print_many(results, args.json)
    return 0


def _print_many(results: list[dict], as_json: bool) -> None:
    """The entries of a set or folder: a JSON list, one entry per line (``[]`` when none finished)."""
    if as_json:
        print("[\n" + ",\n".join(json.dumps(r) for r in results) + "\n]" if results else "[]", flush=True)
    else:
        _print_runs(results, False, listed=True)


def _print_runs(outs: list[dict], as_json: bool, *, listed: bool) -> None:
    """One record as a JSON object (or key/value lines), several as a JSON list (or blocks)."""
    if not listed:
        _print(outs[0], as_json)
    elif as_json:
        print(json.dumps(outs))
    else:
        for out in outs:
            _print(out, False)
            print()


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench grasp``."""
    from mjcodesign.bench import run_benchmark

    res = run_benchmark(
        "grasp",
        command=args.command_line,
        model=args.model,
        source=args.object,
        rollouts=args.rollouts,
        seed=args.seed,
        cache_dir=user_cache_dir(),
    )
    _print(res, args.json)
    return 0


def _print(result: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(result))
        return
    width = max(len(k) for k in result)
    for k, v in result.items():
        print(f"{k:{width}s} {v}")
