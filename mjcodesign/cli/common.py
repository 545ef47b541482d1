"""Helpers shared by every CLI family: parser, printing, design parsing, cache folder, Warp's quieting.

No ``cli.*`` module imports another's private names or ``cli.main``; what they share lives here.
"""

from __future__ import annotations

import argparse
import errno
import json
import logging
import math
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

__all__ = [
    "Parser",
    "emit",
    "parse_design",
    "user_cache_dir",
    "quiet_warp",
    "path_text",
    "add_out_folder",
    "add_mass_mode",
    "add_regime",
    "port_number",
    "int_at_least",
    "finite_float",
    "short",
    "one_line",
    "output_file",
    "output_dir",
    "check_output_link",
    "choice_list",
    "warn_failed_objects",
    "scenario_physics",
    "FRICTION_HELP",
]

_NO_DRIVER = b"Could not find or load the NVIDIA CUDA driver"  # expected on CPU-only machines


class _DefaultsFormatter(argparse.HelpFormatter):
    """Help that ends each option's text with its default, where it has one worth saying.

    Like ``argparse.ArgumentDefaultsHelpFormatter``, but silent on ``None``, ``False`` (a flag) and
    suppressed defaults, and on positionals; a help text that already names ``%(default)s`` or says
    "default" keeps its own wording.
    """

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (
            default is None
            or default is False
            or default is argparse.SUPPRESS
            or not action.option_strings
            or "default" in text.lower()
        ):
            return text
        return f"{text} (default: %(default)s)" if text else "default: %(default)s"


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2, and shows defaults in ``--help``."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", _DefaultsFormatter)
        super().__init__(*args, **kwargs)

    def add_argument(self, *args, **kwargs):  # noqa: D102
        action = super().add_argument(*args, **kwargs)
        if action.help is None and action.option_strings and action.default not in (None, False):
            action.help = ""  # the formatter writes the default; argparse skips an option without help
        return action

    def error(self, message: str):  # noqa: D102
        sys.stderr.write(f"error: {message}\n")
        raise SystemExit(2)


def one_line(text: str) -> str:
    r"""``text`` with its control characters escaped (a newline in a path reads ``\n``): one line."""
    return "".join(c if c.isprintable() or c == " " else c.encode("unicode_escape").decode() for c in text)


def short(text: str, keep: int = 60) -> str:
    """``text`` quoted, cut to ``keep`` characters with an ellipsis: a 5,000-character path stays one line."""
    return repr(text if len(text) <= keep else text[:keep] + "…")


def add_out_folder(p: argparse.ArgumentParser, what: str) -> None:
    """``--out`` (a folder, :mod:`mjcodesign.outputs`' rule) and ``--overwrite`` on parser ``p``."""
    p.add_argument(
        "--out",
        type=path_text,
        required=True,
        help=f"{what} folder: new, empty or this command's earlier output (replaced whole when done)",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="write into a non-empty folder, keeping its other files"
    )


def add_mass_mode(p: argparse.ArgumentParser, where: str) -> None:
    """``--mass density|real|auto`` on parser ``p``; ``where`` says what the real masses replace."""
    p.add_argument(
        "--mass",
        choices=("density", "real", "auto"),
        default=None,
        help="real: every object at its published mass (YCB objects only; the YCB object list), uniform "
        f"density mass / volume, {where}; auto: the published mass where there is one, else the density; "
        "density: from the density (default: the regime's rule, auto in real, density in paper)",
    )


def add_regime(p: argparse.ArgumentParser, default: str | None = "real") -> None:
    """``--regime real|paper`` on parser ``p``: the defaults of the grasp's physics and masses."""
    p.add_argument(
        "--regime",
        choices=("real", "paper"),
        default=default,
        help="real: the hardware's grasp (XL330 servo at 1000 ticks, 10 cm lift, disturbance 0.51 m/s, "
        "published YCB masses, other objects 680 kg/m³); paper: the paper's relative scale (10 N force, "
        "3 cm lift, light density). Flags that name a setting replace the regime's",
    )


