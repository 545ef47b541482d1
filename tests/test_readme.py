"""The README is a front door: short, its set-up commands are CI's, and every file it links exists."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
_MAX_LINES = 250  # the manual lives in docs/; the README says what it is, how to start, where to read


def test_readme_is_short():
    assert len(README.splitlines()) <= _MAX_LINES


def test_setup_and_test_commands_are_what_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    for command in ("bash setup.sh", "python3 -m pytest -q -p no:cacheprovider"):
        assert re.search(rf"^{re.escape(command)}\b", ci, re.M), f"{command!r} is not in .ci/run"
        assert re.search(rf"^{re.escape(command)}\b", README, re.M), f"{command!r} is not in the README"


def test_every_linked_file_ships():
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README)
    local = [t for t in targets if not re.match(r"[a-z]+://", t)]
    assert len(local) > 10
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README links to files that do not exist: {missing}"


def test_every_record_the_readme_names_exists():
    for name in re.findall(r"`(?:benchmarks/records/)?(\d{4}-\d{2}-\d{2}_[\w.]+\.json)`", README):
        assert (ROOT / "benchmarks" / "records" / name).is_file(), name
