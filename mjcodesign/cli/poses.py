"""``mjcodesign poses`` and ``mjcodesign bench poses``.

Wire them into the main CLI with ``cli_poses.add_parser(subparsers)`` and
``cli_poses.add_bench_parser(bench_subparsers)``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from mjcodesign.cli.common import int_at_least, path_text, user_cache_dir

__all__ = ["add_parser", "add_bench_parser", "run", "run_bench", "poses"]

_DEFAULT_BENCH_OBJECTS = "012_strawberry,013_apple,005_tomato_soup_can,010_potted_meat_can"
_DEFAULT_N = 10  # sampled poses returned when --n is not given


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``poses`` on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "poses", help="antipodal grasp candidates, refined on the rigid counterpart of the fingers"
    )
    p.add_argument(
        "--object",
        required=True,
        type=path_text,
        help="YCB name (e.g. 025_mug), egad-like:N, or an OBJ/STL/PLY file",
    )
    p.add_argument(
        "--n",
        type=int_at_least(1),
        default=None,
        help=f"poses to return: sampled ones best first (default {_DEFAULT_N}); with --import the first N "
        "rows in --order (default: every row)",
    )
    p.add_argument(
        "--order",
        choices=("source", "rank"),
        default="source",
        help="with --import: rows in the file's order (source) or best first (rank); refused rows are "
        "listed under 'refused'",
    )
    p.add_argument("--seed", type=int, default=0, help="seeds the surface samples, picks, tilts and noise")
    p.add_argument(
        "--top-fraction",
        type=float,
        default=0.0,
        help="share of the candidates that a side approach could take approached from above instead (top "
        "grasps rarely hold through the disturbance); pairs no side approach fits are always approached "
        "from above",
    )
    p.add_argument(
        "--augment", type=int_at_least(0), default=0, help="noisy copies per candidate (σ 3 mm, 5e-3 rad)"
    )
    p.add_argument(
        "--import",
        dest="import_file",
        type=path_text,
        default=None,
        help="refine external candidates instead of sampling: AnyGrasp .npz (T_pose, N×4×4), .npy 4×4 / "
        "N×4×4 / N×17, or text rows of 17 GraspNet floats, in the authors' camera frame",
    )
    p.add_argument(
        "--fit-depth",
        action="store_true",
        help="the refinement also sets the depth along the approach (the paper's L_init): every finger "
        "point pulled towards the object or the ground, fingertips stopping 2 mm above the ground",
    )
    p.add_argument(
        "--point-cloud",
        type=path_text,
        default=None,
        help="sample contacts from a .npy of shape (n, 6): points [m] and outward normals, object COM frame",
    )
    p.add_argument(
        "--allow-open", action="store_true", help="use the convex hull of a mesh that cannot be repaired"
    )
    p.add_argument("--json", action="store_true")
    p.add_argument(
        "--out",
        type=path_text,
        default=None,
        help="write the poses to FILE.npz (grasp --pose FILE reads it); says so on stderr",
    )
    p.set_defaults(func=run)
    return p


def add_bench_parser(bench_subparsers) -> argparse.ArgumentParser:
    """Register ``poses`` on the ``bench`` command's subparsers object."""
    p = bench_subparsers.add_parser(
        "poses", help="grasp candidates: penetration, approach spread, MuJoCo success (semi-rigid), poses/s"
    )
    p.add_argument(
        "--objects",
        default=_DEFAULT_BENCH_OBJECTS,
        help="comma-separated names, or a named set: ycb-in-domain (46), ycb-ood (32), egad-like (25), ood (42)",
    )
    p.add_argument("--per-object", type=int_at_least(1), default=4, help="poses per object")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--density", default="light", help="object density [kg/m³] or light / heavy")
    p.add_argument(
        "--impulse",
        type=float,
        default=None,
        help="disturbance impulse [N s] of the grasp motion (default: the grasp scenario's, 0.0179)",
    )
    p.add_argument("--top-fraction", type=float, default=0.0)
    p.add_argument(
        "--anygrasp", default=None, help="folder of the authors' pose_info/*.npz, imported beside the sampler"
    )
    p.add_argument("--no-sim", action="store_true", help="skip the MuJoCo grasps")
    p.add_argument(  # does any design of a fixed set hold each pose?
        "--designs",
        default="semi-rigid",
        help="designs to grasp with, comma-separated presets or random:N (the first is reported), or "
        "fixed11: semi-rigid, soft, paper-optimized, random:0..7 (counts the poses every design lets fall)",
    )
    p.add_argument(  # the convex hull is an explicit choice
        "--allow-open", action="store_true", help="use the convex hull of a mesh that no repair can close"
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_bench)
    return p


