"""The benchmark page's figures: every image it embeds exists, and each drawn figure names a real record.

``scripts/benchmark_figures.py`` draws the PNGs of ``docs/_static/benchmarks/`` from
``benchmarks/records/``; these checks read its figure list without drawing all of them again.
"""

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGE = DOCS / "benchmarks.md"
_MAX_BYTES = 150 * 1024  # images stay small enough for the repository and a page load
# Markdown images ![alt](path) and MyST {figure}/{image} directives
_EMBED = re.compile(r"!\[[^\]]*\]\(([^)\s]+)\)|```\{(?:figure|image)\}\s+(\S+)")


@pytest.fixture(scope="module")
def figures(script_module):
    return script_module("benchmark_figures")


def _embedded() -> list[str]:
    return [a or b for a, b in _EMBED.findall(PAGE.read_text())]


def test_every_embedded_image_exists_and_is_small():
    images = _embedded()
    assert images, "docs/benchmarks.md embeds no image"
    for rel in images:
        path = (DOCS / rel).resolve()
        assert path.is_file(), f"docs/benchmarks.md embeds {rel}, which does not exist"
        assert path.stat().st_size <= _MAX_BYTES, f"{rel}: {path.stat().st_size} bytes"


def test_figure_list_names_existing_records_and_every_figure_is_embedded(figures):
    mod = figures
    assert mod.FIGURES
    embedded = {Path(rel).name for rel in _embedded() if Path(rel).parent.name == "benchmarks"}
    for file, (record, draw) in mod.FIGURES.items():
        assert (mod.RECORDS / record).is_file(), f"{file} reads {record}, which is not a record"
        assert callable(draw)
        assert (mod.OUT / file).is_file(), f"{file} is listed but not drawn: run scripts/benchmark_figures.py"
        assert file in embedded, f"{file} is drawn but docs/benchmarks.md does not embed it"
    assert set(embedded) == set(mod.FIGURES), "an image under _static/benchmarks/ is embedded but not drawn"


def test_footer_names_record_commit_and_date(figures):
    mod = figures
    for record, _ in mod.FIGURES.values():
        _, prov = mod.load(record)
        line = mod.footer(record, prov)
        assert record in line
        assert "not recorded" not in line, f"{record}: {line}"
        assert re.search(r"commit [0-9a-f]{7} · \d{4}-\d{2}-\d{2}", line), line


def test_load_reads_both_record_layouts(figures, tmp_path, monkeypatch):
    mod = figures
    (tmp_path / "nested.json").write_text(json.dumps({"provenance": {"date": "d"}, "record": {"x": 1}}))
    (tmp_path / "flat.json").write_text(json.dumps({"provenance": {"date": "d"}, "x": 2}))
    monkeypatch.setattr(mod, "RECORDS", tmp_path)
    assert mod.load("nested.json") == ({"x": 1}, {"date": "d"})
    assert mod.load("flat.json") == ({"x": 2}, {"date": "d"})


def test_one_figure_renders(figures, tmp_path):
    pytest.importorskip("matplotlib")
    mod = figures
    record, draw = mod.FIGURES["finger_speed.png"]
    path = draw(record, tmp_path / "finger_speed.png")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) <= _MAX_BYTES
