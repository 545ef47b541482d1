"""Benchmark records carry their provenance; the at-commit helper installs one commit whole."""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from mjcodesign.bench import BENCHMARKS, run_benchmark
from mjcodesign.bench.record import provenance

ROOT = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout


def test_provenance_names_the_installed_code_and_the_machine():
    rec = provenance("finger", command="mjcodesign bench finger --json")
    assert rec["benchmark"] == "finger" and rec["command"] == "mjcodesign bench finger --json"
    assert rec["date"].endswith("+00:00")
    assert rec["machine"]["cpu_count"] >= 1 and len(rec["load_average"]) == 3
    inst = rec["installed"]
    assert Path(inst["package_dir"]) == Path(__import__("mjcodesign").__file__).resolve().parent
    if shutil.which("git") and (ROOT / ".git").exists() and inst["source"] is None:
        assert inst["commit"] == _git("rev-parse", "HEAD").strip()


def test_run_benchmark_writes_the_provenance_into_the_record(tmp_path, monkeypatch):
    monkeypatch.setitem(BENCHMARKS, "echo", "json:loads")  # a benchmark that returns what it is given
    out = tmp_path / "rec.json"
    res = run_benchmark("echo", out=out, command="mjcodesign bench echo", s='{"ratio": 0.5}')
    on_disk = json.loads(out.read_text())
    assert res == on_disk and on_disk["ratio"] == 0.5
    assert on_disk["provenance"]["command"] == "mjcodesign bench echo"


@pytest.mark.slow
@pytest.mark.skipif(not (ROOT / ".git").exists() or not shutil.which("git"), reason="needs the git checkout")
def test_at_commit_imports_every_root_package_from_that_commit(tmp_path):
    # The installed wheel imports all four root packages from the virtual environment, and `bench
    # calibration` finds its FEM references as package data there (not through the checkout).
    code = (
        "import json, mjcodesign, mjcodesign.viz, mjcodesign.surrogate, mjcodesign.hardware; "
        "print(json.dumps([m.__file__ for m in (mjcodesign, mjcodesign.viz, mjcodesign.surrogate, "
        "mjcodesign.hardware)]))"
    )
    cal = tmp_path / "calibration.json"
    script = (
        f"mjcodesign bench calibration --models chain --designs semi-rigid --out {shlex.quote(str(cal))} "
        f">/dev/null && python3 -c {shlex.quote(code)}"
    )
    out = subprocess.run(
        [str(ROOT / "scripts" / "at-commit"), "HEAD", "bash", "-c", script],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    if out.returncode != 0 and "pip" in out.stderr and "network" in out.stderr.lower():
        pytest.skip("no package index to build the wheel")
    assert out.returncode == 0, out.stderr[-2000:]
    files = json.loads(out.stdout.strip().splitlines()[-1])
    assert all("/venv/" in f and str(ROOT) not in f for f in files), files
    refs = json.loads(cal.read_text(encoding="utf-8"))["references"].values()
    assert refs and all("/venv/" in r["file"] and str(ROOT) not in r["file"] for r in refs), refs
