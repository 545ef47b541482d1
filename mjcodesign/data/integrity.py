"""Whether a dataset's files are the ones its manifest records: size, SHA-256 and the rows' own keys.

The writer records every file's size and SHA-256 beside its name in the manifest (:func:`record`): a
shard's ``checks`` (per table) and an object's ``poses_check``. A file is *damaged* when it is missing,
has another size or hash, cannot be parsed, or holds rows of another object or pose than the entry that
lists it (a copy of another shard). Datasets written before hashes were recorded have no records; their
files are still parsed and their rows' keys checked, so a truncated file or a copied shard is caught
there too, but a file edited in place with the right keys is not.

:func:`read_table` is how the reader reads each file (one read: hashed, then parsed from memory), so
``data info``, ``train`` and everything else that reads a dataset refuses a damaged one with one line
naming the file. :func:`verify` checks a whole dataset and lists every damaged file (``data verify``,
and ``datagen`` before it continues a dataset: the shards of damaged files are computed again).
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mjcodesign.errors import DatasetError

__all__ = ["Damage", "Integrity", "listed_files", "read_table", "record", "verify"]

_KEY_COLUMNS = ("object_index", "pose_index")


def record(data: bytes) -> dict:
    """The manifest's record of a file's content: ``{"bytes": size, "sha256": hex digest}``."""
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


@dataclass(frozen=True)
class Listed:
    """One file the manifest lists: whose it is, its path, its record (None: not recorded), its keys."""

    owner: str
    """The shard key (``o0000-p001``) or ``object N`` (its poses file)."""
    table: str
    """``poses``, ``samples`` or ``rejected``."""
    rel: str
    """Path relative to the dataset folder."""
    check: dict | None
    object_index: int
    pose_index: int | None
    """None for an object's poses file (all its poses)."""


@dataclass(frozen=True)
class Damage:
    """A damaged file: whose it is, its path and what is wrong (one phrase)."""

    owner: str
    rel: str
    problem: str

    def line(self) -> str:
        """``FILE (shard KEY): PROBLEM``."""
        kind = "" if self.owner.startswith("object") else "shard "
        return f"{self.rel} ({kind}{self.owner}): {self.problem}"


@dataclass(frozen=True)
class Integrity:
    """What :func:`verify` found: files checked, how many carry a size and hash, and the damaged ones."""

    files: int
    recorded: int
    damaged: tuple[Damage, ...]

    @property
    def ok(self) -> bool:
        """Whether no file is damaged."""
        return not self.damaged

    def as_dict(self) -> dict:
        """JSON-ready: counts, ``hashes`` (all, some or none recorded) and every damaged file."""
        hashes = "all" if self.recorded == self.files else ("none" if self.recorded == 0 else "some")
        return {
            "ok": self.ok,
            "files": self.files,
            "files_with_hash": self.recorded,
            "hashes": hashes,
            "damaged": [{"file": d.rel, "owner": d.owner, "problem": d.problem} for d in self.damaged],
        }


def listed_files(root: Path, manifest: dict, table: str | None = None) -> Iterator[Listed]:
    """The files the manifest lists (of ``table``, or all), with their records and keys."""
    if table in (None, "poses"):
        for o in manifest.get("objects", []):
            if o.get("status") == "ready":
                yield Listed(
                    f"object {o['index']}", "poses", o["poses_file"], o.get("poses_check"), o["index"], None
                )
    if table == "poses":
        return
    for key, s in manifest.get("shards", {}).items():
        checks = s.get("checks") or {}
        for name, rel in s.get("files", {}).items():
            if table in (None, name):
                yield Listed(key, name, rel, checks.get(name), s["object_index"], s["pose_index"])


def read_table(root: Path, item: Listed, schema: pa.Schema | None = None) -> pa.Table:
    """The file's table after checking it against its record and keys; :class:`DatasetError` if damaged."""
    table, damage = _read(root, item, schema)
    if damage is not None:
        raise DatasetError(
            f"{root}: damaged dataset file {damage.line()}; run `mjcodesign data verify {root}`"
        )
    return table


def verify(root: str | Path, manifest: dict) -> Integrity:
    """Check every file the manifest lists (nothing stops at the first damaged one)."""
    root = Path(root)
    items = list(listed_files(root, manifest))
    damaged = tuple(d for d in (_read(root, it)[1] for it in items) if d is not None)
    return Integrity(len(items), sum(it.check is not None for it in items), damaged)


def _read(root: Path, item: Listed, schema: pa.Schema | None = None) -> tuple[pa.Table | None, Damage | None]:
    def bad(problem: str):
        return None, Damage(item.owner, item.rel, problem)

    try:
        data = (root / item.rel).read_bytes()
    except FileNotFoundError:
        return bad("missing")
    except OSError as exc:
        return bad(f"unreadable ({exc.strerror or exc})")
    if item.check is not None:
        if len(data) != item.check.get("bytes"):
            return bad(f"{len(data)} bytes, the manifest records {item.check.get('bytes')}")
        if hashlib.sha256(data).hexdigest() != item.check.get("sha256"):
            return bad("its SHA-256 is not the one the manifest records (replaced or edited)")
    try:
        table = pq.read_table(pa.BufferReader(data), schema=schema)
    except (pa.ArrowException, OSError, ValueError) as exc:
        return bad(f"not a readable Parquet table ({type(exc).__name__})")
    for column, want in zip(_KEY_COLUMNS, (item.object_index, item.pose_index), strict=True):
        if want is None or table.num_rows == 0:
            continue
        if column not in table.column_names:
            return bad(f"no {column} column")
        values = np.unique(table.column(column).to_numpy())
        if len(values) != 1 or int(values[0]) != want:
            return bad(f"holds rows of {column} {values.tolist()}, not {want} (another shard's file)")
    return table, None
