"""``mjcodesign view``, ``mjcodesign bench viz`` and the recording flags of ``grasp`` and ``crosscheck``.

Recording goes through the observer registered as ``rerun`` (``mjcodesign.observers`` entry points, the
``viz`` package); this module never imports ``viz``. ``view`` and ``--spawn`` run the ``rerun`` viewer
that ships with ``rerun-sdk``; its gRPC server (desktop and web) and web viewer bind 127.0.0.1 only.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mjcodesign.cli.common import (
    check_output_link,
    emit,
    int_at_least,
    output_file,
    path_text,
    port_number,
    short,
    user_cache_dir,
)

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
_VIEWER_START_S = 20.0  # a spawned desktop viewer listens within this time, or is reported [s]
_POLL_S = 0.05  # [s]
_VIEWER_STOP_S = 10.0  # a viewer asked to stop (SIGTERM) is killed after this [s]


def add_recording_flags(p: argparse.ArgumentParser, *, decimation: bool = True) -> None:
    """The recording flags: ``--rrd``, ``--spawn``, ``--viewer-port`` and, for rollouts, ``--decimation``.

    ``--rrd FILE`` writes an offline recording (no viewer); ``--spawn`` streams to a desktop viewer.
    """
    p.add_argument(
        "--rrd", type=output_file, default=None, help="write a Rerun recording to this .rrd file (no viewer)"
    )
    p.add_argument("--spawn", action="store_true", help="also stream to a desktop Rerun viewer")
    p.add_argument(
        "--viewer-port",
        type=port_number,
        default=DEFAULT_VIEWER_PORT,
        help=f"--spawn: the viewer's gRPC port on {_LOOPBACK}; a viewer already there is reused",
    )
    if decimation:
        p.add_argument(
            "--decimation",
            type=int_at_least(1),
            default=None,
            help="log every N-th simulation step (default: 10 states per simulated second)",
        )


def open_recorder(args: argparse.Namespace):
    """The Rerun observer for ``--rrd``/``--spawn``, or None when neither is given.

    ``--spawn`` streams to the viewer already listening on 127.0.0.1 at ``--viewer-port``, or starts a
    desktop viewer there, bound to 127.0.0.1 (Rerun's own spawn binds 0.0.0.0), before the recorder
    looks for one. Raises :class:`ObserverError` when there is no display to show a new viewer on, and
    :class:`OutputError` for an ``--rrd`` that is a symbolic link (unless the command's ``--overwrite``).
    """
    spawn = getattr(args, "spawn", False)
    if not args.rrd and not spawn:
        return None
    if args.rrd:
        check_output_link(args.rrd, "--rrd", overwrite=getattr(args, "overwrite", None))
    from mjcodesign.sim import load_observer

    port = getattr(args, "viewer_port", DEFAULT_VIEWER_PORT)
    if spawn and not _listening(port):
        from mjcodesign.errors import ObserverError

        if not _has_display():
            raise ObserverError(
                "--spawn: no display (DISPLAY or WAYLAND_DISPLAY) for the desktop viewer; record with "
                "--rrd FILE and open it with `mjcodesign view FILE --web`"
            )
        start_viewer(port)
    return load_observer(
        "rerun",
        path=args.rrd,
        spawn=spawn,
        port=port,
        decimation=getattr(args, "decimation", None),
    )


def _has_display() -> bool:
    """Whether a desktop window can open: X11 or Wayland on Linux and the BSDs; always on macOS, Windows."""
    if sys.platform == "darwin" or sys.platform.startswith("win"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _listening(port: int) -> bool:
    """Whether something accepts TCP connections on 127.0.0.1 at ``port``."""
    try:
        with socket.create_connection((_LOOPBACK, port), timeout=1.0):
            return True
    except OSError:
        return False


def start_viewer(port: int) -> subprocess.Popen:
    """Start a desktop viewer whose gRPC server listens on 127.0.0.1 at ``port``; return once it listens.

    The viewer is detached (its own session): it stays open after the command ends, and a Ctrl-C of the
    command does not close it. Raises :class:`ObserverError` if it exits first or does not listen within
    :data:`_VIEWER_START_S`.
    """
    from mjcodesign.errors import ObserverError

    cmd = _viewer_executable() + ["--port", str(port), "--bind", _LOOPBACK, "--expect-data-soon"]
    log = tempfile.TemporaryFile()  # the viewer's own log, read back only if it fails to start
    env = {**os.environ, "RERUN_APP_ONLY": "true"}  # as Rerun's spawn: skips the analytics prompt
    proc = subprocess.Popen(
        cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=log, env=env, start_new_session=True
    )
    deadline = time.monotonic() + _VIEWER_START_S
    while not _listening(port):
        if proc.poll() is not None:
            log.seek(0)
            last = [ln for ln in log.read().decode(errors="replace").splitlines() if ln.strip()][-1:]
            raise ObserverError(
                f"the Rerun viewer exited at start (exit code {proc.returncode})"
                + (f": {last[0].strip()[:200]}" if last else "")
            )
        if time.monotonic() > deadline:
            proc.terminate()
            raise ObserverError(
                f"the Rerun viewer did not listen on port {port} within {_VIEWER_START_S:g} s"
            )
        time.sleep(_POLL_S)
    log.close()
    return proc


def view_command(
    path: str | Path, *, web: bool = False, port: int | None = None, web_port: int | None = None
) -> list[str]:
    """The viewer's command line: desktop or web viewer, its gRPC server bound to 127.0.0.1.

    ``port``: the viewer's (or the web viewer's gRPC server's) port; ``web_port``: the web viewer's
    HTTP port. None keeps Rerun's defaults (9876, 9090).
    """
    cmd = _viewer_executable()
    if web:
        cmd += ["--serve-web"]
        if web_port is not None:
            cmd += ["--web-viewer-port", str(web_port)]
    cmd += ["--bind", _LOOPBACK]
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
    _check_recording(path)
    if not args.web and not _has_display():
        raise ObserverError(
            "no display (DISPLAY or WAYLAND_DISPLAY) for the desktop viewer: use --web to serve the "
            "web viewer on 127.0.0.1"
        )
    cmd = view_command(path, web=args.web, port=args.port, web_port=args.web_port)
    with _signals_interrupt((signal.SIGTERM, signal.SIGHUP)) as received:
        proc = subprocess.Popen(cmd, preexec_fn=_die_with_parent)
        try:
            return proc.wait()
        except KeyboardInterrupt:  # SIGINT, SIGTERM or SIGHUP: close the viewer's servers, then go
            proc.terminate()
            try:
                proc.wait(timeout=_VIEWER_STOP_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            return 128 + received.get("signal", signal.SIGINT)


_PR_SET_PDEATHSIG = 1  # prctl(2) option: the signal the child gets when its parent dies (Linux)


def _die_with_parent() -> None:
    """In the viewer's process, before exec: ask the kernel to end it (SIGTERM) when its parent dies.

    So a command killed by any signal, SIGKILL included, leaves no viewer behind. Linux only; elsewhere
    the viewer goes with the command on SIGINT, SIGTERM and SIGHUP (:func:`_signals_interrupt`).
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


@contextlib.contextmanager
def _signals_interrupt(signals: tuple[int, ...]):
    """Within the block, ``signals`` raise :class:`KeyboardInterrupt` as SIGINT does.

    Yields a dict that then holds the ``signal`` received; the previous handlers are put back after.
    """
    received: dict = {}

    def handler(signum, frame):
        received["signal"] = signum
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield received
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _check_recording(path: Path) -> None:
    """Raise :class:`ObserverError` unless ``path`` is a Rerun recording holding some logged data.

    Reads the file's chunks up to the first one of a logged entity (Rerun's own ``/__properties`` are
    not data), so that the viewer is never started on a file it would show as empty.
    """
    from rerun.chunk import RrdReader

    from mjcodesign.errors import ObserverError

    try:
        has_data = any(not str(c.entity_path).startswith("/__") for c in RrdReader(str(path)).stream())
    except (RuntimeError, OSError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ObserverError(
            f"{short(str(path))} is not a readable Rerun recording ({reason[:200]})"
        ) from None
    if not has_data:
        raise ObserverError(f"{short(str(path))}: the recording holds no data")


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
        command=args.command_line,
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
    p.add_argument("file", type=path_text, help="a .rrd file written with --rrd")
    p.add_argument("--web", action="store_true", help=f"serve the web viewer on {_LOOPBACK} instead")
    p.add_argument("--port", type=port_number, default=None, help="viewer / gRPC server port (default 9876)")
    p.add_argument("--web-port", type=port_number, default=None, help="--web: HTTP port (default 9090)")
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
    p.add_argument("--repeats", type=int_at_least(1), default=5, help="rollouts per measurement (median)")
    p.add_argument(
        "--decimations",
        default="default,5,1",
        help="logged every N steps, comma-separated ('default': 10 Hz)",
    )
    p.add_argument("--out", type=path_text, default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_viz)
