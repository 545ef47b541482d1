import json
import subprocess
import sys

import pytest


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
    assert m.ntendon == 2 and m.nu == 5
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
    assert bench.run_benchmark("toy", out=out, s='{"a": [1, 2]}') == {"a": [1, 2]}
    assert json.loads(out.read_text()) == {"a": [1, 2]}
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
