"""``grasp`` command: JSON output and bad input (exit 2, one line, no traceback).

These run ``python -m mjcodesign.cli grasp``.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

_KEYS = {"success", "body_force", "displacement", "ground_contact", "reason", "wall_time_s"}


def _run(tmp_path, *args, timeout=120):
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", "grasp", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=Path(__file__).resolve().parents[1],
    )


# The paper's regime at its heavy density, no disturbance: a 50 mm box the default design holds (in the
# real regime, at 680 kg/m³, the servo squeezes it out of the top-down pose: docs/regime.md).
_PAPER_HEAVY = ("--regime", "paper", "--density", "heavy", "--impulse", "0")


def _mesh(tmp_path, name, mesh):
    path = tmp_path / name
    mesh.export(path)
    return str(path)


def test_grasp_box_json(tmp_path):
    box = _mesh(tmp_path, "box.stl", trimesh.creation.box(extents=(0.05, 0.05, 0.05)))
    r = _run(tmp_path, "--object", box, *_PAPER_HEAVY, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert _KEYS <= set(out)
    assert out["success"], out["reason"]
    assert len(out["body_force"]) == 6 and len(out["displacement"]) == 3
    assert np.all(np.isfinite(out["body_force"]))


@pytest.mark.parametrize(
    "case",
    ["missing", "broken", "open", "too_big", "bad_design", "below_ground", "bad_density", "folder"],
)
def test_bad_input_exits_2_with_one_line(tmp_path, case):
    box = _mesh(tmp_path, "box.obj", trimesh.creation.box(extents=(0.04, 0.04, 0.04)))
    args = ["--object", box]
    if case == "missing":
        args = ["--object", str(tmp_path / "missing.stl")]
    elif case == "broken":
        bad = tmp_path / "broken.ply"
        bad.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
        args = ["--object", str(bad)]
    elif case == "open":  # a flat sheet: no repair closes it (a bent one is closed by pymeshfix now)
        sheet = trimesh.Trimesh(
            [[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0.05, 0.05, 0]], [[0, 1, 2], [1, 3, 2]]
        )
        args = ["--object", _mesh(tmp_path, "sheet.stl", sheet)]
    elif case == "too_big":
        args = ["--object", _mesh(tmp_path, "big.stl", trimesh.creation.box(extents=(0.04, 0.2, 0.04)))]
    elif case == "bad_design":
        args += ["--design", "1,2,3"]
    elif case == "below_ground":
        pose = tmp_path / "pose.json"
        T = np.eye(4)
        T[2, 3] = 0.05
        pose.write_text(json.dumps({"pose": T.tolist(), "openings": [0.03, 0.03]}))
        args += ["--pose", str(pose)]
    elif case == "bad_density":
        args += ["--density", "feather"]
    elif case == "folder":
        empty = tmp_path / "empty"
        empty.mkdir()
        args = ["--object", str(empty)]
    r = _run(tmp_path, *args, "--json")
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr


def test_folder_runs_every_object_as_a_json_list(tmp_path):
    folder = tmp_path / "objects"
    folder.mkdir()
    _mesh(folder, "a_box.stl", trimesh.creation.box(extents=(0.05, 0.05, 0.05)))
    _mesh(folder, "b_wide.obj", trimesh.creation.box(extents=(0.04, 0.2, 0.04)))  # too big to grasp
    (folder / "empty.obj").write_bytes(b"")  # two objects of one stem: named apart by their suffix
    (folder / "empty.stl").write_bytes(b"")
    (folder / "notes.txt").write_text("not a mesh")
    r = _run(tmp_path, "--object", str(folder), *_PAPER_HEAVY, "--json", timeout=240)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert [o["object"] for o in out] == ["a_box", "b_wide", "empty.obj", "empty.stl"]
    assert all(_KEYS <= set(o) for o in out)
    assert out[0]["success"], out[0]["reason"]
    assert not out[1]["success"] and out[1]["reason"].startswith("error:") and "too big" in out[1]["reason"]
    assert all(not o["success"] and "empty" in o["reason"] for o in out[2:])
    assert len(r.stdout.strip().splitlines()) == 6  # "[", one line per object, "]"


def test_interrupted_folder_prints_what_finished_then_one_line(tmp_path, monkeypatch, capsys):
    """Interrupted while the second object loads: the first one's entry is printed, then the interruption.

    The interruption is the KeyboardInterrupt that Python's SIGINT handler raises, raised here: a
    SIGINT sent to this long-lived process reaches that handler only while the process-wide C-level
    handler and the main thread's signal mask are Python's, which native code in any thread of it can
    change (the run that returned 0 was one where no KeyboardInterrupt arrived).
    """
    from mjcodesign.cli import grasp as cg
    from mjcodesign.cli.main import main

    folder = tmp_path / "objects"
    folder.mkdir()
    for name in ("a_box.stl", "b_box.stl", "c_box.stl"):
        _mesh(folder, name, trimesh.creation.box(extents=(0.05, 0.05, 0.05)))
    prepare = cg._Runner.prepare

    def interrupted_at_b(self, source):
        if source.endswith("b_box.stl"):
            raise KeyboardInterrupt  # what Python's SIGINT handler raises
        return prepare(self, source)

    monkeypatch.setattr(cg._Runner, "prepare", interrupted_at_b)
    monkeypatch.setattr(cg, "user_cache_dir", lambda: tmp_path / "cache")
    code = main(["grasp", "--object", str(folder), *_PAPER_HEAVY, "--json"])
    captured = capsys.readouterr()
    assert code == 130
    out = json.loads(captured.out)
    assert [o["object"] for o in out] == ["a_box"] and out[0]["success"], out
    assert captured.err.strip().splitlines()[-1] == "error: interrupted", captured.err


def test_mjwarp_flex_is_refused_with_one_line(tmp_path):
    pytest.importorskip("mujoco_warp")
    box = _mesh(tmp_path, "box.stl", trimesh.creation.box(extents=(0.05, 0.05, 0.05)))
    r = _run(tmp_path, "--object", box, "--model", "flex", "--backend", "mjwarp", "--json", timeout=240)
    assert r.returncode == 2, (r.stdout, r.stderr)
    # Warp itself may print a CUDA-driver notice on a CPU-only machine; ours is the one error line.
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "flex" in lines[0] and "Traceback" not in r.stderr


def test_mjwarp_cuda_without_a_gpu_exits_2_with_one_line(tmp_path):
    wp = pytest.importorskip("warp")
    pytest.importorskip("mujoco_warp")
    from mjcodesign.optional import import_warp

    import_warp()
    if wp.get_cuda_device_count() > 0:
        pytest.skip("a CUDA device is present")
    box = _mesh(tmp_path, "box.stl", trimesh.creation.box(extents=(0.05, 0.05, 0.05)))
    r = _run(tmp_path, "--object", box, "--backend", "mjwarp", "--device", "cuda", "--json")
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "CUDA" in lines[0] and "Traceback" not in r.stderr


def test_one_warp_device_picker_for_every_command():
    """--device of grasp and datagen: cpu is the CPU, auto is CUDA when Warp finds one, cuda needs one."""
    pytest.importorskip("warp")
    from mjcodesign.errors import UnsupportedError
    from mjcodesign.optional import import_warp, warp_device

    has_cuda = import_warp().get_cuda_device_count() > 0
    assert warp_device("cpu") == "cpu"
    assert warp_device("auto") == ("cuda" if has_cuda else "cpu")
    if has_cuda:
        assert warp_device("cuda") == "cuda"
    else:
        with pytest.raises(UnsupportedError, match="no CUDA device"):
            warp_device("cuda")
    with pytest.raises(UnsupportedError, match="unknown Warp device"):
        warp_device("gpu")


def test_several_designs_load_and_pose_the_object_once(tmp_path, monkeypatch, capsys):
    import argparse

    from mjcodesign import jobs
    from mjcodesign.cli import grasp as cg

    calls = []
    load = jobs.load_object
    monkeypatch.setattr(jobs, "load_object", lambda *a, **k: calls.append(a) or load(*a, **k))
    monkeypatch.setattr(cg, "user_cache_dir", lambda: tmp_path / "cache")
    box = _mesh(tmp_path, "box.stl", trimesh.creation.box(extents=(0.05, 0.05, 0.05)))
    p = argparse.ArgumentParser()
    cg._arguments(p)
    args = p.parse_args(["--object", box, "--design", "soft,semi-rigid", "--impulse", "0", "--json"])
    assert cg.run(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert [o["design"] for o in out] == ["soft", "semi-rigid"]
    assert len(calls) == 1
    assert out[0]["palm_position"] == out[1]["palm_position"]
