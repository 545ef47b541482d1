"""``mjcodesign view``, ``mjcodesign bench viz`` and the recording flags of ``grasp`` and ``crosscheck``.

Recording goes through the observer registered as ``rerun`` (``mjcodesign.observers`` entry points, the
``viz`` package); this module never imports ``viz``. ``view`` runs the ``rerun`` viewer that ships with
``rerun-sdk``; its web viewer and gRPC server bind 127.0.0.1 only.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from mjcodesign.cli.common import emit, user_cache_dir

__all__ = [
    "add_parser",
    "add_bench_parser",
    "add_recording_flags",
    "open_recorder",
    "view_command",
]

_LOOPBACK = "127.0.0.1"
DEFAULT_VIEWER_PORT = 9876
"""Rerun's default viewer port."""


def add_recording_flags(p: argparse.ArgumentParser, *, decimation: bool = True) -> None:
    """The recording flags: ``--rrd``, ``--spawn``, ``--viewer-port`` and, for rollouts, ``--decimation``.

    ``--rrd FILE`` writes an offline recording (no viewer); ``--spawn`` streams to a desktop viewer.
    """
    p.add_argument("--rrd", default=None, help="write a Rerun recording to this .rrd file (no viewer)")
    p.add_argument("--spawn", action="store_true", help="also stream to a desktop Rerun viewer")
    p.add_argument(
        "--viewer-port",
        type=int,
        default=DEFAULT_VIEWER_PORT,
        help=f"--spawn: the viewer's gRPC port on {_LOOPBACK}; a viewer already there is reused",
    )
    if decimation:
        p.add_argument(
            "--decimation",
            type=int,
            default=None,
            help="log every N-th simulation step (default: 10 states per simulated second)",
        )


def open_recorder(args: argparse.Namespace):
    """The Rerun observer for ``--rrd``/``--spawn``, or None when neither is given."""
    spawn = getattr(args, "spawn", False)
    if not args.rrd and not spawn:
        return None
    from mjcodesign.sim import load_observer

    return load_observer(
        "rerun",
        path=args.rrd,
        spawn=spawn,
        port=getattr(args, "viewer_port", DEFAULT_VIEWER_PORT),
        decimation=getattr(args, "decimation", None),
    )


def view_command(
    path: str | Path, *, web: bool = False, port: int | None = None, web_port: int | None = None
) -> list[str]:
    """The viewer's command line: desktop, or web viewer + gRPC server bound to 127.0.0.1.

    ``port``: the viewer's (or the web viewer's gRPC server's) port; ``web_port``: the web viewer's
    HTTP port. None keeps Rerun's defaults (9876, 9090).
    """
    cmd = _viewer_executable()
    if web:
        cmd += ["--serve-web", "--bind", _LOOPBACK]
        if web_port is not None:
            cmd += ["--web-viewer-port", str(web_port)]
    if port is not None:
        cmd += ["--port", str(port)]
    return cmd + [str(path)]


def _viewer_executable() -> list[str]:
    """The ``rerun`` binary of the installed ``rerun-sdk`` itself (``RERUN_CLI_PATH`` overrides it).

    Not ``python -m rerun``: that wrapper runs the binary as its own child, which a signal to the wrapper
    alone (a supervisor, a test) leaves running with its servers open.
    """
    import os

    override = os.environ.get("RERUN_CLI_PATH")
    if override:
        return [override]
    try:
        import rerun_cli
    except ImportError:
        return [sys.executable, "-m", "rerun"]
    exe = Path(rerun_cli.__file__).with_name("rerun.exe" if sys.platform.startswith("win") else "rerun")
    return [str(exe)] if exe.is_file() else [sys.executable, "-m", "rerun"]


def _cmd_view(args) -> int:
    import importlib.util

    from mjcodesign.errors import ObserverError

    path = Path(args.file)
    if not path.is_file():
        raise ObserverError(f"recording not found: {path}")
    if importlib.util.find_spec("rerun") is None:
        raise ObserverError("the Rerun viewer is not installed (pip install 'mjcodesign[viz]')")
    proc = subprocess.Popen(view_command(path, web=args.web, port=args.port, web_port=args.web_port))
    try:
        return proc.wait()
    except KeyboardInterrupt:  # let the viewer close its servers, then go
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        return 130


def _cmd_bench_viz(args) -> int:
    from mjcodesign.bench import run_benchmark
    from mjcodesign.bench.viz import CASES
    from mjcodesign.errors import DesignError

    try:
        decimations = tuple(None if v == "default" else int(v) for v in args.decimations.split(","))
    except ValueError:
        decimations = (0,)
    if any(v is not None and v < 1 for v in decimations):
        raise DesignError(f"--decimations must be 'default' or steps >= 1, got {args.decimations}")
    unknown = set(args.cases.split(",")) - {c.name for c in CASES}
    if unknown:
        raise DesignError(
            f"unknown bench viz case(s) {sorted(unknown)}; choose from {[c.name for c in CASES]}"
        )
    res = run_benchmark(
        "viz",
        out=args.out,
        names=args.cases.split(","),
        decimations=decimations,
        repeats=args.repeats,
        cache_dir=user_cache_dir(),
    )
    if args.json:
        print(json.dumps(res))
    else:
        emit(res["cases"], False)
    return 0


def add_parser(subparsers) -> None:
    """Register ``view`` on the top-level sub-parsers."""
    p = subparsers.add_parser("view", help="open a Rerun recording (.rrd) in the desktop or web viewer")
    p.add_argument("file", help="a .rrd file written with --rrd")
    p.add_argument("--web", action="store_true", help=f"serve the web viewer on {_LOOPBACK} instead")
    p.add_argument("--port", type=int, default=None, help="viewer / gRPC server port (default 9876)")
    p.add_argument("--web-port", type=int, default=None, help="--web: HTTP port (default 9090)")
    p.set_defaults(func=_cmd_view)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench viz`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "viz", help="cost of recording a grasp to Rerun against the rollout time, per decimation"
    )
    p.add_argument(
        "--cases",
        default="chain-box,chain-held,chain-ycb",
        help="comma-separated, from chain-box, chain-held, chain-ycb, flex-box",
    )
    p.add_argument("--repeats", type=int, default=5, help="rollouts per measurement (median)")
    p.add_argument(
        "--decimations",
        default="default,5,1",
        help="logged every N steps, comma-separated ('default': 10 Hz)",
    )
    p.add_argument("--out", default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_viz)
