"""Where tasks run: in this process, in a pool of processes, or as Ray remote tasks.

Each executor takes tasks (``"prepare"`` an :class:`~mjcodesign.data.tasks.ObjectTask`, or ``"run"`` a
list of :class:`~mjcodesign.data.tasks.ShardTask`), runs at most :attr:`slots` at a time, and hands
back finished ones with their result or exception. A process keeps one
:class:`~mjcodesign.data.tasks.Worker` (objects, compiled scenes, simulator) for all its tasks.

* :class:`InlineExecutor`: runs a task when it is submitted (``--workers 1`` on MJWarp or one core).
* :class:`ThreadExecutor`: a thread per core in this process (``--workers 1`` on MuJoCo C).
* :class:`PoolExecutor`: ``concurrent.futures.ProcessPoolExecutor`` with the ``spawn`` context (no
  fork of a process holding MuJoCo's and Warp's threads); each worker runs ``cores // workers``
  MuJoCo threads and exits when its parent dies, so a killed run leaves no worker behind.
* :class:`RayExecutor`: Ray remote tasks with ``max_retries`` (the task of a worker or node that died is
  rerun on what is left of the cluster), taken with ``ray.wait``; a task Ray gives up on stops the run
  with :class:`~mjcodesign.errors.ClusterError`. ``ray`` is imported only here, when one is made.

:func:`check_ray_address` refuses a ``--ray`` value that cannot be joined (its form, then a TCP
connection to the head) before any work, in seconds rather than Ray's minutes of retries.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import logging
import multiprocessing
import os
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures.process import BrokenProcessPool

from mjcodesign.data.tasks import Worker
from mjcodesign.errors import ClusterError, DesignError

__all__ = [
    "InlineExecutor",
    "PoolExecutor",
    "RayExecutor",
    "ThreadExecutor",
    "check_ray_address",
    "cpu_count",
    "execute",
    "parse_ray_address",
]

_RAY_RETRIES = 3  # reruns of a task whose worker process or node died
_PARENT_POLL_S = 0.5  # how often a pool worker checks that its parent is alive
_RAY_OBJECT_STORE = 256 * 1024 * 1024  # [bytes] a local Ray's object store (results are small)
# [s] TCP connect to a cluster's head before Ray is asked: as long as Ray's own first gRPC connect
# (RAY_gcs_rpc_server_connect_timeout_s, 5 s), after which Ray retries for about 14 minutes.
_RAY_CONNECT_S = 5.0
_RAY_ADDRESS_FORM = "'local' or a Ray head's HOST:PORT (the address `ray start --head` prints)"

_worker: Worker | None = None  # this process's worker (pool and Ray processes)
_setup_done = False


def cpu_count() -> int:
    """Cores this process may run on."""
    return len(os.sched_getaffinity(0))


def execute(kind: str, payload, worker: Worker):
    """Run one task on ``worker``: ``prepare`` an object or ``run`` a list of shards."""
    if kind == "prepare":
        return worker.prepare(payload)
    if kind == "run":
        return worker.run(payload)
    raise ValueError(f"unknown task kind {kind!r}")


class _Done:
    """A finished task of the inline executor."""

    def __init__(self, result=None, error: BaseException | None = None):
        self.result, self.error = result, error


class InlineExecutor:
    """Runs each task in this process when it is submitted; MuJoCo uses every core."""

    slots = 1

    def __init__(self, device: str = "cpu"):
        self.worker = Worker(nthread=cpu_count(), device=device)

    def submit(self, kind: str, payload) -> _Done:  # noqa: D102
        try:
            return _Done(execute(kind, payload, self.worker))
        except Exception as exc:  # handed to the caller as a pool would
            return _Done(error=exc)

    def wait(self, handles: list) -> list[tuple[object, object, BaseException | None]]:  # noqa: D102
        return [(h, h.result, h.error) for h in handles]

    def close(self) -> None:  # noqa: D102
        pass


def _wait_futures(handles: list) -> list[tuple[object, object, BaseException | None]]:
    """The futures that finished first, as (future, result, error); a broken process pool is raised."""
    done, _ = cf.wait(handles, return_when=cf.FIRST_COMPLETED)
    out = []
    for f in done:
        err = f.exception()
        if isinstance(err, BrokenProcessPool):
            raise err
        out.append((f, None if err else f.result(), err))
    return out


class ThreadExecutor:
    """``threads`` threads in this process, each rollout on one MuJoCo thread (``--workers 1`` on MuJoCo C).

    A rollout releases the GIL, so one thread's Python work (model copies, outcome replays) overlaps
    another's rollout instead of leaving a core idle, as it does between the batches of one worker on
    every core. The threads share one :class:`Worker`, so each object is loaded and each scene compiled
    once. Object preparation (Warp's SDF kernels) runs one task at a time. A shard's rows do not
    depend on which thread runs it, so the dataset is the same as the other executors'.
    """

    def __init__(self, threads: int, device: str = "cpu", slots: int | None = None):
        self.slots = slots or 2 * threads
        self.device = device
        self.worker = Worker(nthread=1, device=device)
        self._prepare = threading.Lock()
        self.pool = cf.ThreadPoolExecutor(max_workers=threads, thread_name_prefix="datagen")

    def _run(self, kind: str, payload):
        if kind == "prepare":
            with self._prepare:
                return execute(kind, payload, self.worker)
        return execute(kind, payload, self.worker)

    def submit(self, kind: str, payload) -> cf.Future:  # noqa: D102
        return self.pool.submit(self._run, kind, payload)

    def wait(self, handles: list) -> list[tuple[object, object, BaseException | None]]:  # noqa: D102
        return _wait_futures(handles)

    def close(self) -> None:  # noqa: D102
        self.pool.shutdown(wait=True, cancel_futures=True)


def _init_pool_worker(nthread: int, device: str, setup: Callable[[], None] | None, parent: int) -> None:
    global _worker
    _worker = Worker(nthread=nthread, device=device)
    if setup is not None:
        setup()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(_PARENT_POLL_S)
        os._exit(1)  # the driver died (e.g. kill -9): stop computing shards nobody will write

    threading.Thread(target=watch, daemon=True).start()


def _pool_task(kind: str, payload):
    return execute(kind, payload, _worker)


class PoolExecutor:
    """``workers`` spawned processes; ``slots`` tasks in flight (default twice the workers)."""

    def __init__(
        self,
        workers: int,
        *,
        device: str = "cpu",
        setup: Callable[[], None] | None = None,
        slots: int | None = None,
    ):
        self.slots = slots or 2 * workers
        nthread = max(1, cpu_count() // workers)
        self.pool = cf.ProcessPoolExecutor(
            max_workers=workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_pool_worker,
            initargs=(nthread, device, setup, os.getpid()),
        )

    def submit(self, kind: str, payload) -> cf.Future:  # noqa: D102
        return self.pool.submit(_pool_task, kind, payload)

    def wait(self, handles: list) -> list[tuple[object, object, BaseException | None]]:  # noqa: D102
        return _wait_futures(handles)

    def close(self) -> None:  # noqa: D102
        self.pool.shutdown(wait=True, cancel_futures=True)


def _ray_task(kind: str, payload, device: str, setup: Callable[[], None] | None):
    global _worker, _setup_done
    if not _setup_done and setup is not None:
        setup()
    _setup_done = True
    if _worker is None:
        _worker = Worker(nthread=1, device=device)
    return execute(kind, payload, _worker)


def parse_ray_address(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of a ``--ray`` cluster address ``HOST:PORT`` (``[IPv6]:PORT``); ``None`` for ``"local"``.

    Raises :class:`~mjcodesign.errors.DesignError` for anything else (no port, a port outside
    1-65535, a ``ray://`` Ray Client address, ``auto``, blanks).
    """
    if address == "local":
        return None
    host, sep, port = address.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not sep or not host or not port or any(c.isspace() or c in "/[]" for c in host) or "://" in address:
        raise DesignError(f"--ray takes {_RAY_ADDRESS_FORM}, got {address!r}")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise DesignError(f"--ray {address}: the port must be a number in 1-65535, got {port!r}")
    return host, int(port)


def check_ray_address(address: str, timeout: float = _RAY_CONNECT_S) -> None:
    """Refuse a ``--ray`` value that cannot be joined, before any work.

    ``"local"`` passes. A cluster address must have the form of :func:`parse_ray_address`, and a TCP
    connection to it must open within ``timeout`` seconds (the head's GCS listens there); else
    :class:`~mjcodesign.errors.ClusterError` naming the address and what to check. The host dialled is
    the one Ray dials: Ray replaces ``localhost``, ``127.0.0.1`` and ``::1`` by this machine's outward
    address. A port that answers but is not a Ray head passes here; Ray then refuses it itself.
    """
    parsed = parse_ray_address(address)
    if parsed is None:
        return
    host, port = parsed
    dialled = _ray_dialled_host(host)
    via = "" if dialled == host else f"; Ray dials {dialled} for {host}"
    try:
        with socket.create_connection((dialled, port), timeout=timeout):
            pass
    except socket.gaierror as exc:
        raise ClusterError(
            f"--ray {address}: cannot resolve host {host!r} ({exc.strerror}); check the head's name, "
            "or give its IP address"
        ) from None
    except OSError as exc:
        why = f"no answer within {timeout:g} s" if isinstance(exc, TimeoutError) else exc.strerror or exc
        raise ClusterError(
            f"--ray {address}: no Ray head answers there ({why}{via}); check that "
            f"`ray start --head --port {port}` runs on {host} and that this machine can reach that port"
        ) from None


@contextlib.contextmanager
def _stderr_held() -> Iterator[None]:
    """Hold what is written to file descriptor 2 in the block; hand it on to stderr only if it succeeds.

    Ray's C++ GCS client writes its connection warnings straight to the descriptor, past Python's
    ``sys.stderr``, so a cluster it cannot join would print them ahead of the command's one error line.
    """
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        ok = False
        try:
            yield
            ok = True
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            if ok:
                held.seek(0)
                text = held.read()
                if text:
                    os.write(2, text)


def _ray_dialled_host(host: str) -> str:
    """The host Ray connects to for ``host`` (this machine's outward address for a loopback name)."""
    try:
        from ray._private.services import resolve_ip_for_localhost
    except ImportError:  # no ray (the executor will say so), or another Ray layout: the host as given
        return host
    return resolve_ip_for_localhost(host)


class RayExecutor:
    """Tasks as Ray remote tasks (one CPU and one MuJoCo thread each), at most ``slots`` in flight.

    ``address``: ``"local"`` starts a Ray instance on this machine with ``num_cpus`` CPUs, whatever
    ``RAY_ADDRESS`` says (its addresses are loopback only when the caller set
    ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``); ``HOST:PORT`` is the head of a running cluster, which
    this joins once :func:`check_ray_address` passes; a cluster Ray cannot join raises
    :class:`~mjcodesign.errors.ClusterError`. A task whose worker or node
    dies is rerun (up to three times) wherever the cluster has a free CPU, and waits for one while it
    has none; a task Ray still loses raises :class:`~mjcodesign.errors.ClusterError` from ``wait``
    (the shards written before it are kept).
    """

    def __init__(
        self,
        address: str,
        *,
        num_cpus: int | None = None,
        device: str = "cpu",
        setup: Callable[[], None] | None = None,
        slots: int | None = None,
    ):
        import ray

        self.ray = ray
        if address == "local":
            ray.init(
                address="local",  # a new instance: Ray would join RAY_ADDRESS's cluster for None
                num_cpus=num_cpus or cpu_count(),
                include_dashboard=False,
                log_to_driver=False,
                object_store_memory=_RAY_OBJECT_STORE,
                logging_level=logging.WARNING,  # not "Started a local Ray instance." under the progress bar
                _node_ip_address="127.0.0.1",
            )
        else:
            check_ray_address(address)
            try:
                with _stderr_held():  # Ray's own retry warnings, for a port that is no Ray head
                    try:
                        ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
                    except BaseException:
                        ray.shutdown()
                        raise
            except (ConnectionError, RuntimeError, TimeoutError) as exc:  # answers, but is no Ray head
                first = (str(exc).strip().splitlines() or [""])[0]
                raise ClusterError(
                    f"--ray {address}: Ray could not join a cluster there ({type(exc).__name__}: {first}); "
                    "check that the port is the head's GCS port (`ray start --head --port`) and, with "
                    "token authentication, that RAY_AUTH_TOKEN is the cluster's"
                ) from exc
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.slots = slots or 2 * cpus
        self._remote = ray.remote(num_cpus=1, max_retries=_RAY_RETRIES, retry_exceptions=False)(_ray_task)
        self._device, self._setup = device, setup

    def submit(self, kind: str, payload):  # noqa: D102
        return self._remote.remote(kind, payload, self._device, self._setup)

    def wait(self, handles: list) -> list[tuple[object, object, BaseException | None]]:  # noqa: D102
        ray = self.ray
        done, _ = ray.wait(handles, num_returns=1)
        out = []
        for ref in done:
            try:
                out.append((ref, ray.get(ref), None))
            except ray.exceptions.RayTaskError as exc:
                cause = exc.cause if isinstance(exc.cause, Exception) else exc
                out.append((ref, None, cause))
            except ray.exceptions.RayError as exc:  # the cluster lost it: a dead node, retries spent
                first = (str(exc).strip().splitlines() or [""])[0]
                raise ClusterError(
                    f"Ray lost a task ({type(exc).__name__}: {first}); the shards written are kept: "
                    "rerun the same command with --resume once the cluster is whole"
                ) from exc
        return out

    def close(self) -> None:  # noqa: D102
        self.ray.shutdown()
