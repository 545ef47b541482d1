"""Output folders: which folder a command may write into, and how its files land there whole.

Every command that writes a folder (``datagen``, ``train``, ``optimize``, ``evaluate``, ``finger export``,
``export-print``) follows one rule:

- it writes into a new or empty folder (a hidden file counts as content), or into one that holds its
  own kind of output, recognised by the marker file :data:`MARKER` it wrote there (a dataset by its
  ``manifest.json``);
- a folder that holds anything else is refused with :class:`OutputError`, unless ``overwrite`` is given
  for a kind that allows it; then its files are kept beside the new output (same-named ones replaced);
- another kind's output, and a folder that is also one of the command's inputs (or lies inside one, or
  holds one), are always refused;
- it never removes a file it did not write: files the marker does not list are carried into the new
  folder (hard links, else copies).

:func:`check_output` applies the rule before any work. :func:`staged` then yields a temporary sibling
folder to write into and, when the block ends without an exception, writes the marker and swaps the
sibling into place with one ``renameat2(RENAME_EXCHANGE)`` (two renames where the kernel lacks it, undone
on the next check after a kill between them). A process killed at any moment leaves the old output or the
new one, whole.
"""

from __future__ import annotations

import contextlib
import ctypes
import datetime
import enum
import errno
import io
import json
import os
import shutil
import tempfile
import uuid
from collections.abc import Iterator, Mapping
from dataclasses import KW_ONLY, dataclass
from pathlib import Path

from mjcodesign.errors import MjcodesignError, OutputError, UnsupportedError

__all__ = [
    "MARKER",
    "TMP_SUFFIX",
    "OutputFolder",
    "OutputKind",
    "check_output",
    "folder_kind",
    "new_figure",
    "read_versioned_json",
    "save_figure",
    "staged",
    "write_atomic",
]

TMP_SUFFIX = ".tmp"
"""Suffix of :func:`write_atomic`'s temporary files (``.NAME.HEX.tmp``, hidden, beside the file)."""
MARKER = ".mjcodesign-output.json"
"""The file naming a folder's kind and the files the command wrote (JSON)."""
_MARKER_FORMAT = "mjcodesign-output"
_MARKER_VERSION = 1
# A dataset is recognised by its own manifest (mjcodesign.data.store.MANIFEST and FORMAT; a test keeps
# them equal): datagen continues a dataset shard by shard, so it never writes through staged().
_DATASET_MANIFEST = "manifest.json"
_DATASET_FORMAT = "mjcodesign-grasp-dataset"
_STAGING = "mjcodesign-staging"
_OLD = "mjcodesign-old"
_RENAME_EXCHANGE = 2  # linux/fs.h: swap two paths atomically
_AT_FDCWD = -100


class OutputKind(enum.Enum):
    """What a command writes; its value names the kind in the marker."""

    DATASET = "dataset"
    CHECKPOINT = "checkpoint"
    CODESIGN = "codesign"
    EVALUATION = "evaluation"
    FINGER = "finger"
    PRINT = "print"
    DESIGN = "design"
    ORACLE = "oracle"

    @property
    def command(self) -> str:
        """The command that writes this kind."""
        return _COMMANDS[self]


_COMMANDS = {
    OutputKind.DATASET: "datagen",
    OutputKind.CHECKPOINT: "train",
    OutputKind.CODESIGN: "optimize",
    OutputKind.EVALUATION: "evaluate",
    OutputKind.FINGER: "finger export",
    OutputKind.PRINT: "export-print",
    OutputKind.DESIGN: "design",
    OutputKind.ORACLE: "bench oracle",
}
_NO_OVERWRITE = frozenset({OutputKind.DATASET})  # datagen continues its own dataset, never writes beside


@dataclass(frozen=True)
class OutputFolder:
    """A folder :func:`check_output` accepted for ``kind`` (pass it to :func:`staged`)."""

    path: Path
    """The folder as the user named it (messages show this)."""
    kind: OutputKind
    _: KW_ONLY
    overwrite: bool = False
    """Whether files another writer left there may stay beside the new output."""
    inputs: tuple[tuple[str, Path], ...] = ()
    """(flag, path) of the command's inputs, which the folder must not overlap."""
    flag: str = "--out"
    """The flag that named the folder (messages show it)."""

    def __post_init__(self) -> None:
        if not isinstance(self.path, Path) or not str(self.path):
            raise OutputError(f"{self.flag}: an output folder must be a non-empty path, got {self.path!r}")
        if not isinstance(self.kind, OutputKind):
            raise TypeError(f"kind must be an OutputKind, got {self.kind!r}")
        if self.overwrite and self.kind in _NO_OVERWRITE:
            raise OutputError(f"{self.kind.command} has no --overwrite")

    @property
    def real(self) -> Path:
        """The folder's absolute path with links resolved (a link to a folder keeps pointing to it)."""
        return Path(os.path.realpath(self.path))


