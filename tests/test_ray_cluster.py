"""``datagen --ray ADDRESS`` on a two-node Ray cluster that loses a node mid-run.

A head node and a second node, each with one CPU, are started with ``ray start`` on this machine;
``mjcodesign datagen --ray HEAD`` runs across both as a subprocess whose progress lines are read from a
pipe. Once a shard is written and the second node's worker is running a task, its raylet is killed
with SIGKILL, and so is that worker (a machine that dies takes both). The task lost with them is retried
on the head, the run finishes, and the dataset equals the single-process reference: the same Parquet tables, bitwise but
``wall_time_s``, every (object, pose, design) once.

The other tests check what is refused or redirected before any work: a ``--ray`` address of the wrong
form, a cluster nobody answers for (refused in seconds, no folder made, a dataset being resumed left as
it was), and ``--ray local`` with ``RAY_ADDRESS`` set (a local Ray all the same).

The nodes bind 127.0.0.2 and 127.0.0.3, loopback addresses: Ray replaces 127.0.0.1 in a node's or a
cluster's address by the machine's outward address whenever it may form a multi-node cluster. A
random token (``RAY_AUTH_MODE=token``) keeps anyone else out of the cluster. The test ends what it
started, each node's process group and the workers under it, not with ``ray stop``, which would end
every Ray on the machine.
"""

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pyarrow as pa
import pytest

HEAD_IP, NODE_IP = "127.0.0.2", "127.0.0.3"
_START_S = 90.0  # [s] `ray start` of one node (5-12 s measured on the shared 2-core machine)
_RUN_S = 240.0  # [s] the datagen run on the cluster (10-15 s measured)
_KILL_S = 120.0  # [s] until a shard is written and the second node runs a task
_POLL_S = 0.02  # [s] how often the test looks at the run's lines and the node's workers
_GONE_S = 15.0  # [s] for a killed process to be gone
# [s] an unreachable --ray refused, interpreter start included (about 2 s measured; Ray alone would
# retry for about 14 minutes)
_REFUSE_S = 60.0
_OBJECT_STORE = 100 * 1024 * 1024  # [bytes] each node's object store (Ray's minimum is 75 MiB)
# A small dataset: a 50 mm box and two egad-like shapes, 4 poses x 2 designs, a shortened grasp.
_SCENARIO = '{"impulse": 0.0, "tighten_s": 0.1, "lift_s": 0.2, "hold_s": 0.1, "post_hold_s": 0.02}'


def _free_port(host: str) -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _table() -> dict[int, tuple[int, int, str]]:
    """The live processes: pid -> (parent pid, process group, command line)."""
    out = {}
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if fields[0] != "Z":
            out[int(proc.name)] = (int(fields[1]), int(fields[3]), cmd)
    return out


