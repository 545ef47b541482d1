import importlib.util
import os
import signal
import sys
from pathlib import Path

import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

# A suite started as a background job of a script (`cmd &` without job control, nohup) inherits SIGINT
# ignored, and an ignored signal stays ignored across exec: every command a test starts would then
# ignore the SIGINT the test sends it (a view waiting out its 30 s, a grasp run never interrupted).
# Python's own handler is caught, not ignored, so children start with SIGINT at its default again, as
# from an interactive shell.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
REFERENCE = SHARED / "reference" / "codesign-soft-gripper"


@pytest.fixture
def reference_dir():
    if not REFERENCE.is_dir():
        pytest.skip("shared/reference/codesign-soft-gripper is absent")
    return REFERENCE


SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


@pytest.fixture(scope="session")
def script_module():
    """A loader of ``scripts/NAME.py`` as a module (registered in ``sys.modules`` for its dataclasses)."""
    loaded = []

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        loaded.append(name)
        spec.loader.exec_module(mod)
        return mod

    yield load
    for name in loaded:
        sys.modules.pop(name, None)


@pytest.fixture(scope="module")
def one_torch_thread():
    """torch on one thread for a module's tests (a shared 2-core machine: a second thread mostly waits)."""
    torch = pytest.importorskip("torch")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="session")
def tiny_checkpoint(tmp_path_factory):
    """A tiny surrogate trained here on a small generated dataset (two shapes, 2 poses x 6 designs)."""
    torch = pytest.importorskip("torch")
    import trimesh

    from mjcodesign.data import DatagenConfig, generate, parse_density_spec
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.surrogate import (
        ModelConfig,
        OptimizerConfig,
        Surrogate,
        TrainConfig,
        load_grasp_data,
        save_checkpoint,
        split,
        train,
    )

    work = tmp_path_factory.mktemp("tiny_surrogate")
    files = []
    for name, mesh in {
        "box": trimesh.creation.box(extents=(0.05, 0.04, 0.06)),
        "ball": trimesh.creation.icosphere(radius=0.03),
    }.items():
        mesh.export(work / f"{name}.stl")
        files.append(str(work / f"{name}.stl"))
    scenario = GraspScenario(impulse=0.0, tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.02)
    cfg = DatagenConfig(
        objects=tuple(files),
        poses_per_object=2,
        designs_per_pose=6,
        density=parse_density_spec("uniform:100,400"),
        scenario=scenario,
        tension=scenario.tension,
    )
    generate(cfg, work / "ds", workers=1, cache_dir=work / "cache")
    data = load_grasp_data(work / "ds")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        result = train(
            data,
            split(data, "random", seed=0),
            TrainConfig(
                epochs=5, batch_size=16, optimizer=OptimizerConfig(lr=1e-2), early_stop_patience=5, seed=0
            ),
            ModelConfig(point_widths=(8, 16), hidden=16, depth=2, penultimate=8, dropout=0.0),
        )
    finally:
        torch.set_num_threads(n)
    meta = {
        "dataset": {
            "density": {"low_kg_m3": 100.0, "high_kg_m3": 400.0},
            "object_seed": 0,
            "cloud_points": 256,
        }
    }
    sur = Surrogate(
        result.model, result.normalizer, lift=data.lift, lifted_fraction=data.lifted_fraction, meta=meta
    )
    return save_checkpoint(work / "ckpt", sur)


# The suite's own long-lived helpers, which end with the pytest process itself.
_SUITE_HELPERS = ("multiprocessing.resource_tracker", "multiprocessing.forkserver")
_LEFTOVER_WAIT_S = 15.0  # a process the suite started gets this long after the last test to end [s]
_PR_SET_CHILD_SUBREAPER = 36  # prctl(2): orphans of our descendants become our children (Linux)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")[:200]
    except OSError:
        return ""


def child_pids(pid: int | None = None) -> set[int]:
    """The processes ``pid`` (default: this one) started that are still its children, from every thread's
    ``/proc/PID/task/TID/children`` list (Linux); a thread that ends while read is passed over."""
    kids = set()
    for task in Path(f"/proc/{os.getpid() if pid is None else pid}/task").glob("*"):
        try:
            kids |= {int(k) for k in (task / "children").read_text().split()}
        except OSError:
            continue
    return kids


@pytest.fixture
def children():
    """:func:`child_pids` for a test: ``children()`` this process's children, ``children(pid)`` another's."""
    return child_pids


def _running_children() -> set[int]:
    """This process's children that are running (zombies reaped), not the suite's own helpers."""
    running = set()
    for pid in child_pids():
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state == "Z":
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass
        elif not any(h in _cmdline(pid) for h in _SUITE_HELPERS):
            running.add(pid)
    return running


@pytest.fixture(scope="session", autouse=True)
def no_process_outlives_the_suite():
    """After the last test, no process the suite started is still running.

    The pytest process becomes a child subreaper, so a process orphaned by its parent (a viewer left
    behind by a killed command, a daemon) is re-parented here rather than to init, and is seen. Any
    still running after :data:`_LEFTOVER_WAIT_S` is named, killed, and fails the suite.
    """
    import sys
    import time

    if not (sys.platform.startswith("linux") and Path("/proc/self/task").exists()):
        yield
        return
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
    before = _running_children()
    yield
    deadline = time.monotonic() + _LEFTOVER_WAIT_S
    while (left := _running_children() - before) and time.monotonic() < deadline:
        time.sleep(0.1)
    named = {pid: _cmdline(pid) for pid in left}
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    assert not named, f"processes the suite started outlived it (killed now): {named}"
