"""The objects of ``mjcodesign design``: what loads each one, and its mass.

An object is a YCB name, ``egad-like:N``, a mesh file (STL/OBJ/PLY) or a folder of mesh files (each of
its files an object), optionally with a mass after ``@``: ``box.stl@120g``, ``013_apple@0.197kg``.
A masses file (CSV, ``--masses``) gives masses by object name in two columns, ``object,mass``, with an
optional header row; a mass there takes the same units (``120g``, ``0.12kg``). An object without a
given mass is simulated in the checkpoint dataset's regime: at its published mass where that regime
takes them (``real``), else at the dataset's density.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

from mjcodesign.data import resolve_objects
from mjcodesign.errors import MeshError
from mjcodesign.objects import MAX_MASS, MESH_SUFFIXES, object_name

__all__ = ["DEFAULT_DENSITY", "ObjectSpec", "parse_mass_text", "parse_objects", "read_masses"]

DEFAULT_DENSITY = "light"
"""Density an object is loaded at before its mass is set (the mass then sets the density)."""
_MASS = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(g|kg)\s*$")
_TO_KG = {"g": 1e-3, "kg": 1.0}


@dataclass(frozen=True)
class ObjectSpec:
    """One object to design for."""

    name: str
    """Its name in the outputs (a YCB name, ``egad-like:N`` or the mesh file's stem)."""
    source: str
    """What loads it: the YCB name, ``egad-like:N`` or the mesh file's absolute path."""
    mass_kg: float | None = None
    """Its mass [kg]; None: the default density."""


def parse_mass_text(text: str, where: str) -> float:
    """A mass with its unit, ``120g`` or ``0.12kg``, in kg; :class:`~mjcodesign.errors.MeshError` (naming ``where``) else."""
    m = _MASS.match(str(text))
    if m is None:
        raise MeshError(f"{where}: bad mass {text!r}: give it with its unit, e.g. 120g or 0.12kg")
    kg = float(m.group(1)) * _TO_KG[m.group(2)]
    if not (math.isfinite(kg) and 0.0 < kg <= MAX_MASS):
        raise MeshError(f"{where}: mass {text!r} must be in (0, {MAX_MASS:g}] kg")
    return kg


def read_masses(path: str | Path) -> dict[str, float]:
    """Masses [kg] by object name from a CSV file (module docstring); :class:`~mjcodesign.errors.MeshError` if unusable."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MeshError(
            f"--masses {p}: cannot read it ({getattr(exc, 'strerror', None) or type(exc).__name__})"
        ) from None
    out: dict[str, float] = {}
    for i, row in enumerate(csv.reader(text.splitlines()), start=1):
        cells = [c.strip() for c in row]
        if not any(cells):
            continue
        if len(cells) != 2:
            raise MeshError(f"--masses {p}, line {i}: two columns (object,mass) expected, got {len(cells)}")
        if i == 1 and _MASS.match(cells[1]) is None and cells[1].lower().startswith("mass"):
            continue  # the header row
        key = _key(cells[0])
        if key in out:
            raise MeshError(f"--masses {p}, line {i}: object {cells[0]!r} listed twice")
        out[key] = parse_mass_text(cells[1], f"--masses {p}, line {i}")
    if not out:
        raise MeshError(f"--masses {p}: no object,mass row")
    return out


def _key(text: str) -> str:
    """The name an object goes by: a mesh file's stem (``object_name``), or the text itself."""
    return object_name(text) if Path(text).suffix.lower() in MESH_SUFFIXES else text


def parse_objects(
    items: list[str] | tuple[str, ...], masses: dict[str, float] | None = None
) -> tuple[ObjectSpec, ...]:
    """The objects of the command line, each checked without loading it (:func:`~mjcodesign.data.resolve_objects`).

    ``items``: ``SOURCE`` or ``SOURCE@MASS`` (a folder's mass applies to each of its files);
    ``masses``: masses by object name (:func:`~mjcodesign.pipeline.read_masses`), for objects without ``@MASS``. Raises
    :class:`~mjcodesign.errors.MeshError` for an unknown object, a missing file, a bad mass, an object given twice or a
    masses entry that names no object.
    """
    if not items:
        raise MeshError("no object given")
    masses = dict(masses or {})
    specs: list[ObjectSpec] = []
    for item in items:
        text, at, mass_text = str(item).rpartition("@") if "@" in str(item) else (str(item), "", "")
        if at and not text:
            raise MeshError(f"{item!r}: an object is missing before @")
        mass = parse_mass_text(mass_text, str(item)) if at else None
        if "," in text:
            raise MeshError(f"{item!r}: give objects as separate arguments, not comma-separated")
        for src in resolve_objects(text):
            is_file = Path(src).suffix.lower() in MESH_SUFFIXES
            name = object_name(src) if is_file else src
            given = mass if mass is not None else masses.get(name)
            specs.append(ObjectSpec(name, str(Path(src).resolve()) if is_file else src, given))
    names = [s.name for s in specs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise MeshError(f"object {twice[0]} is given twice")
    unused = sorted(set(masses) - set(names))
    if unused:
        raise MeshError(f"--masses names {unused[0]!r}, which is not one of the objects")
    return tuple(specs)