class _Cluster:
    """Ray nodes started with ``ray start``, each in a process group of its own.

    A node's daemons (GCS, raylet, agents) keep the group of its ``ray start``; its workers have groups
    of their own but are the raylet's children, or, once it is killed, this process's (a subreaper).
    The temp dirs are under a short ``/tmp/mjc-ray-*``: Ray's socket paths (``DIR/session_<date>_<pid>/
    sockets/plasma_store``) must fit AF_UNIX's 108 characters, which pytest's ``tmp_path`` would not.
    """

    def __init__(self, env: dict[str, str]):
        self.env = {k: v for k, v in env.items() if not k.startswith("RAY_")}
        token = secrets.token_hex(32)  # only this test's processes can join the cluster
        self.env |= {"RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": token}
        self.root = Path(tempfile.mkdtemp(prefix="mjc-ray-", dir="/tmp"))
        self.groups: dict[str, int] = {}  # node name -> its process group
        self.port = _free_port(HEAD_IP)
        self.address = f"{HEAD_IP}:{self.port}"

    def start(self, name: str, ip: str, *, head: bool) -> None:
        """``ray start`` a node with one CPU at ``ip`` (the head, or one joining it); returns once it runs."""
        where = (
            ["--head", "--port", str(self.port), "--include-dashboard", "false"]
            + ["--ray-client-server-port", str(_free_port(ip))]
            if head
            else ["--address", self.address]
        )
        argv = [
            sys.executable,  # `ray start` with this interpreter's Ray (the `ray` command's entry point)
            "-m",
            "ray.scripts.scripts",
            "start",
            *where,
            "--node-ip-address",
            ip,
            "--num-cpus",
            "1",
            "--object-store-memory",
            str(_OBJECT_STORE),
            "--dashboard-agent-listen-port",
            str(_free_port(ip)),
            "--temp-dir",
            str(self.root / name),
            "--disable-usage-stats",
        ]
        proc = subprocess.Popen(
            argv, env=self.env, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
        )
        self.groups[name] = proc.pid
        out, _ = proc.communicate(timeout=_START_S)
        assert proc.returncode == 0, out.decode(errors="replace")[-3000:]

    def raylet(self, name: str) -> int:
        """The pid of node ``name``'s raylet."""
        group = self.groups[name]
        (pid,) = [p for p, (_, g, cmd) in _table().items() if g == group and "/raylet/raylet " in cmd]
        return pid

    @staticmethod
    def busy_workers(raylet: int) -> list[int]:
        """The workers of ``raylet`` running one of datagen's tasks (Ray titles a worker by its task)."""
        return [
            p for p, (pp, _, cmd) in _table().items() if pp == raylet and cmd.startswith("ray::_ray_task")
        ]

    def processes(self) -> dict[int, str]:
        """The live processes of the cluster: its nodes' groups, their descendants, and orphaned workers."""
        table = _table()
        ours = {p for p, (pp, g, cmd) in table.items() if g in self.groups.values()}
        ours |= {p for p, (pp, _, cmd) in table.items() if pp == os.getpid() and cmd.startswith("ray::")}
        while more := {p for p, (pp, _, _) in table.items() if pp in ours} - ours:
            ours |= more
        return {p: table[p][2] for p in ours}

    def close(self, children) -> dict[int, str]:
        """SIGKILL every process of the cluster, reap ``children()`` (our zombies, and those re-parented
        to this subreaper); the processes still alive after :data:`_GONE_S` (pid -> command line)."""
        deadline = time.monotonic() + _GONE_S
        while (alive := self.processes()) and time.monotonic() < deadline:
            for pid in alive:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            time.sleep(0.1)
        for pid in children():
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass
        shutil.rmtree(self.root, ignore_errors=True)
        return alive


def _lines(stream, into: list[tuple[float, str]]) -> None:
    for raw in stream:
        into.append((time.monotonic(), raw.decode(errors="replace").rstrip("\n")))


