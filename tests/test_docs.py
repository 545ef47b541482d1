"""The documentation site builds with warnings as errors, and it covers the CLI, the API and the records.

One ``sphinx-build -W -n`` (nitpicky: every cross-reference must resolve) into a temporary folder,
then checks on its HTML: every subcommand of the parser has its section in the CLI reference, every
name of every package's ``__all__`` is documented, and every record is in the records index with its
provenance. Skips when the documentation's dependencies (the ``docs`` extra) are not installed.
"""

import argparse
import html
import importlib
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

for _mod in ("sphinx", "furo", "myst_parser", "sphinxarg"):
    pytest.importorskip(_mod)

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
_BUILD_TIMEOUT_S = 600  # a cold build takes ~40 s on 2 free cores; a loaded machine several times that
_NOT_DOCUMENTED = {"mjcodesign.cli", "mjcodesign.models_xml"}  # the CLI has its own page; XML only


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("html")
    cmd = [sys.executable, "-m", "sphinx", "-W", "-n", "--keep-going", "-E", "-q", "-b", "html"]
    res = subprocess.run(
        [*cmd, "-d", str(out / ".doctrees"), str(DOCS), str(out)],
        capture_output=True,
        text=True,
        timeout=_BUILD_TIMEOUT_S,
        check=False,
    )
    assert res.returncode == 0, f"sphinx-build -W failed:\n{res.stderr[-6000:]}"
    return out


def _text(page: Path) -> str:
    return html.unescape(re.sub(r"<[^>]+>", "", page.read_text(encoding="utf-8")))


def _commands(parser: argparse.ArgumentParser, path=()):
    """Every (sub)command path of the parser with its parser, depth first."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*path, name), sub
                yield from _commands(sub, (*path, name))


def test_every_cli_command_and_flag_is_in_the_reference(site):
    from mjcodesign.cli.main import build_parser

    page = (site / "cli.html").read_text(encoding="utf-8")
    ids = set(re.findall(r'<section id="([^"]+)"', page))
    text = _text(site / "cli.html")
    commands = list(_commands(build_parser()))
    assert len(commands) > 20
    missing = [" ".join(path) for path, _ in commands if "mjcodesign-" + "-".join(path) not in ids]
    assert not missing, f"commands without a section in the CLI reference: {missing}"
    flags = {
        s
        for _, sub in commands
        for a in sub._actions
        if not isinstance(a, argparse._HelpAction)  # the reference leaves out every command's --help
        for s in a.option_strings
        if s.startswith("--")
    }
    assert not sorted(f for f in flags if f not in text), "flags missing from the CLI reference"


def _packages() -> list[str]:
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return [p for p in meta["tool"]["setuptools"]["packages"] if p not in _NOT_DOCUMENTED]


def test_every_public_name_is_documented(site):
    ids = set()
    for page in (site / "api").glob("*.html"):
        ids |= set(re.findall(r'id="(mjcodesign\.[^"]+)"', page.read_text(encoding="utf-8")))
    missing = []
    for name in [*_packages(), "mjcodesign.jobs", "mjcodesign.errors", "mjcodesign.optional", "mjcodesign.outputs"]:
        mod = importlib.import_module(name)
        missing += [f"{name}.{n}" for n in getattr(mod, "__all__", ()) if f"{name}.{n}" not in ids]
    assert not missing, f"public names missing from the API pages: {missing}"


def test_every_record_carries_its_provenance_and_is_indexed(site):
    text = _text(site / "records.html")
    files = sorted((ROOT / "benchmarks" / "records").glob("*.json"))
    files += sorted((ROOT / "tests" / "data").glob("*.json"))
    files += sorted((ROOT / "mjcodesign" / "bench").glob("*.json"))
    assert len(files) > 40
    for f in files:
        prov = json.loads(f.read_text(encoding="utf-8"))["provenance"]
        assert prov.get("command") and prov.get("date"), f"{f.name}: provenance without command or date"
        assert prov.get("commit") or prov.get("installed"), f"{f.name}: provenance names no code"
        assert str(f.relative_to(ROOT)) in text, f"{f.name} is not in the records index"
    dated = [f for f in files if f.parent.name == "records"]
    assert all(re.fullmatch(r"\d{4}-\d{2}-\d{2}_[\w.-]+\.json", f.name) for f in dated)
