"""``mjcodesign grasp`` and ``mjcodesign bench grasp``.

Wire them into the main CLI with ``cli_grasp.add_parser(subparsers)`` and
``cli_grasp.add_bench_parser(bench_subparsers)``. ``python -m mjcodesign.cli_grasp ARGS`` runs
``grasp`` on its own with the same error mapping (exit 2 and one line).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

__all__ = ["add_parser", "add_bench_parser", "run", "run_bench", "grasp", "user_cache_dir", "main"]

_MODELS = ("chain", "flex")
_BACKENDS = ("mujoco", "mjwarp")


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/mjcodesign`` or ``~/.cache/mjcodesign`` (flags and environment live here)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mjcodesign"


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--object", required=True, help="YCB name (e.g. 025_mug), egad-like:N, or an OBJ/STL/PLY file"
    )
    p.add_argument(
        "--design", default="paper-optimized", help="stiffness preset or 11/22 comma-separated ln(E/Pa)"
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
    p.add_argument("--impulse", type=float, default=0.1, help="downward disturbance impulse [N s]")
    p.add_argument("--tension", type=float, default=None, help="tendon tension per finger [N]")
    p.add_argument("--lift", type=float, default=None, help="lift distance [m]")
    p.add_argument("--backend", choices=_BACKENDS, default="mujoco")
    p.add_argument(
        "--seed", type=int, default=0, help="seeds CoACD and egad-like shapes; MuJoCo is deterministic"
    )
    p.add_argument(
        "--allow-open", action="store_true", help="use the convex hull of a mesh that cannot be repaired"
    )
    p.add_argument("--json", action="store_true")


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
    from mjcodesign.mjcf import GripperPose
    from mjcodesign.scenario import auto_pose

    if text == "auto":
        return auto_pose(obj, design)
    if text == "best":
        from mjcodesign.poses import sample_poses, to_gripper_pose

        return to_gripper_pose(sample_poses(obj, 10, seed=seed, design=design))
    path = Path(text)
    if not path.is_file():
        raise PoseError(f"pose file not found: {path}")
    if path.suffix == ".npz":
        from mjcodesign.poses import read_candidates, to_gripper_pose

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
    impulse: float = 0.1,
    tension: float | None = None,
    lift: float | None = None,
    backend: str = "mujoco",
    seed: int = 0,
    allow_open: bool = False,
    cache_dir: Path | None = None,
) -> dict:
    """One grasp rollout; returns the JSON-ready outcome plus the object's facts."""
    from mjcodesign.backends import get_backend
    from mjcodesign.errors import MeshError
    from mjcodesign.finger import FingerDesign
    from mjcodesign.mjcf import FingerModel
    from mjcodesign.objects import CoacdSettings, convex_decomposition, load_object, parse_density
    from mjcodesign.scenario import GraspScenario, build_scene
    from mjcodesign.stiffness import Stiffness

    stiffness = Stiffness.parse(design)
    rho = parse_density(density)
    if Path(source).is_dir():
        raise MeshError(f"{source} is a folder: grasp takes one object (pass one mesh file)")
    sim = get_backend(backend)
    obj = load_object(source, rho, allow_open=allow_open, seed=seed)
    convex_decomposition(obj, CoacdSettings(seed=seed), cache_dir=cache_dir)
    finger_design = FingerDesign()
    gripper_pose = _read_pose(pose, obj, finger_design, seed)
    kwargs = {k: v for k, v in (("tension", tension), ("lift", lift)) if v is not None}
    scenario = GraspScenario(impulse=impulse, **kwargs)
    scene = build_scene(obj, finger_design, stiffness, FingerModel(model), gripper_pose)
    out = sim.run(scene, scenario).as_dict()
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


def run(args: argparse.Namespace) -> int:
    """Run ``grasp``; library errors propagate to the caller (exit 2 there)."""
    out = grasp(
        args.object,
        args.design,
        args.model,
        args.density,
        args.pose,
        impulse=args.impulse,
        tension=args.tension,
        lift=args.lift,
        backend=args.backend,
        seed=args.seed,
        allow_open=args.allow_open,
        cache_dir=user_cache_dir(),
    )
    _print(out, args.json)
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench grasp``."""
    from mjcodesign.bench_grasp import bench_grasp

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


def main(argv: list[str] | None = None) -> int:
    """Stand-alone ``grasp``: typed errors become exit 2 and one line on stderr."""
    from mjcodesign.cli import _Parser
    from mjcodesign.errors import MjcodesignError

    parser = _Parser(prog="mjcodesign grasp")
    _arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except MjcodesignError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
