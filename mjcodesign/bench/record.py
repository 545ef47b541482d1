"""Provenance of a benchmark record: what ran, from which installed code, when, where and under what load.

Every record :func:`~mjcodesign.bench.run_benchmark` returns carries it under ``"provenance"``, so a
record file is self-describing wherever it is copied.
"""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import json
import os
import platform
import subprocess
from pathlib import Path

__all__ = ["installed_source", "provenance"]

_GIT_TIMEOUT_S = 5.0  # a git query on a local tree; anything slower is a broken tree, not a slow one


def installed_source() -> dict:
    """The installed ``mjcodesign``: version, where it was installed from, and that tree's git commit.

    ``source`` is the folder pip installed from (PEP 610 ``direct_url.json``), ``editable`` whether it is
    an editable install; ``commit`` is that folder's ``HEAD`` and ``dirty`` whether its tracked files
    differ from it (both ``None`` when the folder is not a git work tree). The package's own folder is
    reported too, so a record shows which copy of the code was imported.
    """
    import mjcodesign

    out: dict = {"package_dir": str(Path(mjcodesign.__file__).resolve().parent)}
    try:
        dist = importlib.metadata.distribution("mjcodesign")
    except importlib.metadata.PackageNotFoundError:
        return {**out, "version": None, "source": None, "editable": None, "commit": None, "dirty": None}
    out["version"] = dist.version
    direct = dist.read_text("direct_url.json")
    info = json.loads(direct) if direct else {}
    url = info.get("url", "")
    source = Path(url.removeprefix("file://")) if url.startswith("file://") else None
    out["source"] = str(source) if source else None
    out["editable"] = bool(info.get("dir_info", {}).get("editable", False))
    out["commit"], out["dirty"] = _git_state(source if source else Path(out["package_dir"]))
    return out


def _git_state(folder: Path) -> tuple[str | None, bool | None]:
    """(HEAD, whether tracked files differ) of the git work tree holding ``folder``, or (None, None)."""
    try:
        head = subprocess.run(
            ["git", "-C", str(folder), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_S,
            check=True,
        ).stdout.strip()
        diff = subprocess.run(
            ["git", "-C", str(folder), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_S,
            check=True,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return None, None
    return head or None, bool(diff.strip())


def provenance(name: str, *, command: str | None = None) -> dict:
    """The provenance of one record of benchmark ``name``.

    ``command`` is the command line that ran it (when given); then the UTC date, the installed code
    (:func:`installed_source`), the machine and its load average.
    """
    return {
        "benchmark": name,
        "command": command,
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "installed": installed_source(),
        "machine": {
            "platform": platform.platform(),
            "python": platform.python_version(),
            "cpu_count": os.cpu_count(),
        },
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
