"""``mjcodesign design OBJECT... --out DIR``: a verified, printable gripper for the user's objects.

Wire it in with ``cli_design.add_parser(subparsers)``. The pipeline is :func:`mjcodesign.pipeline.run_design`;
this module reads the flags, the environment (the OpenGL backend of the report's images, :func:`offscreen_gl`)
and prints.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys

from mjcodesign.cli.common import add_out_folder, emit, int_at_least, path_text, user_cache_dir
from mjcodesign.cli.progress import StageProgress

__all__ = ["add_parser", "offscreen_gl", "run"]

_MODES = ("joint", "individual")


def offscreen_gl(environ=os.environ) -> str | None:
    """The OpenGL backend of the report's images: ``MUJOCO_GL`` when it names one, EGL without a display.

    Returns one of :data:`mjcodesign.pipeline.GL_BACKENDS`, or None for MuJoCo's own choice (another
    ``MUJOCO_GL`` value, or a display). The backend is handed to the pipeline rather than set in the
    environment: MuJoCo reads ``MUJOCO_GL`` once, when it is first imported, which in a process that
    imported it before (a notebook, a test run) has already happened. EGL renders with no display
    (``MUJOCO_GL=osmesa`` also does).
    """
    from mjcodesign.pipeline import GL_BACKENDS

    gl = environ.get("MUJOCO_GL", "").strip().lower()
    if gl in GL_BACKENDS:
        return gl
    if gl:
        return None
    if sys.platform.startswith("linux") and not environ.get("DISPLAY") and not environ.get("WAYLAND_DISPLAY"):
        return "egl"
    return None


def add_parser(subparsers) -> None:
    """Register ``design`` on the main subparsers object."""
    p = subparsers.add_parser(
        "design",
        help="objects to a verified, printable gripper: poses, co-design, re-simulation, print files, report",
        description=(
            "Sample grasp poses of each object, co-design the 22 block stiffnesses through the surrogate, "
            "verify the design against soft, semi-rigid and paper-optimized by perturbed re-simulation, and "
            "write the design, poses, print files, report.md, report.html and run.rrd into --out."
        ),
    )
    p.add_argument(
        "objects",
        nargs="+",
        metavar="OBJECT",
        help="YCB name, egad-like:N, mesh file (STL/OBJ/PLY) or folder of meshes, with an optional mass: "
        "box.stl@120g, 013_apple@0.197kg (default: the checkpoint dataset's regime; real: the published "
        "YCB mass, other objects at 680 kg/m³)",
    )
    add_out_folder(p, "design")
    p.add_argument(
        "--ckpt",
        type=path_text,
        default=None,
        help="surrogate checkpoint folder (default: the shipped weights)",
    )
    p.add_argument("--masses", type=path_text, default=None, help="CSV of object,mass (120g, 0.12kg)")
    p.add_argument("--mode", choices=_MODES, default="joint", help="one design for all objects, or one each")
    p.add_argument(
        "--tendon", default=None, help="force:N or position:TICKS (default: the checkpoint dataset's drive)"
    )
    p.add_argument("--poses-per-object", type=int_at_least(1), default=10, help="grasp candidates per object")
    p.add_argument(
        "--budget",
        type=int_at_least(1),
        default=720,
        help="re-simulation rollouts of the verification (objects × 4 designs × 3 disturbances × draws)",
    )
    p.add_argument("--max-iterations", type=int_at_least(1), default=2000, help="N of Algorithm 1")
    p.add_argument(
        "--adapt",
        type=int_at_least(0),
        default=0,
        metavar="N",
        help="first simulate N grasps of each object at its sampled poses and fine-tune the surrogate on "
        "them (as train --init CKPT --lr 1e-4 does), then co-design through the adapted network "
        "(0: no adaptation)",
    )
    p.add_argument("--seed", type=int_at_least(0), default=0, help="poses, clouds and perturbation draws")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``design``; library errors propagate to the main CLI (exit 2, one line)."""
    from mjcodesign.codesign import Mode
    from mjcodesign.pipeline import DesignOptions, parse_objects, read_masses, run_design

    masses = read_masses(args.masses) if args.masses else None
    specs = parse_objects(args.objects, masses)
    tendon = None
    if args.tendon is not None:
        from mjcodesign.data import parse_tendon

        tendon = parse_tendon(args.tendon)
    options = DesignOptions(
        mode=Mode(args.mode),
        tendon=tendon,
        poses_per_object=args.poses_per_object,
        budget=args.budget,
        seed=args.seed,
        max_iterations=args.max_iterations,
        adapt=args.adapt,
    )
    from mjcodesign.surrogate import checkpoint_or_shipped

    ckpt = checkpoint_or_shipped(args.ckpt)
    recorder = None
    if importlib.util.find_spec("rerun") is not None:
        from mjcodesign.sim import load_observer

        def recorder(path):
            return load_observer("rerun", path=str(path))
    else:
        _warn("rerun-sdk is not installed: no run.rrd (pip install 'mjcodesign[viz]')")
    with StageProgress("design") as bars:

        def progress(stage: str, done: int, total: int) -> None:
            # iterations are many and short: plain lines only for the other stages
            bars.update(stage, done, total, log="iterations" not in stage)

        record = run_design(
            specs,
            checkpoint=ckpt,
            out=args.out,
            options=options,
            overwrite=args.overwrite,
            cache_dir=user_cache_dir(),
            command=args.command_line,
            recorder=recorder,
            progress=progress,
            warn=_warn,
            gl=offscreen_gl(),
        )
    if args.json:
        print(json.dumps(record))
    else:
        emit(_table(record), False)
        if record["adapt"]:
            print(f"adapt: {record['adapt']['summary']}")
        print(
            f"wrote {args.out}: design, poses, print files, report.md, report.html ({record['wall_s']:.0f} s)"
        )
    return 0


def _table(record: dict) -> list[dict]:
    """One row per object: success [%] with its interval per design at the table's disturbance."""
    v = record["verification"]
    rows = []
    for o in record["objects"]:
        row = {"object": o["name"]}
        for c in v["cells"]:
            if c["object"] == o["name"] and c["impulse_paper_ns"] == v["table_impulse_paper_ns"]:
                p = c["p"]
                row[c["design"]] = f"{100 * p['value']:.0f}% [{100 * p['low']:.0f}, {100 * p['high']:.0f}]"
        rows.append(row)
    return rows


def _warn(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr, flush=True)