def poses(
    source: str,
    n: int | None = None,
    seed: int = 0,
    *,
    order: str = "source",
    top_fraction: float = 0.0,
    augment: int = 0,
    import_file: str | None = None,
    point_cloud: str | None = None,
    allow_open: bool = False,
    fit_depth: bool = False,
):
    """(object, candidates) for the ``poses`` command.

    ``n``: sampled poses (default ``_DEFAULT_N``), or the first ``n`` imported rows (default: all) in
    ``order``: ``source`` (the file's rows, each followed by its noisy copies) or ``rank`` (best first).
    """
    import numpy as np

    from mjcodesign.errors import PoseError
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.objects import load_mesh
    from mjcodesign.poses import SamplerOptions, import_anygrasp, load_external, sample_poses

    T = load_external(import_file) if import_file is not None else None  # a bad file fails first
    points = normals = None
    if point_cloud is not None:
        try:
            cloud = np.load(point_cloud)
        except (OSError, ValueError, EOFError) as exc:  # EOFError: an empty file
            raise PoseError(f"{point_cloud}: cannot read the point cloud ({type(exc).__name__})") from exc
        if not isinstance(cloud, np.ndarray):
            raise PoseError(f"{point_cloud}: a point cloud is one .npy array of shape (n, 6), not an .npz")
        if cloud.ndim != 2 or cloud.shape[1] != 6:
            raise PoseError(f"{point_cloud}: point cloud must have shape (n, 6), got {cloud.shape}")
        points, normals = cloud[:, :3], cloud[:, 3:]
    # the object with its convex pieces (cached), so that the candidates' start-opening check
    # sees the geometry the grasp scene collides with.
    obj = load_grasp_object(source, 100.0, seed=seed, allow_open=allow_open, cache_dir=user_cache_dir())
    if T is not None:
        cands = import_anygrasp(
            obj,
            T,
            load_mesh(source).vertices,
            seed=seed,
            augment=augment,
            source=Path(import_file).name,
            cache_dir=user_cache_dir(),
            fit_depth=fit_depth,
        )
        if order == "source":
            cands = cands.in_source_order()
        return obj, cands if n is None else cands.head(n)
    options = SamplerOptions(top_fraction=top_fraction, augment=augment, fit_depth=fit_depth)
    return obj, sample_poses(
        obj,
        _DEFAULT_N if n is None else n,
        seed=seed,
        options=options,
        points=points,
        normals=normals,
        cache_dir=user_cache_dir(),
    )


def run(args: argparse.Namespace) -> int:
    """Run ``poses``; library errors propagate to the caller (exit 2 there)."""
    from mjcodesign.errors import OutputError, PoseError

    obj, cands = poses(
        args.object,
        args.n,
        args.seed,
        order=args.order,
        top_fraction=args.top_fraction,
        augment=args.augment,
        import_file=args.import_file,
        point_cloud=args.point_cloud,
        allow_open=args.allow_open,
        fit_depth=args.fit_depth,
    )
    if not cands.as_dicts():  # e.g. an object wider than every opening once refined
        top = sorted(cands.rejected.items(), key=lambda kv: -kv[1])[:3]
        raise PoseError(
            f"no grasp pose accepted for {obj.name} (most rejections: "
            + ", ".join(f"{k} {v}" for k, v in top)
            + ")"
        )
    if args.out is not None:
        out = Path(args.out)
        if out.suffix != ".npz":
            raise OutputError(f"--out must name an .npz file, got {out}")
        try:
            cands.save(out, obj.name)
        except OSError as exc:
            raise OutputError(f"cannot write {out}: {exc}") from exc
        # On stderr: with --json, stdout holds the JSON alone.
        print(f"wrote {len(cands.as_dicts())} poses of {obj.name} to {out}", file=sys.stderr)
    result = {"object": obj.name, "poses": cands.as_dicts(), "rejected": cands.rejected}
    asked = args.n if args.n is not None or args.import_file is not None else _DEFAULT_N
    if asked is not None and len(cands) < asked:  # fewer than asked: say so, and why
        top = sorted(cands.rejected.items(), key=lambda kv: (-kv[1], kv[0]))[:3]
        why = ", ".join(f"{k} {v}" for k, v in top) or "no more candidates"
        what = "rows accepted" if args.import_file is not None else "candidates accepted"
        result["short"] = {
            "asked": asked,
            "returned": len(cands),
            "reason": f"{len(cands)} {what} (most rejections: {why})",
        }
        print(
            f"warning: {len(cands)} of {asked} poses for {obj.name}: {result['short']['reason']}",
            file=sys.stderr,
        )
    if cands.source != "sampler":  # an import names its file and every row it refused
        result.update(source=cands.source, refused=cands.refused_dicts())
    if args.json:
        print(json.dumps(result))
    elif args.out is None:
        for i, row in enumerate(result["poses"]):
            print(
                f"{i:3d} source {row['source_index']}/{row['copy_index']} score {row['score']:.3f} "
                f"openings {row['openings']} sd {row['min_signed_distance_m']:.2e}"
            )
        print("rejected", result["rejected"])
    return 0


def _bench_designs(text: str) -> tuple[str, ...]:
    """``--designs``: ``fixed11`` or comma-separated designs, each checked by ``Stiffness.parse``."""
    from mjcodesign.bench.poses import FIXED_DESIGNS
    from mjcodesign.design.stiffness import Stiffness

    designs = FIXED_DESIGNS if text == "fixed11" else tuple(d.strip() for d in text.split(","))
    for d in designs:
        Stiffness.parse(d)  # a bad name exits 2 before any object loads
    return designs


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench poses``."""
    from mjcodesign.bench import run_benchmark
    from mjcodesign.objects import OBJECT_SETS, named_set, parse_density

    names = list(named_set(args.objects)) if args.objects in OBJECT_SETS else args.objects.split(",")
    res = run_benchmark(
        "poses",
        command=args.command_line,
        objects=names,
        per_object=args.per_object,
        seed=args.seed,
        density=parse_density(args.density),
        impulse=args.impulse,
        top_fraction=args.top_fraction,
        anygrasp_dir=args.anygrasp,
        simulate=not args.no_sim,
        allow_open=args.allow_open,
        designs=_bench_designs(args.designs),
        cache_dir=user_cache_dir(),
    )
    failed = [r for r in res["objects"] if "error" in r]
    if failed and len(failed) == len(res["objects"]):  # a benchmark of nothing is a refusal
        from mjcodesign.errors import MjcodesignError

        more = f"; {len(failed) - 1} more failed" if len(failed) > 1 else ""
        raise MjcodesignError(
            f"bench poses: no object could be used ({failed[0]['object']}: {failed[0]['error']}{more})"
        )
    if args.json:
        print(json.dumps(res))
    else:
        for k in ("sampler", "anygrasp"):
            print(k, res[k])
    return 0
