"""The command line's error handler: one line whatever the name, the environment or the output stream."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_TIMEOUT_S = 120


def _run(args, cwd, *, env=None, stdout=subprocess.PIPE):
    paths = [str(ROOT), os.environ.get("PYTHONPATH", "")]
    full = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p), **(env or {})}
    cmd = [sys.executable, "-m", "mjcodesign.cli", *args]
    return subprocess.run(cmd, cwd=cwd, env=full, stdout=stdout, stderr=subprocess.PIPE, timeout=_TIMEOUT_S)


def _one_error_line(r) -> str:
    err = r.stderr.decode(errors="replace")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert r.returncode == 2, err[-1500:]
    assert "Traceback" not in err and len(lines) == 1, err[-1500:]
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    import trimesh

    path = tmp_path_factory.mktemp("errors") / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(path)
    return path


def test_a_newline_in_a_path_stays_on_the_error_line(tmp_path):
    line = _one_error_line(_run(["grasp", "--object", "a\nb\tc.stl"], tmp_path))
    assert "a\\nb\\tc.stl" in line


def test_a_full_stdout_is_one_error_line(box, tmp_path):
    with open("/dev/full", "wb") as full:
        r = _run(["grasp", "--object", str(box), "--json"], tmp_path, stdout=full)
    assert "no space left" in _one_error_line(r).lower()


def test_an_unknown_mujoco_gl_does_not_stop_a_command_that_renders_nothing(box, tmp_path):
    r = _run(["grasp", "--object", str(box), "--json"], tmp_path, env={"MUJOCO_GL": "bogus"})
    assert r.returncode == 0, r.stderr.decode()[-1500:]
    assert b'"success"' in r.stdout


def test_a_file_name_that_is_not_utf8_is_read(box, tmp_path):
    name = os.fsdecode(b"\xff\xfebox.stl")  # not UTF-8: held as surrogate escapes
    (tmp_path / name).write_bytes(box.read_bytes())
    r = _run(["grasp", "--object", name, "--json"], tmp_path, env={"LC_ALL": "C"})
    assert r.returncode == 0, r.stderr.decode(errors="replace")[-1500:]
    (tmp_path / "bôx.stl").write_bytes(box.read_bytes())
    r = _run(["grasp", "--object", "bôx.stl", "--json"], tmp_path, env={"LC_ALL": "C"})
    assert r.returncode == 0, r.stderr.decode(errors="replace")[-1500:]


def test_datagen_names_each_object_it_left_out(tmp_path, capsys):
    # A run that leaves an object out says so on stderr, not only as a count in its JSON.
    import json

    from mjcodesign.cli.common import warn_failed_objects

    objects = [
        {"index": 0, "source": "good.stl", "status": "ready"},
        {
            "index": 1,
            "source": "broken\nname.stl",
            "status": "failed",
            "error": "MeshError: mesh file is empty",
        },
    ]
    (tmp_path / "manifest.json").write_text(json.dumps({"objects": objects}))
    assert warn_failed_objects(tmp_path) == 1
    err = capsys.readouterr().err.splitlines()
    assert err == ["warning: object broken\\nname.stl left out: MeshError: mesh file is empty"]
    assert warn_failed_objects(tmp_path / "none") == 0


@pytest.mark.parametrize(
    ("result", "where"),
    [
        ({"a": 1.0, "b": {"c": [0.5, float("nan")]}}, "b.c[1]"),
        ([{"x": 1}, {"x": float("inf")}], "[1].x"),
        (float("-inf"), "the top level"),
    ],
)
def test_json_output_refuses_nan_and_infinity_naming_where(result, where, capsys):
    # No command prints a NaN token as JSON: the result is refused, naming the first bad value.
    from mjcodesign.cli.common import emit
    from mjcodesign.errors import OutputError

    with pytest.raises(OutputError, match=f"at {re.escape(where)}:"):
        emit(result, True)
    assert capsys.readouterr().out == ""
    emit({"a": 1.0, "b": [2, "nan"]}, True)  # finite numbers and the string "nan" print as they are
    assert capsys.readouterr().out.strip() == '{"a": 1.0, "b": [2, "nan"]}'
