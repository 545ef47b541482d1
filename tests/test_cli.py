import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

_VIEW_EXIT_S = 30  # view ends within this after a signal: it gives its viewer 10 s to stop, then kills it
_ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


def _run(*args, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", *args], capture_output=True, text=True, timeout=timeout
    )


def test_validate_beam_json():
    r = _run("validate", "beam", "--model", "chain", "--design", "paper-optimized", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert {"tip_deflection_m", "analytic_m", "rel_error"} <= set(out)
    assert out["rel_error"] <= 0.05


@pytest.mark.parametrize(
    "args",
    [
        ["validate", "beam", "--design", "bogus"],
        ["validate", "beam", "--design", "1,2,3"],
        ["validate", "beam", "--design", "nan," + ",".join(["15"] * 10)],
        ["validate", "beam", "--design", ",".join(["18"] * 22)],
        ["validate", "beam", "--model", "fem"],
        ["validate", "beam", "--force", "-1"],
        ["finger", "export", "--out", "/proc/forbidden/x"],
    ],
)
def test_bad_input_exits_2_with_one_line(args):
    r = _run(*args)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr


def test_finger_export_reloads(tmp_path):
    import mujoco

    r = _run(
        "finger",
        "export",
        "--design",
        "soft",
        "--model",
        "chain",
        "--gripper",
        "--out",
        str(tmp_path),
        "--json",
    )
    assert r.returncode == 0, r.stderr
    m = mujoco.MjModel.from_xml_path(str(tmp_path / "model.xml"))
    names = [m.tendon(i).name for i in range(m.ntendon)]
    assert m.nu == 5 and sorted(n for n in names if "gap" not in n) == ["A_tendon", "B_tendon"]
    assert len(names) == 2 + 2 * 5  # and every flexure's gap stop (chain)
    mb = mujoco.MjModel.from_binary_path(str(tmp_path / "model.mjb"))
    assert mb.nq == m.nq
    assert len(list((tmp_path / "blocks").glob("*.stl"))) == 11


def test_import_is_light():
    code = (
        "import sys, mjcodesign, mjcodesign.cli\n"
        "heavy = [m for m in ('torch', 'rerun', 'warp', 'franky', 'dynamixel_sdk', 'mujoco_warp', 'ray')"
        " if m in sys.modules]\n"
        "print(','.join(heavy))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "", r.stdout + r.stderr


def test_bench_finger_writes_json(tmp_path):
    out = tmp_path / "bench.json"
    r = _run("bench", "finger", "--models", "chain", "--seconds", "0.05", "--json", "--out", str(out))
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["chain"]["steps_per_s"] > 0 and json.loads(out.read_text()) == res


def test_bench_finger_out_unwritable_exits_2_with_one_line(tmp_path):
    r = _run(
        "bench", "finger", "--models", "chain", "--seconds", "0.01", "--out", str(tmp_path / "no" / "b.json")
    )
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: cannot write"), r.stderr


def test_run_benchmark_writes_atomically(tmp_path, monkeypatch):
    from mjcodesign import bench
    from mjcodesign.errors import DesignError, OutputError

    monkeypatch.setitem(bench.BENCHMARKS, "toy", "json:loads")
    out = tmp_path / "toy.json"
    out.write_text("old")
    res = bench.run_benchmark("toy", out=out, s='{"a": [1, 2]}')
    assert res.pop("provenance")["benchmark"] == "toy" and res == {"a": [1, 2]}
    on_disk = json.loads(out.read_text())
    assert on_disk.pop("provenance")["benchmark"] == "toy" and on_disk == {"a": [1, 2]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["toy.json"]  # no temporary file left
    with pytest.raises(OutputError):
        bench.run_benchmark("toy", out=tmp_path, s="{}")  # a folder: the rename fails, nothing is left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["toy.json"]
    with pytest.raises(DesignError):
        bench.run_benchmark("nope")
    assert set(bench.BENCHMARKS) >= {"finger", "grasp", "poses", "viz", "fem"}


def test_cli_families_import_only_common():
    # cli/main.py assembles the parser; the families share cli/common.py, never cli.main's names.
    import ast
    from pathlib import Path

    cli = Path(__file__).resolve().parents[1] / "mjcodesign" / "cli"
    for path in cli.glob("*.py"):
        if path.name in ("main.py", "__init__.py", "__main__.py"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module:
                assert node.module != "mjcodesign.cli.main", path.name
                if node.module == "mjcodesign.cli":
                    assert all(a.name != "main" for a in node.names), path.name


def test_quiet_warp_keeps_json_clean():
    pytest.importorskip("warp")
    code = (
        "from mjcodesign.cli.common import quiet_warp\n"
        "from mjcodesign.optional import import_warp\n"
        "quiet_warp(); import_warp(); print('{}')"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout == "{}\n", r.stdout + r.stderr
    assert "CUDA driver" not in r.stderr, r.stderr


# -- viewers bind 127.0.0.1 only -----------------------------------------------------------------
# A desktop viewer needs a display. Here a fake X server takes the viewer's connection and never
# answers, so the viewer waits in its X handshake with its gRPC server already listening (it binds
# before it opens a window): the test reads that server's sockets from /proc/net/tcp{,6}.
_LOOPBACK_HEX = "0100007F"  # 127.0.0.1 as /proc/net/tcp writes it
_LISTEN = "0A"


def _sockets_on(port: int) -> dict[str, str]:
    """Inode -> local address (hex) of every socket listening on TCP ``port``, IPv4 and IPv6."""
    found = {}
    for table in (Path("/proc/net/tcp"), Path("/proc/net/tcp6")):
        rows = table.read_text().splitlines()[1:] if table.exists() else []
        for fields in (row.split() for row in rows):
            address, hex_port = fields[1].rsplit(":", 1)
            if fields[3] == _LISTEN and int(hex_port, 16) == port:
                found[fields[9]] = address
    return found


def _pids_holding(inodes) -> set[int]:
    """Processes that hold any of these socket inodes open."""
    wanted = {f"socket:[{i}]" for i in inodes}
    pids = set()
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        try:
            if any(os.readlink(fd) in wanted for fd in fd_dir.iterdir()):
                pids.add(int(fd_dir.parent.name))
        except OSError:  # a process that ended, or one of another user
            continue
    return pids


def _await_sockets(port: int, alive, timeout_s: float = 60.0) -> dict[str, str]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if found := _sockets_on(port):
            return found
        assert alive(), "the viewer's process ended before listening"
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on port {port} after {timeout_s} s")


@pytest.fixture
def fake_display(monkeypatch):
    """DISPLAY of an X server (a Linux abstract socket) that accepts connections and never answers."""
    if not (sys.platform.startswith("linux") and Path("/proc/net/tcp").exists()):
        pytest.skip("reads listening sockets from /proc and uses a Linux abstract socket")
    pytest.importorskip("rerun")
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    for n in range(4711, 4911):
        try:
            server.bind(f"\0/tmp/.X11-unix/X{n}")
            break
        except OSError:
            continue
    server.listen(16)
    env = {k: v for k, v in os.environ.items() if k != "WAYLAND_DISPLAY"}
    yield {**env, "DISPLAY": f":{n}", "RERUN_ANALYTICS": "0"}
    server.close()


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _box_recording(tmp_path) -> Path:
    import trimesh

    box, rrd = tmp_path / "box.stl", tmp_path / "box.rrd"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    r = _run("grasp", "--object", str(box), "--impulse", "0", "--rrd", str(rrd))
    assert r.returncode == 0, r.stderr
    return rrd


def test_desktop_view_binds_loopback_only(tmp_path, fake_display, children):
    rrd, port = _box_recording(tmp_path), _free_tcp_port()
    cmd = [sys.executable, "-m", "mjcodesign.cli", "view", str(rrd), "--port", str(port)]
    proc = subprocess.Popen(
        cmd, env=fake_display, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    try:
        sockets = _await_sockets(port, lambda: proc.poll() is None)
        assert set(sockets.values()) == {_LOOPBACK_HEX}, sockets
    finally:
        proc.send_signal(signal.SIGINT)  # view closes its viewer and returns 130
        code = _wait_or_end(proc, children)
    assert code == 130, proc.stderr.read()
    left = _sockets_on(port)  # the viewer went with it; if not, name who still holds the port
    assert not left, {pid: _cmdline(pid) for pid in _pids_holding(left)} or left


def _wait_or_end(proc: subprocess.Popen, children) -> int:
    """``proc``'s exit code within :data:`_VIEW_EXIT_S`; else it and its children are killed, and it raises.

    A view that outlived its test would keep its viewer's servers spinning through the rest of the suite.
    """
    try:
        return proc.wait(timeout=_VIEW_EXIT_S)
    except subprocess.TimeoutExpired:
        for pid in [*children(proc.pid), proc.pid]:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        proc.wait()
        raise


def _alive(pid: int) -> bool:
    """Whether ``pid`` is a running process (not gone, not a zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT, signal.SIGKILL])
def test_web_view_leaves_no_viewer_behind_whatever_ends_it(tmp_path, sig, children):
    # SIGINT, SIGTERM, SIGHUP: view closes its viewer and returns 128 + the signal; SIGKILL: the kernel
    # ends the viewer with it (PR_SET_PDEATHSIG). Either way no process view started survives it.
    if not (sys.platform.startswith("linux") and Path("/proc/net/tcp").exists()):
        pytest.skip("reads listening sockets and children from /proc")
    pytest.importorskip("rerun")
    rrd, port, web_port = _box_recording(tmp_path), _free_tcp_port(), _free_tcp_port()
    cmd = [sys.executable, "-m", "mjcodesign.cli", "view", str(rrd), "--web", "--port", str(port)]
    cmd += ["--web-port", str(web_port)]
    proc = subprocess.Popen(cmd, env=_ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    kids: set[int] = set()
    try:
        _await_sockets(port, lambda: proc.poll() is None)
        kids = children(proc.pid)
        assert kids, "view started no viewer"
    finally:
        proc.send_signal(sig)
        code = _wait_or_end(proc, children)
    deadline = time.monotonic() + _VIEW_EXIT_S
    while any(_alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    survivors = {k: _cmdline(k) for k in kids if _alive(k)}
    for k in survivors:
        os.kill(k, signal.SIGKILL)
    assert not survivors, survivors
    assert code == (-sig if sig == signal.SIGKILL else 128 + sig)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")[:200]
    except OSError:
        return "(gone)"


def test_spawn_starts_a_viewer_bound_to_loopback_only(tmp_path, fake_display):
    import trimesh

    box, port = tmp_path / "box.stl", _free_tcp_port()
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    args = ["grasp", "--object", str(box), "--impulse", "0", "--spawn", "--viewer-port", str(port), "--json"]
    r = subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", *args],
        capture_output=True, text=True, timeout=300, env={**fake_display, "XDG_CACHE_HOME": str(tmp_path)},
    )  # fmt: skip
    sockets = _sockets_on(port)
    viewers = _pids_holding(sockets)
    try:
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["reason"] is not None
        # The viewer outlives the command (it is the user's window) and listens on 127.0.0.1 only.
        assert sockets and set(sockets.values()) == {_LOOPBACK_HEX}, sockets
        assert viewers, "no process holds the viewer's socket"
    finally:
        for pid in viewers:
            os.kill(pid, signal.SIGTERM)


def test_view_and_spawn_without_a_display_are_refused_before_binding(tmp_path):
    pytest.importorskip("rerun")
    if not sys.platform.startswith("linux"):
        pytest.skip("a desktop window needs DISPLAY or WAYLAND_DISPLAY only on Linux and the BSDs")
    import trimesh

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    box, port = tmp_path / "box.stl", _free_tcp_port()
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    for args in (
        ["view", str(_box_recording(tmp_path)), "--port", str(port)],
        ["grasp", "--object", str(box), "--spawn", "--viewer-port", str(port)],
    ):
        r = subprocess.run(
            [sys.executable, "-m", "mjcodesign.cli", *args],
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1 and "--web" in lines[0], r.stderr
        assert not _sockets_on(port)


def test_benchmarks_refuse_bad_arguments_before_running():
    from mjcodesign.bench import run_benchmark
    from mjcodesign.errors import DesignError

    for name, kwargs in (
        ("finger", {"models": ["rubber"]}),
        ("finger", {"models": ["chain"], "seconds": float("nan")}),
        ("finger", {"models": ["chain"], "seconds": -1.0}),
        ("finger", {"models": ["chain"], "flex_cells": 0}),
        ("grasp", {"rollouts": 0}),  # once silently 32
        ("grasp", {"rollouts": -2}),
        ("viz", {"repeats": 0}),
    ):
        with pytest.raises(DesignError):
            run_benchmark(name, **kwargs)


def test_bench_finger_reports_progress_per_model_on_stderr_only():
    from mjcodesign.bench import run_benchmark

    calls = []
    res = run_benchmark("finger", models=["chain"], seconds=0.01, progress=lambda *a: calls.append(a))
    assert calls == [("chain", 0)] and set(res) == {"chain", "provenance"}
    r = _run("bench", "finger", "--models", "chain", "--seconds", "0.01", "--json")
    assert r.returncode == 0, r.stderr
    rec = json.loads(r.stdout)  # stdout: the JSON alone, with the command that made it
    assert set(rec) == {"chain", "provenance"}
    assert rec["provenance"]["command"] == "mjcodesign bench finger --models chain --seconds 0.01 --json"


def test_finger_export_flex_notes_the_approximate_tendon_on_stderr(tmp_path):
    r = _run("finger", "export", "--model", "flex", "--out", str(tmp_path / "flex"), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["tendon_mode"] == "native"
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("note:") and "approximate" in lines[0], r.stderr
    r = _run("finger", "export", "--model", "chain", "--out", str(tmp_path / "chain"), "--json")
    assert r.returncode == 0 and r.stderr == "", r.stderr


def test_poses_out_says_what_it_wrote_on_stderr(tmp_path):
    pytest.importorskip("warp")
    import trimesh

    box, out = tmp_path / "box.stl", tmp_path / "p.npz"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    cmd = [
        sys.executable,
        "-m",
        "mjcodesign.cli",
        "poses",
        "--object",
        str(box),
        "--n",
        "2",
        "--out",
        str(out),
    ]
    r = subprocess.run([*cmd, "--json"], capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    n = len(json.loads(r.stdout)["poses"])  # stdout: the JSON alone
    assert out.is_file() and r.stderr.strip().splitlines()[-1] == f"wrote {n} poses of box to {out}", r.stderr


def test_finite_floats_parses_a_list_and_refuses_any_bad_element():
    import argparse

    from mjcodesign.cli.common import finite_floats

    positive = finite_floats(0.0, strict=True)
    assert positive("1,2.5,1e-3") == [1.0, 2.5, 0.001]
    assert finite_floats(0.0)("0,3") == [0.0, 3.0]  # not strict: the bound itself is allowed
    for text in ("1,x", "0", "2,-1", "nan", "1,inf", "", "1,,2"):
        with pytest.raises(argparse.ArgumentTypeError, match="finite number > 0"):
            positive(text)
