"""The one atomic file writer (mjcodesign.outputs.write_atomic) and the writers built on it."""

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