def folder_kind(path: str | Path) -> OutputKind | None:
    """The kind of output ``path`` holds (its marker, or a dataset's manifest), or None."""
    root = Path(path)
    head = _read_json(root / MARKER)
    if head is not None and head.get("format") == _MARKER_FORMAT:
        try:
            return OutputKind(head.get("kind"))
        except ValueError:
            return None
    head = _read_json(root / _DATASET_MANIFEST)
    if head is not None and head.get("format") == _DATASET_FORMAT:
        return OutputKind.DATASET
    return None


def check_output(
    path: str | Path,
    kind: OutputKind,
    *,
    overwrite: bool = False,
    inputs: Mapping[str, str | Path | None] | None = None,
    flag: str = "--out",
) -> OutputFolder:
    """Apply the rule of the module docstring to ``path`` before any work; the accepted folder.

    ``inputs`` maps each input's flag to its path (None: not given). Raises :class:`OutputError` with
    one line naming the reason; writes nothing. Leftovers of a killed :func:`staged` beside ``path``
    (its temporary sibling, or the old output between two renames) are cleared or put back first.
    """
    given = tuple((k, Path(v)) for k, v in (inputs or {}).items() if v is not None and str(v))
    folder = OutputFolder(Path(path), kind, overwrite=overwrite, inputs=given, flag=flag)
    _recover(folder.real)
    _check(folder)
    return folder


def _check(folder: OutputFolder) -> None:
    where, real, kind = f"{folder.flag} {folder.path}", folder.real, folder.kind
    for name, given in folder.inputs:
        src = Path(os.path.realpath(given))
        if src == real or real in src.parents or src in real.parents:
            rel = "is" if src == real else ("holds" if real in src.parents else "lies inside")
            raise OutputError(f"{where} {rel} the input {name} {given}: choose another folder")
    cwd = Path(os.path.realpath(os.getcwd()))
    if real == cwd or real in cwd.parents:  # replaced whole, it would leave the shell in a removed folder
        raise OutputError(f"{where} is the working folder or holds it: name a folder inside it")
    base = real.parent  # the sibling is made there: it must be a writable folder (checked before any work)
    while not os.path.lexists(base) and base != base.parent:
        base = base.parent
    if not base.is_dir():
        raise OutputError(f"{where}: {base} is not a writable folder")
    try:  # a real probe: permission bits say nothing for root, on /proc or on a read-only mount
        os.rmdir(tempfile.mkdtemp(prefix=".mjcodesign-probe-", dir=base))
    except OSError as exc:
        raise OutputError(f"{where}: {base} is not a writable folder ({exc.strerror or exc})") from None
    if not real.exists():
        if os.path.lexists(folder.path):
            raise OutputError(f"{where} is a broken link")
        return
    if not real.is_dir():
        raise OutputError(f"{where} is a file, not a folder")
    try:
        entries = sorted(os.listdir(real))
    except OSError as exc:
        raise OutputError(f"{where} cannot be read: {exc.strerror or exc}") from exc
    if not entries:
        return
    found = folder_kind(real)
    if found is kind:
        return
    if found is not None:
        raise OutputError(
            f"{where} holds {_article(found)} ({found.command} output), not {_article(kind)}: choose another folder"
        )
    if folder.overwrite:
        return
    hint = "" if kind in _NO_OVERWRITE else ", or pass --overwrite to write beside them"
    shown = ", ".join(repr(e) for e in entries[:3]) + (", …" if len(entries) > 3 else "")
    raise OutputError(
        f"{where} is not empty and holds no {kind.command} output ({shown}): choose a new or empty folder{hint}"
    )