def path_text(text: str) -> str:
    """The argparse type of a path argument: not empty, and a name the file system can look up.

    An empty path would mean the current directory (``Path("")`` is ``.``); a name past ``NAME_MAX`` or
    ``PATH_MAX`` would fail later with ``ENAMETOOLONG`` wherever it is first used. A path that does not
    exist passes: the command says what it expected there (names such as ``025_mug`` are not files).
    """
    if not text:
        raise argparse.ArgumentTypeError("empty path")
    try:
        os.stat(text)
    except ValueError:  # an embedded NUL
        raise argparse.ArgumentTypeError(f"not a path: {short(text)}") from None
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:
            raise argparse.ArgumentTypeError(
                f"file name too long ({len(text)} characters): {short(text)}"
            ) from None
    return text


def output_file(text: str) -> str:
    """The argparse type of an output file, checked before any work.

    :func:`path_text`, and then: not a folder, in a folder that exists and can be written, and
    writable if it exists already.
    """
    text = path_text(text)
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{short(one_line(text))} is a folder, not a file")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"no folder {short(one_line(str(parent)))} to write {path.name} in")
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise argparse.ArgumentTypeError(f"{short(one_line(text))} cannot be written (permission denied)")
    return text


def output_dir(text: str) -> str:
    """The argparse type of an output folder written as the command goes (event logs), checked first.

    :func:`path_text`, not a file, and writable (or creatable in a writable folder).
    """
    text = path_text(text)
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{short(one_line(text))} is a file, not a folder")
    existing = next((p for p in (path, *path.parents) if p.exists()), Path("."))
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(
            f"{short(one_line(str(existing)))} cannot be written (permission denied)"
        )
    return text


def check_output_link(text: str, flag: str, *, overwrite: bool | None = None) -> None:
    """Raise :class:`~mjcodesign.errors.OutputError` if output file ``text`` is a symbolic link.

    Writing through it would replace whatever file it points at. ``overwrite``: the command's
    ``--overwrite`` (True lets it write through), or None for a command without one.
    """
    from mjcodesign.errors import OutputError

    if Path(text).is_symlink() and not overwrite:
        target = os.readlink(text)
        hint = "; --overwrite writes through it" if overwrite is not None else "; name the file itself"
        raise OutputError(
            f"{flag} {short(one_line(text))} is a symbolic link to {short(one_line(target))}: refused{hint}"
        )


def choice_list(choices: tuple[str, ...], what: str) -> Callable[[str], list[str]]:
    """The argparse type of a comma-separated list drawn from ``choices``, each at most once."""

    def parse(text: str) -> list[str]:
        items = [v.strip() for v in text.split(",")]
        unknown = [v for v in items if v not in choices]
        if unknown:
            raise argparse.ArgumentTypeError(f"unknown {what}(s) {unknown}: choose from {', '.join(choices)}")
        if len(set(items)) != len(items):
            raise argparse.ArgumentTypeError(f"a {what} is listed twice: {short(text)}")
        return items

    return parse


def warn_failed_objects(dataset: str | Path) -> int:
    """One stderr line per object the dataset in folder ``dataset`` could not use; returns how many.

    Reads its manifest's objects (``status`` failed, with the ``error`` datagen recorded), so that a
    run that leaves an object out says so where it is seen, not only in ``objects_failed``.
    """
    try:
        objects = json.loads((Path(dataset) / "manifest.json").read_text(encoding="utf-8"))["objects"]
    except (OSError, ValueError, KeyError, TypeError):
        return 0  # no readable manifest: the command has said why already
    failed = [o for o in objects if isinstance(o, dict) and o.get("status") == "failed"]
    for o in failed:
        name = one_line(str(o.get("name", o.get("source"))))
        sys.stderr.write(f"warning: object {name} left out: {one_line(str(o.get('error')))}\n")
    return len(failed)


def port_number(text: str) -> int:
    """The argparse type of a TCP port: an integer in 1..65535."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port number in 1..65535, got {short(text)}")
    return value


def int_at_least(low: int) -> Callable[[str], int]:
    """The argparse type of an integer >= ``low``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {short(text)}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value}")
        return value

    return parse


def finite_float(low: float, *, strict: bool = False) -> Callable[[str], float]:
    """The argparse type of a finite number >= ``low`` (> ``low`` when ``strict``): never NaN or inf."""
    bound = f"> {low:g}" if strict else f">= {low:g}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or value < low or (strict and value == low):
            raise argparse.ArgumentTypeError(f"must be a finite number {bound}, got {short(text)}")
        return value

    return parse


def finite_floats(low: float, *, strict: bool = False) -> Callable[[str], list[float]]:
    """The argparse type of a comma-separated list of :func:`finite_float` values."""
    one = finite_float(low, strict=strict)

    def parse(text: str) -> list[float]:
        return [one(v) for v in text.split(",")]

    return parse


