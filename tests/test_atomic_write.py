"""The one atomic file writer (mjcodesign.outputs.write_atomic), the writers built on it, and the figures."""

import json

import pytest

from mjcodesign.errors import OutputError
from mjcodesign.outputs import TMP_SUFFIX, write_atomic


def test_writes_text_and_bytes_and_replaces_whole(tmp_path):
    path = tmp_path / "a.json"
    assert write_atomic(path, json.dumps({"x": "é"})) == path
    assert json.loads(path.read_text(encoding="utf-8")) == {"x": "é"}
    write_atomic(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]  # no temporary file left


@pytest.mark.parametrize("case", ["folder", "missing_parent"])
def test_a_failed_write_leaves_the_target_and_no_temporary(tmp_path, case):
    if case == "folder":  # the rename onto a folder fails after the data is written
        target = tmp_path / "out"
        target.mkdir()
        (target / "keep").write_text("old")
    else:
        target = tmp_path / "nowhere" / "out.json"
    with pytest.raises(OutputError, match="cannot write"):
        write_atomic(target, "new")
    if case == "folder":
        assert (target / "keep").read_text() == "old"
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(TMP_SUFFIX)]


def test_bench_json_goes_through_it(tmp_path, monkeypatch):
    import mjcodesign.outputs as outputs
    from mjcodesign.bench import write_json

    seen = []
    real = outputs.write_atomic

    def spy(path, data):
        seen.append(path)
        return real(path, data)

    monkeypatch.setattr("mjcodesign.bench.write_atomic", spy)
    write_json({"a": 1}, tmp_path / "b.json")
    assert seen == [tmp_path / "b.json"] and json.loads((tmp_path / "b.json").read_text()) == {"a": 1}


def test_figure_writers_leave_pyplot_and_the_backend_alone(tmp_path):
    """Library figures are bare Figures written through write_atomic: the process's backend stays as the
    program set it, and pyplot is never imported (a library must not touch either)."""
    import subprocess
    import sys

    script = f"""
import sys
from pathlib import Path
import matplotlib
matplotlib.use("svg")
from mjcodesign.crosscheck.plot import plot_curves as curl
from mjcodesign.surrogate.plots import plot_calibration, plot_curves, plot_lines

out = Path({str(tmp_path)!r})
curl({{"chain": {{"tension": [0.0, 1.0], "bend": [0.0, 0.1], "tip": [[0.0, 0.0, 0.01]]}}}}, str(out / "curl.png"))
plot_curves({{"full": {{"train_loss": [2.0, 1.0], "val_loss": [2.5, 1.5], "best_epoch": 1}}}}, out / "curves.png")
plot_calibration({{"net": [{{"predicted": 0.2, "observed": 0.3}}, {{"predicted": 0.8, "observed": 0.7}}]}}, out / "cal.png")
line = {{"object": "box", "pose_row": 0, "line": 0, "t": [0.0, 1.0], "simulator_loss": [1.0, 2.0],
        "surrogate_loss": [1.1, 1.9]}}
plot_lines({{"lines": [line]}}, out / "lines.png")
print(matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["svg", "False"]
    for name in ("curl.png", "curves.png", "cal.png", "lines.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal.png", "curl.png", "curves.png", "lines.png"]
