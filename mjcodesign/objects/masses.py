"""Real object masses: the YCB objects' published masses, and an object placed at a given mass.

The table (``ycb_masses.json``, package data) holds the measured mass of every YCB object of the
paper's two splits (:data:`~mjcodesign.objects.YCB_IN_DOMAIN`, :data:`~mjcodesign.objects.YCB_OOD`) as
the YCB object list publishes it, its source in the table's header. An object whose mesh the list gives
no mass for (the marbles, the toy airplane's parts, the LEGO Duplo pieces, the box of colored wood
blocks) has ``null`` and a note saying why: :func:`published_mass` refuses it rather than invent one.

An object at a mass keeps its shape and a uniform density: :func:`at_mass` scales the density to
``mass / volume`` and the inertia with it (the inertia of the mesh filled uniformly). A real object is
rarely uniform (a can of liquid, a hollow ball), so its centre of mass and inertia are the mesh's, not
the object's; its total mass is the measured one.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from mjcodesign.errors import MeshError
from mjcodesign.objects.mesh import MESH_SUFFIXES, GraspObject

__all__ = [
    "MASS_MODES",
    "MASS_TABLE",
    "MAX_MASS",
    "PublishedMass",
    "at_mass",
    "mass_by_rule",
    "mass_table",
    "parse_mass",
    "published_mass",
    "published_mass_or_none",
    "real_density",
]

MASS_TABLE = "ycb_masses.json"
"""File name of the published-mass table in this package."""
MASS_MODES = ("density", "real", "auto")
"""How an object's mass is set: from a density [kg/m³] (the paper's relative scale); ``real``, the
published mass of a YCB object (refused for any object without one); or ``auto``, the published mass
where the YCB object list gives one and the density otherwise (the real regime's rule for user meshes,
generated shapes and the YCB objects without a published mass). A number is a given mass [kg]."""
MAX_MASS = 20.0
"""Largest given mass [kg]: far above anything the 60-mm gripper could lift (the heaviest YCB object
of the splits, the nine-hole peg test, weighs 1.4 kg)."""


@dataclass(frozen=True)
class PublishedMass:
    """The published mass of one YCB object."""

    name: str
    mass: float
    """[kg]."""
    source: str
    """Short citation of the table's source."""
    note: str | None = None
    """What the published figure covers, where the table says more (e.g. a padlock without its keys)."""


@functools.cache
def mass_table() -> dict:
    """The table as shipped: ``source``, ``citation``, ``unit`` and ``objects`` (name -> mass_kg, note)."""
    text = resources.files("mjcodesign.objects").joinpath(MASS_TABLE).read_text(encoding="utf-8")
    table = json.loads(text)
    if table.get("unit") != "kg" or not isinstance(table.get("objects"), dict):
        raise MeshError(f"{MASS_TABLE}: expected unit 'kg' and an 'objects' map")
    return table


def published_mass(name: str) -> PublishedMass:
    """The published mass of the YCB object ``name`` (e.g. ``013_apple``).

    Raises :class:`MeshError` with one line when ``name`` is not a YCB object of the table (a mesh file,
    ``egad-like:N``) or the table has no published mass for it (with the table's reason).
    """
    table = mass_table()
    text = str(name)
    if text.startswith("egad-like:") or Path(text).suffix.lower() in MESH_SUFFIXES or Path(text).exists():
        raise MeshError(
            f"{text} has no published mass (only YCB objects do): give it a density (--density) or, "
            "where a command takes one, a mass in kg"
        )
    row = table["objects"].get(text)
    if row is None:
        raise MeshError(f"{text} is not in the table of published YCB masses ({table['citation']})")
    if row.get("mass_kg") is None:
        raise MeshError(
            f"{text} has no published mass: {row.get('note', 'not given')} ({table['citation']}); "
            "give it a density (--density) or, where a command takes one, a mass in kg"
        )
    return PublishedMass(text, float(row["mass_kg"]), table["citation"], row.get("note"))


def published_mass_or_none(name: str) -> PublishedMass | None:
    """:func:`published_mass` of ``name``, or None when it has none (the ``auto`` rule).

    None for any object the table cannot give a mass: a mesh file, ``egad-like:N``, a YCB object
    without a published mass.
    """
    try:
        return published_mass(name)
    except MeshError:
        return None


def mass_by_rule(name: str, rule: str) -> PublishedMass | None:
    """The published mass the mass rule ``rule`` (:data:`MASS_MODES`) gives object ``name``, or None.

    ``real``: :func:`published_mass` (:class:`MeshError` without one); ``auto``:
    :func:`published_mass_or_none`; ``density``: None (the mass comes from a density).
    """
    if rule == "real":
        return published_mass(name)
    if rule == "auto":
        return published_mass_or_none(name)
    if rule == "density":
        return None
    raise MeshError(f"mass rule must be one of {', '.join(MASS_MODES)}, got {rule!r}")


def parse_mass(text: str | float | None) -> str | float | None:
    """``--mass``: None or ``density`` (mass from the density), ``real``, ``auto``, or a mass in kg.

    Raises :class:`MeshError` for anything else or a mass outside (0, :data:`MAX_MASS`].
    """
    if text is None or text == "density":
        return None
    if text in ("real", "auto"):
        return text
    try:
        mass = float(text)
    except (TypeError, ValueError):
        raise MeshError(f"--mass must be density, real, auto or a mass in kg, got {text!r}") from None
    if not (math.isfinite(mass) and 0.0 < mass <= MAX_MASS):
        raise MeshError(f"--mass {text}: a mass must be in (0, {MAX_MASS:g}] kg")
    return mass


def real_density(obj: GraspObject, mass: float) -> float:
    """The uniform density [kg/m³] at which ``obj``'s mesh weighs ``mass`` [kg]."""
    if not (math.isfinite(mass) and mass > 0):
        raise MeshError(f"a mass must be a finite value > 0 kg, got {mass}")
    volume = obj.mass / obj.density  # [m³]: the mesh's, at any density
    return float(mass / volume)


def at_mass(obj: GraspObject, mass: float) -> GraspObject:
    """``obj`` at ``mass`` [kg]: the same mesh and convex pieces at a uniform density of mass / volume.

    Mass and inertia scale together (the inertia of the uniformly filled mesh); the centre of mass stays
    the mesh's.
    """
    rho = real_density(obj, mass)
    r = rho / obj.density
    return dataclasses.replace(obj, density=rho, mass=float(mass), inertia=obj.inertia * r)