def write_atomic(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` through a temporary sibling file and a rename.

    A reader never sees half a file, and a failed write leaves ``path`` as it was (the temporary file,
    ``.NAME.HEX`` + :data:`TMP_SUFFIX`, is removed). Raises :class:`OutputError` when it cannot be written.
    """
    out = Path(path)
    tmp = out.with_name(f".{out.name}.{uuid.uuid4().hex[:12]}{TMP_SUFFIX}")
    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        with open(tmp, "xb") as f:  # "x": a new file, mode from the umask as usual
            f.write(raw)
        os.replace(tmp, out)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from exc
    return out


def read_versioned_json(
    source: str | os.PathLike | bytes,
    *,
    fmt: str,
    version: object,
    what: str,
    where: str | os.PathLike | None = None,
    error: type[MjcodesignError] = OutputError,
) -> dict:
    """The JSON object in ``source`` (a file, or its bytes) whose ``format`` is ``fmt`` and ``version`` ``version``.

    ``what`` names the kind of record in the messages (``"a surrogate checkpoint"``); ``where`` is the
    place they start with (default: the file; the folder for a record that marks one). Raises ``error``
    (one line) for a missing or unreadable file, bytes that are not a JSON object, another format, or
    another version.
    """
    if isinstance(source, bytes):
        raw, path = source, None
    else:
        path = Path(source)
        try:
            raw = path.read_bytes()
        except (FileNotFoundError, NotADirectoryError):
            raise error(f"{where or path}: not {what} ({path.name} missing)") from None
        except OSError as exc:
            raise error(f"{path}: unreadable ({exc.strerror or type(exc).__name__})") from None
    place = where or path
    try:
        record = json.loads(raw)
    except ValueError as exc:  # not JSON, or not text
        raise error(f"{path or place}: unreadable, not JSON ({type(exc).__name__})") from None
    if not isinstance(record, dict) or record.get("format") != fmt:
        raise error(f"{place}: not {what} of mjcodesign (format {fmt!r})")
    if record.get("version") != version:
        raise error(
            f"{place}: {what} of another schema (version {record.get('version')!r}; this mjcodesign reads {version!r})"
        )
    return record


def new_figure(figsize: tuple[float, float], *, unavailable: str):
    """A bare ``matplotlib.figure.Figure`` of ``figsize`` [in], drawn on with its own axes (``subplots``).

    No pyplot: the process's backend and pyplot's figure list are left as they are (a library must not
    set them). Raises :class:`UnsupportedError` with the message ``unavailable`` without matplotlib.
    """
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise UnsupportedError(unavailable) from None
    return Figure(figsize=figsize)


def save_figure(fig, path: str | os.PathLike, *, dpi: int) -> Path:
    """Lay out ``fig`` (:func:`new_figure`) and write it to ``path`` (format from its suffix, PNG by default).

    Rendered in memory, then written by :func:`write_atomic`. Raises :class:`OutputError`.
    """
    out = Path(path)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format=out.suffix[1:].lower() or "png", dpi=dpi)
    return write_atomic(out, buf.getvalue())


def _article(kind: OutputKind) -> str:
    return f"{'an' if kind.value[0] in 'aeiou' else 'a'} {kind.value}"


@contextlib.contextmanager
def staged(folder: OutputFolder) -> Iterator[Path]:
    """A temporary sibling of ``folder`` to write the whole output into, swapped into place at the end.

    The folder is checked again first (it may have changed during the work). On a normal exit the
    marker is written (listing the files written), files of the old folder that the old marker does
    not list are carried over, and the sibling replaces the folder in one exchange. On an exception the
    sibling is removed and the folder is left as it was. Raises :class:`OutputError` when it cannot write.
    """
    if folder.kind in _NO_OVERWRITE:
        raise OutputError(f"{folder.kind.command} writes its folder in place, not staged")
    _check(folder)
    real = folder.real
    tmp = real.with_name(f".{real.name}.{_STAGING}-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    made = _missing(real.parent)
    done = False
    try:
        try:
            real.parent.mkdir(parents=True, exist_ok=True)
            tmp.mkdir()
            yield tmp
            _check(folder)
            _finish(folder, tmp)
            _swap(folder, tmp)
            done = True
        except OSError as exc:
            raise OutputError(f"cannot write {folder.flag} {folder.path}: {exc.strerror or exc}") from exc
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if not done:
            for d in made:  # the folders this call made, deepest first, while empty
                with contextlib.suppress(OSError):
                    d.rmdir()


def _missing(path: Path) -> list[Path]:
    """``path`` and its ancestors that do not exist yet, deepest first."""
    out = []
    while not os.path.lexists(path) and path != path.parent:
        out.append(path)
        path = path.parent
    return out


def _finish(folder: OutputFolder, tmp: Path) -> None:
    """Write the marker into ``tmp`` and carry over every file of the old folder that it did not write.

    The marker lists every file written (paths relative to the folder). A file of the old folder is
    kept unless the old marker lists it or the new output writes the same path (which replaces it).
    """
    written = sorted(rel for rel in _files(tmp) if rel != MARKER)
    marker = {
        "format": _MARKER_FORMAT,
        "version": _MARKER_VERSION,
        "kind": folder.kind.value,
        "command": folder.kind.command,
        "files": written,
        "written": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    (tmp / MARKER).write_text(json.dumps(marker, indent=1) + "\n", encoding="utf-8")
    real = folder.real
    if not real.is_dir():
        return
    shutil.copymode(real, tmp)  # the folder keeps its permissions
    old = _read_json(real / MARKER) if folder_kind(real) is folder.kind else None
    ours = set((old or {}).get("files") or ()) | {MARKER}
    for rel in _files(real, dirs=True):
        if rel in ours:
            continue
        src, dst = real / rel, tmp / rel
        if os.path.isdir(src) and not os.path.islink(src):
            if os.path.lexists(dst) and not dst.is_dir():
                raise OutputError(
                    f"{folder.flag} {folder.path}: the output writes a file where {rel}/ is kept"
                )
            dst.mkdir(parents=True, exist_ok=True)
        elif not os.path.lexists(dst):
            if not dst.parent.is_dir():
                raise OutputError(
                    f"{folder.flag} {folder.path}: the output writes a file where {rel} is kept"
                )
            _link_or_copy(src, dst)


def _files(root: Path, *, dirs: bool = False) -> list[str]:
    """Relative paths of the files and links under ``root`` (and its folders, parents first, if ``dirs``)."""
    out = []
    for here, subdirs, names in os.walk(root):
        base = Path(here).relative_to(root)
        for d in list(subdirs):
            if os.path.islink(Path(here) / d):  # a link to a folder is carried as a link
                subdirs.remove(d)
                names.append(d)
            elif dirs:
                out.append(str(base / d))
        out.extend(str(base / n) for n in names)
    return out


def _link_or_copy(src, dst) -> None:
    """A hard link (the file itself, not a copy), or a copy where links are not possible."""
    if os.path.islink(src):
        os.symlink(os.readlink(src), dst)
        return
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _swap(folder: OutputFolder, tmp: Path) -> None:
    """Put ``tmp`` at the folder's place in one step; the old folder ends at ``tmp`` (then removed)."""
    real = folder.real
    if not os.path.lexists(real):
        os.rename(tmp, real)  # replaces an empty folder made meanwhile; a non-empty one is an error
        return
    if _exchange(tmp, real):
        return
    old = real.with_name(f".{real.name}.{_OLD}-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    os.rename(real, old)  # a kill here leaves `old`; the next check_output puts it back
    os.rename(tmp, real)
    os.rename(old, tmp)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths with ``renameat2(RENAME_EXCHANGE)``; False where the system cannot."""
    fn = getattr(_libc(), "renameat2", None)
    if fn is None:
        return False
    rc = fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


_LIBC: list = []


def _libc():
    if not _LIBC:
        try:
            _LIBC.append(ctypes.CDLL(None, use_errno=True))
        except OSError:
            _LIBC.append(None)
    return _LIBC[0]


def _recover(real: Path) -> None:
    """Clear what a killed :func:`staged` left beside ``real``: its sibling, or the old folder to put back."""
    parent = real.parent
    if not parent.is_dir():
        return
    prefix = f".{real.name}."
    for name in os.listdir(parent):
        if not name.startswith(prefix):
            continue
        tag = next((t for t in (_STAGING, _OLD) if name[len(prefix) :].startswith(t + "-")), None)
        if tag is None or _alive(name[len(prefix) + len(tag) + 1 :].split("-")[0]):
            continue
        leftover = parent / name
        with contextlib.suppress(OSError):
            if tag == _OLD and not os.path.lexists(real):
                os.rename(leftover, real)
            else:
                shutil.rmtree(leftover)


def _alive(pid_text: str) -> bool:
    """Whether the process that left a sibling may still be writing it (its id is in the name)."""
    try:
        pid = int(pid_text)
    except ValueError:
        return True
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _read_json(path: Path) -> dict | None:
    try:
        head = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return head if isinstance(head, dict) else None