def _tables(root: Path) -> dict[str, pa.Table]:
    from mjcodesign.data import open_dataset

    ds = open_dataset(root)
    return {
        "poses": ds.poses(),
        "samples": ds.samples().drop_columns(["wall_time_s"]),
        "rejected": ds.rejected().drop_columns(["wall_time_s"]),
    }


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="loopback 127.0.0.x and /proc: Linux")
def test_datagen_survives_a_node_killed_mid_run(tmp_path, monkeypatch, children):
    pytest.importorskip("ray")
    import trimesh

    from mjcodesign.cli.main import main
    from mjcodesign.data import open_dataset

    box = tmp_path / "box50.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    cache = tmp_path / "cache"
    argv = [
        "datagen",
        "--objects",
        f"{box},egad-like:1,egad-like:3",
        "--poses-per-object",
        "4",
        "--designs-per-pose",
        "2",
        "--density",
        "uniform:300,500",
        "--scenario",
        _SCENARIO,
    ]
    # The single-process reference, in this process.
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    assert main([*argv, "--out", str(tmp_path / "ref")]) == 0
    ref = _tables(tmp_path / "ref")

    cluster = _Cluster(dict(os.environ))
    run = None
    try:
        cluster.start("head", HEAD_IP, head=True)
        cluster.start("node", NODE_IP, head=False)
        out = tmp_path / "ds"
        summary = tmp_path / "summary.json"  # the run's stdout
        with summary.open("wb") as stdout:
            run = subprocess.Popen(
                [sys.executable, "-m", "mjcodesign.cli", *argv, "--ray", cluster.address, "--out", str(out)],
                env=cluster.env,
                stdout=stdout,
                stderr=subprocess.PIPE,
            )
        lines: list[tuple[float, str]] = []  # (when, line) of the run's stderr
        reader = threading.Thread(target=_lines, args=(run.stderr, lines), daemon=True)
        reader.start()
        # Kill the second node's raylet once a shard is written and one of its workers runs a task.
        raylet = cluster.raylet("node")
        deadline = time.monotonic() + _KILL_S
        busy: list[int] = []
        while run.poll() is None and time.monotonic() < deadline and not busy:
            if any(ln.startswith("datagen: shards ") and " 0/" not in ln for _, ln in lines):
                busy = cluster.busy_workers(raylet)
            time.sleep(_POLL_S)
        assert busy, f"the second node ran no task after a shard was written: {[ln for _, ln in lines]}"
        os.kill(raylet, signal.SIGKILL)
        killed_at = time.monotonic()
        # A worker outlives its killed raylet here (> 15 s measured) and could still hand its result to
        # the driver: the workers that ran a task die too, as with the node's machine, so the task is lost.
        for pid in busy:
            os.kill(pid, signal.SIGKILL)
        run.wait(timeout=_RUN_S)
        reader.join(timeout=_GONE_S)
        text = "\n".join(ln for _, ln in lines)
        assert run.returncode == 0 and "Traceback" not in text, text[-3000:]
    finally:
        if run is not None and run.poll() is None:
            run.kill()
            run.wait()
        left = cluster.close(children)
    assert not left, f"processes the test started outlived it: {left}"
    res = json.loads(summary.read_text())  # stdout holds the summary only (Ray's messages: stderr)
    assert res["complete"] and res["shards_failed"] == 0, res
    # The run went on after the kill: shards were written by the head alone.
    after = [ln for t, ln in lines if t > killed_at and ln.startswith("datagen: shards ")]
    assert after, text
    got = _tables(out)
    for name, table in ref.items():
        assert got[name].num_rows == table.num_rows, name
        assert got[name].equals(table), name
    # Every (object, pose, design) once; the manifest's files check out.
    d = got["samples"].select(["object_index", "pose_index", "design_index"]).to_pylist()
    d += got["rejected"].select(["object_index", "pose_index", "design_index"]).to_pylist()
    keys = [tuple(r.values()) for r in d]
    assert len(keys) == len(set(keys)) == ref["poses"].num_rows * 2
    assert not open_dataset(out).verify().damaged


def test_a_task_ray_loses_stops_the_run_with_one_line(monkeypatch):
    ray = pytest.importorskip("ray")
    from mjcodesign.data.executors import RayExecutor
    from mjcodesign.errors import ClusterError

    monkeypatch.setenv("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")  # a local Ray on loopback only
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")

    def die():
        os._exit(1)  # the worker dies as on a lost node; with no retry left, Ray gives the task up

    executor = RayExecutor("local", num_cpus=1)
    try:
        lost = ray.remote(num_cpus=1, max_retries=0)(die).remote()
        with pytest.raises(ClusterError, match="rerun the same command with --resume") as err:
            executor.wait([lost])
        assert "\n" not in str(err.value) and "WorkerCrashedError" in str(err.value)
    finally:
        executor.close()


@pytest.mark.parametrize(
    ("address", "expected"),
    [
        ("local", None),
        ("head:6379", ("head", 6379)),
        ("10.0.0.1:1", ("10.0.0.1", 1)),
        ("[::1]:65535", ("::1", 65535)),
    ],
)
def test_ray_address_forms_accepted(address, expected):
    from mjcodesign.data.executors import parse_ray_address

    assert parse_ray_address(address) == expected


@pytest.mark.parametrize(
    "address",
    [
        "",
        " ",
        "head",
        "head:",
        ":6379",
        "head:0",
        "head:65536",
        "head:x",
        "ray://head:10001",
        "auto",
        "he ad:1",
    ],
)
def test_ray_address_forms_refused(address):
    from mjcodesign.data.executors import parse_ray_address
    from mjcodesign.errors import DesignError

    with pytest.raises(DesignError, match="--ray") as err:
        parse_ray_address(address)
    assert "\n" not in str(err.value)


