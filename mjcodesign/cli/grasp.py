"""``mjcodesign grasp`` and ``mjcodesign bench grasp``.

Wire them into the main CLI with ``cli_grasp.add_parser(subparsers)`` and
``cli_grasp.add_bench_parser(bench_subparsers)``. ``python -m mjcodesign.cli_grasp ARGS`` runs
``grasp`` on its own with the same error mapping (exit 2 and one line).

``--design`` takes one design (a preset, or 11/22 comma-separated ln E) or several presets separated by
commas (``soft,semi-rigid,paper-optimized``): each is run on the same object and pose, ``--json`` then
prints a list of outcome objects, each with its ``design``, and ``--rrd``/``--spawn`` record them side by
side.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

__all__ = [
    "add_parser",
    "add_bench_parser",
    "run",
    "prepare_object",
    "run_bench",
    "grasp",
    "split_designs",
    "object_sources",
    "user_cache_dir",
]

_MODELS = ("chain", "flex")
_BACKENDS = ("mujoco", "mjwarp")


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/mjcodesign`` or ``~/.cache/mjcodesign`` (flags and environment live here)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mjcodesign"


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--object",
        required=True,
        help="YCB name (e.g. 025_mug), egad-like:N or an OBJ/STL/PLY file; or several: a named set "
        "(ycb-in-domain, ycb-ood, egad-like) or a folder of OBJ/STL/PLY files, printed as a JSON list",
    )
    p.add_argument(
        "--design",
        default="paper-optimized",
        help="stiffness preset, 11/22 comma-separated ln(E/Pa), or several comma-separated presets",
    )
    p.add_argument("--model", choices=_MODELS, default="chain")
    p.add_argument(
        "--density", default="light", help="object density [kg/m³] or a preset: light (100), heavy (400)"
    )
    p.add_argument(
        "--pose",
        default="auto",
        help="auto (top-down), best (top-ranked of `mjcodesign poses`), an .npz from `poses --out` (its "
        'first row) or a JSON file {"pose": 4x4 palm pose [m], "openings": [s1, s2] [m]}; the '
        "object's COM is at world x = y = 0 with the object resting on the ground (z = 0)",
    )
    p.add_argument(
        "--impulse",
        type=float,
        default=None,
        help="downward disturbance impulse [N s]; default 0.0179, the paper's 0.1 N s (applied to a 5x "
        "larger scene) mapped to real size (its 0.2 and 0.4 map to 0.036 and 0.072)",
    )
    p.add_argument("--tension", type=float, default=None, help="tendon tension per finger [N]")
    p.add_argument("--lift", type=float, default=None, help="lift distance [m]")
    p.add_argument(
        "--backend",
        default="mujoco",
        help="mujoco or mjwarp; several comma-separated (mujoco,mjwarp) run side by side",
    )
    p.add_argument(
        "--device",
        choices=("auto", "cpu", "cuda"),
        default="auto",
        help="mjwarp: Warp device (auto: CUDA when present, else the CPU)",
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
    p.add_argument("--model", choices=_MODELS, default="chain")
    p.add_argument("--object", default="010_potted_meat_can", help="object (convex-decomposed, cached)")
    p.add_argument(
        "--rollouts", type=int, default=None, help="rollouts per measurement (default 32 chain, 2 flex)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_bench)
    return p


def _read_pose(text: str, obj, design, seed: int = 0):
    from mjcodesign.errors import PoseError
    from mjcodesign.models.types import GripperPose
    from mjcodesign.scenarios.grasp import auto_pose

    if text == "auto":
        return auto_pose(obj, design)
    if text == "best":
        from mjcodesign.poses.sampler import sample_poses, to_gripper_pose

        return to_gripper_pose(sample_poses(obj, 10, seed=seed, design=design))
    path = Path(text)
    if not path.is_file():
        raise PoseError(f"pose file not found: {path}")
    if path.suffix == ".npz":
        from mjcodesign.poses.sampler import read_candidates, to_gripper_pose

        return to_gripper_pose(read_candidates(path))
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        return GripperPose.from_matrix(raw["pose"], tuple(raw["openings"]))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise PoseError(f"{path}: not a pose file ({type(exc).__name__}: {exc})") from exc


def grasp(
    source: str,
    design: str = "paper-optimized",
    model: str = "chain",
    density: str = "light",
    pose: str = "auto",
    *,
    impulse: float | None = None,
    tension: float | None = None,
    lift: float | None = None,
    backend: str = "mujoco",
    device: str = "auto",
    seed: int = 0,
    allow_open: bool = False,
    cache_dir: Path | None = None,
    observer=None,
    label: str | None = None,
    prepared: tuple | None = None,
) -> dict:
    """One grasp rollout; returns the JSON-ready outcome plus the object's facts.

    ``observer`` (:mod:`mjcodesign.observe`) receives the rollout as ``label``. ``prepared``: the
    result of :func:`prepare_object` for these ``source``, ``density`` and ``pose`` arguments, so that
    several designs or backends on one object load, decompose and pose it once.
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError
    from mjcodesign.models.types import FingerModel
    from mjcodesign.scenarios.grasp import GraspScenario, build_scene
    from mjcodesign.sim.protocol import get_backend

    stiffness = Stiffness.parse(design)
    if backend not in _BACKENDS:
        raise DesignError(f"unknown backend {backend!r}: choose from {', '.join(_BACKENDS)}")
    if backend == "mjwarp":
        sim = get_backend(backend, device=_warp_device(device, FingerModel(model)))
    else:
        sim = get_backend(backend)
    if prepared is None:
        prepared = prepare_object(
            source, density, pose, seed=seed, allow_open=allow_open, cache_dir=cache_dir
        )
    obj, rho, gripper_pose = prepared
    finger_design = FingerDesign()
    kwargs = {k: v for k, v in (("tension", tension), ("lift", lift), ("impulse", impulse)) if v is not None}
    scenario = GraspScenario(**kwargs)
    scene = build_scene(obj, finger_design, stiffness, FingerModel(model), gripper_pose)
    recording = {} if observer is None else {"observer": observer, "label": label or design}
    out = sim.run(scene, scenario, **recording).as_dict()
    out.update(
        object=obj.name,
        mass_kg=obj.mass,
        density_kg_m3=rho,
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
    from mjcodesign.optional import import_warp

    try:
        wp = import_warp()
    except ImportError as exc:
        raise DesignError("the mjwarp backend needs mujoco-warp and warp-lang") from exc
    has_cuda = wp.get_cuda_device_count() > 0
    if device == "cuda" and not has_cuda:
        raise UnsupportedError("--device cuda: Warp finds no CUDA device here")
    chosen = "cuda" if device == "cuda" or (device == "auto" and has_cuda) else "cpu"
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
    seed: int = 0,
    allow_open: bool = False,
    cache_dir: Path | None = None,
) -> tuple:
    """(object with its convex decomposition, density [kg/m³], gripper pose) for :func:`grasp`."""
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.errors import MeshError
    from mjcodesign.objects.mesh import CoacdSettings, convex_decomposition, load_object, parse_density

    rho = parse_density(density)
    if Path(source).is_dir():
        raise MeshError(f"{source} is a folder: grasp() takes one object (see object_sources)")
    obj = load_object(source, rho, allow_open=allow_open, seed=seed)
    convex_decomposition(obj, CoacdSettings(seed=seed), cache_dir=cache_dir)
    return obj, rho, _read_pose(pose, obj, FingerDesign(), seed)


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
    from mjcodesign.objects.mesh import MESH_SUFFIXES, OBJECT_SETS, named_set

    if text in OBJECT_SETS:
        return list(named_set(text))
    folder = Path(text)
    if not folder.is_dir():
        return None
    files = sorted(str(p) for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise MeshError(f"{folder}: no {', '.join(MESH_SUFFIXES)} files")
    return files


def _failed_object(source: str, exc: Exception) -> dict:
    """The record of an object that could not be simulated in a multi-object run (never NaN)."""
    return {
        "object": Path(source).stem if Path(source).suffix else source,
        "success": False,
        "body_force": [0.0] * 6,
        "displacement": [0.0] * 3,
        "ground_contact": False,
        "reason": f"error: {exc}",
        "wall_time_s": 0.0,
    }


def run(args: argparse.Namespace) -> int:
    """Run ``grasp``; library errors propagate to the caller (exit 2 there).

    Several designs run on the same object side by side. A named set or a folder runs every object
    (for every design) and prints a JSON list (one object per line); an object that fails to load,
    decompose or pose is a failed entry with ``reason`` "error: ...".
    """
    from mjcodesign.cli.viz import open_recorder
    from mjcodesign.errors import DesignError, MjcodesignError, StiffnessError

    designs = split_designs(args.design)
    if len(set(designs)) != len(designs):
        raise StiffnessError(f"--design lists a preset twice: {args.design}")
    backends = [b.strip() for b in args.backend.split(",")]
    for b in backends:
        if b not in _BACKENDS:
            raise DesignError(f"unknown backend {b!r}: choose from {', '.join(_BACKENDS)}")
    if len(set(backends)) != len(backends):
        raise DesignError(f"--backend lists a backend twice: {args.backend}")
    # Every design on every backend; the keys that tell the runs apart are added to their records.
    variants = []
    for design in designs:
        for backend in backends:
            keys = {"design": design} if len(designs) > 1 else {}
            keys.update({"backend": backend} if len(backends) > 1 else {})
            label = "/".join([design] + ([backend] if len(backends) > 1 else []))
            variants.append((design, backend, label, keys))
    sources = object_sources(args.object)
    recorder = open_recorder(args)

    def one(source: str, variant: tuple, prefix: str = "", prepared=None) -> dict:
        design, backend, label, keys = variant
        out = grasp(
            source,
            design,
            args.model,
            args.density,
            args.pose,
            impulse=args.impulse,
            tension=args.tension,
            lift=args.lift,
            backend=backend,
            device=args.device,
            seed=args.seed,
            allow_open=args.allow_open,
            cache_dir=user_cache_dir(),
            observer=recorder,
            label=prefix + label,
            prepared=prepared,
        )
        return {**keys, **out}

    def prepare(source: str):
        return prepare_object(
            source,
            args.density,
            args.pose,
            seed=args.seed,
            allow_open=args.allow_open,
            cache_dir=user_cache_dir(),
        )

    try:
        if sources is None:
            prepared = prepare(args.object)
            outs = [one(args.object, v, prepared=prepared) for v in variants]
            if len(outs) == 1:
                _print(outs[0], args.json)
            elif args.json:
                print(json.dumps(outs))
            else:
                for out in outs:
                    _print(out, False)
                    print()
            return 0
        from rich.console import Console
        from rich.progress import Progress

        results = []
        with Progress(console=Console(stderr=True), transient=True) as bar:
            task = bar.add_task(f"grasp {args.object}", total=len(sources) * len(variants))
            for source in sources:
                name = Path(source).stem if Path(source).suffix else source
                bar.update(task, description=f"grasp {name} (loading)")
                try:
                    prepared = prepare(source)
                except MjcodesignError as exc:  # every variant fails alike on an object that does not load
                    results += [{**v[3], **_failed_object(source, exc)} for v in variants]
                    bar.advance(task, len(variants))
                    continue
                for variant in variants:
                    bar.update(task, description=f"grasp {name} ({variant[2]})")
                    try:
                        results.append(one(source, variant, f"{name}/", prepared))
                    except MjcodesignError as exc:
                        results.append({**variant[3], **_failed_object(source, exc)})
                    bar.advance(task)
    finally:
        if recorder is not None:
            recorder.close()
    if args.json:
        print("[\n" + ",\n".join(json.dumps(r) for r in results) + "\n]")
    else:
        for r in results:
            _print(r, False)
            print()
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench grasp``."""
    from mjcodesign.bench.grasp import bench_grasp

    res = bench_grasp(
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