def parse_design(text: str):
    """The :class:`~mjcodesign.design.stiffness.Stiffness` for ``--design`` (preset, random:SEED, log E)."""
    from mjcodesign.design import Stiffness

    return Stiffness.parse(text)


def emit(result, as_json: bool) -> None:
    """Print a dict or a list of row dicts: one JSON line, or a rich table.

    JSON is strict: a NaN or an infinity anywhere in ``result`` raises
    :class:`~mjcodesign.errors.OutputError` naming where, instead of printing a token no JSON reader takes.
    """
    if as_json:
        try:
            text = json.dumps(result, indent=None, allow_nan=False)
        except ValueError:
            from mjcodesign.errors import OutputError

            where = _non_finite(result) or "?"
            raise OutputError(
                f"the result holds a NaN or an infinity at {where}: not printed as JSON"
            ) from None
        print(text)
        return
    from rich.console import Console
    from rich.table import Table

    if isinstance(result, dict):
        table = Table("key", "value")
        for k, v in result.items():
            table.add_row(str(k), _fmt(v))
        Console().print(table)
        return
    rows = result
    table = Table()
    keys = list(rows[0].keys())
    for k in keys:
        table.add_column(k)
    for r in rows:
        table.add_row(*[_fmt(r[k]) for k in keys])
    Console().print(table)


def _non_finite(value, path: str = "") -> str | None:
    """The key path of the first NaN or infinity in a JSON-like ``value`` (``a.b[2]``); None if none."""
    if isinstance(value, float):
        return None if math.isfinite(value) else (path or "the top level")
    if isinstance(value, dict):
        items = ((f"{path}.{k}" if path else str(k), v) for k, v in value.items())
    elif isinstance(value, list | tuple):
        items = ((f"{path}[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    return next((p for key, v in items if (p := _non_finite(v, key)) is not None), None)


def _fmt(v) -> str:
    from rich.markup import escape

    return escape(_plain(v))


def _plain(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_plain(x) for x in v[:6]) + (", …]" if len(v) > 6 else "]")
    return str(v)


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/mjcodesign`` or ``~/.cache/mjcodesign`` (flags and environment live here)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mjcodesign"


def quiet_warp() -> None:
    """Initialise Warp quietly, once, before a command that can reach it; later ``wp.init()`` is silent.

    Warp logs its banner and every module load at INFO level on stdout, which would break ``--json``;
    and on a machine without the NVIDIA driver its native library prints a one-line CUDA warning on
    stderr during ``wp.init()``, which would make a refused command print two lines. The first is
    silenced by the log level, the second is filtered out of the captured file descriptor 2; anything
    else Warp writes there is kept. Raises ImportError if warp-lang is missing.
    """
    import warp as wp

    wp.config.log_level = logging.WARNING
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        kept = [ln for ln in captured.read().splitlines(keepends=True) if _NO_DRIVER not in ln]
    if kept:
        sys.stderr.buffer.write(b"".join(kept))
        sys.stderr.flush()


FRICTION_HELP = (
    "finger-object sliding friction coefficient (default: the regime's, 1 in both); 'tape-min': 0.6, the "
    "floor the gripping tape's maker claims (the range 0.6-1 is in the docs' regime page)"
)
"""``--friction``'s help, the same on every command that takes it."""


def scenario_physics(delta_v: str | float | None, friction: str | float | None) -> dict:
    """GraspScenario's ``delta_v`` and ``friction`` from ``--delta-v`` and ``--friction`` (names or numbers).

    None leaves a setting out of the result (the regime's stays). Raises :class:`DesignError`.
    """
    from mjcodesign.errors import DesignError
    from mjcodesign.scenarios import PAPER_DELTA_V, TAPE_FRICTION_FLOOR

    names = {"delta_v": {"paper": PAPER_DELTA_V}, "friction": {"tape-min": TAPE_FRICTION_FLOOR}}
    out = {}
    for key, text in (("delta_v", delta_v), ("friction", friction)):
        if text is None:
            continue
        try:
            out[key] = float(names[key].get(text, text))
        except (TypeError, ValueError):
            choices = ", ".join(names[key])
            raise DesignError(
                f"--{key.replace('_', '-')} must be a number or {choices}, got {text!r}"
            ) from None
    return out