def _listing(root: Path) -> dict[str, tuple[int, int, bytes]]:
    """Every file under ``root``: relative path -> (mode, mtime [ns], content)."""
    return {
        str(f.relative_to(root)): (f.stat().st_mode, f.stat().st_mtime_ns, f.read_bytes())
        for f in sorted(root.rglob("*"))
        if f.is_file()
    }


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="loopback 127.0.0.2: Linux")
def test_unreachable_cluster_refused_at_once_leaving_folders_as_they_were(tmp_path):
    pytest.importorskip("ray")
    import trimesh

    from mjcodesign.cli.data import datagen_config
    from mjcodesign.cli.main import build_parser
    from mjcodesign.data.store import DatasetDir

    box = tmp_path / "box50.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    address = f"{HEAD_IP}:{_free_port(HEAD_IP)}"  # bound and closed: nothing listens there
    argv = ["datagen", "--objects", str(box), "--poses-per-object", "1", "--designs-per-pose", "1"]
    # A dataset to resume, as datagen leaves one: its manifest and lock.
    existing = tmp_path / "existing"
    config = datagen_config(build_parser().parse_args([*argv, "--out", str(existing)]))
    DatasetDir.open(existing, config, {"command": argv}).close()
    before = _listing(existing)
    assert set(before) == {"manifest.json", ".lock"}
    fresh = tmp_path / "fresh"
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    for out, extra in ((fresh, []), (existing, ["--resume"])):
        t0 = time.monotonic()
        run = subprocess.run(
            [sys.executable, "-m", "mjcodesign.cli", *argv, "--ray", address, "--out", str(out), *extra],
            env=env,
            capture_output=True,
            text=True,
            timeout=_REFUSE_S,
        )
        took = time.monotonic() - t0
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 2 and len(lines) == 1, run.stderr[-3000:]
        assert lines[0].startswith(f"error: --ray {address}: no Ray head answers there"), lines
        assert "ray start --head" in lines[0] and took < _REFUSE_S, (lines, took)
    assert not fresh.exists()
    assert _listing(existing) == before


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="loopback 127.0.0.2: Linux")
def test_a_port_that_answers_but_is_no_ray_head_is_refused_leaving_no_folder(tmp_path):
    pytest.importorskip("ray")
    import trimesh

    box = tmp_path / "box50.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    out = tmp_path / "ds"
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    # Ray's waits shortened for the test (about 42 s at its defaults): 1 s to connect, 1 s for the
    # cluster id.
    env |= {"RAY_gcs_rpc_server_connect_timeout_s": "1", "RAY_py_gcs_connect_timeout_s": "1"}
    with socket.socket() as silent:  # the kernel completes the connection; nothing ever speaks on it
        silent.bind((HEAD_IP, 0))
        silent.listen(8)
        address = f"{HEAD_IP}:{silent.getsockname()[1]}"
        run = subprocess.run(
            [sys.executable, "-m", "mjcodesign.cli", "datagen", "--objects", str(box), "--ray", address]
            + ["--out", str(out)],
            env=env,
            capture_output=True,
            text=True,
            timeout=_REFUSE_S,
        )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr[-3000:]
    # one line: Ray's C++ client's retry warnings (written to the descriptor itself) are not shown
    assert len(lines) == 1, run.stderr[-3000:]
    assert lines[0].startswith(f"error: --ray {address}: Ray could not join a cluster there"), lines[0]
    assert not out.exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="loopback 127.0.0.2: Linux")
def test_ray_local_starts_a_local_ray_whatever_ray_address_says(tmp_path, monkeypatch, capsys):
    pytest.importorskip("ray")
    import trimesh

    from mjcodesign.cli.main import main

    box = tmp_path / "box50.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    elsewhere = f"{HEAD_IP}:{_free_port(HEAD_IP)}"  # no cluster there: joining it could only fail
    monkeypatch.setenv("RAY_ADDRESS", elsewhere)
    for k in ("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "RAY_USAGE_STATS_ENABLED"):  # restored afterwards
        monkeypatch.setenv(k, "0")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    argv = ["datagen", "--objects", str(box), "--poses-per-object", "1", "--designs-per-pose", "1"]
    argv += ["--scenario", _SCENARIO, "--ray", "local", "--out", str(tmp_path / "ds")]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    res = json.loads(out)
    assert res["complete"] and res["ray"] == "local" and res["samples"] + res["rejected"] == 1, res
    note = f"datagen: --ray local starts a Ray on this machine; RAY_ADDRESS={elsewhere} is ignored"
    assert note in err.splitlines()[0], err[-3000:]
    assert "RAY_ADDRESS" not in os.environ  # nothing started by this run can join that address
