"""The designs an evaluation compares (``--designs``), design files, and the paper's Table 1 figures.

A design group is named on the command line (``--designs``):

* a preset (``soft``, ``semi-rigid``, ``paper-optimized``) or ``random:SEED``;
* ``joint:FILE``: one design for every object, from a design file
  (:func:`mjcodesign.design.stiffness.read_design_file`);
* ``individual:DIR``: one design per object, from a folder of design files ``OBJECT.json`` or ``.txt``
  (``mjcodesign optimize --mode individual --out DIR`` writes them under ``DIR/designs/``, which is
  also accepted). As in the paper, an individual design is evaluated only on its own in-domain objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from mjcodesign.design.stiffness import DESIGN_FILE_SUFFIXES, Stiffness, read_design_file
from mjcodesign.errors import DesignError, MjcodesignError

__all__ = [
    "PAPER_TABLE1",
    "DesignGroup",
    "parse_design_groups",
    "parse_list",
]


PAPER_TABLE1: dict[tuple[str, str, str, str], float] = {
    # (group, pose sampling, domain, density) -> success [%], as the issue quotes the paper's Table 1
    # (in-domain, fixed pose); every other cell of the paper's table is not recorded here.
    ("soft", "fixed", "in-domain", "light"): 69.6,
    ("soft", "fixed", "in-domain", "heavy"): 56.5,
    ("semi-rigid", "fixed", "in-domain", "light"): 52.2,
    ("semi-rigid", "fixed", "in-domain", "heavy"): 37.0,
    ("joint", "fixed", "in-domain", "light"): 89.1,
    ("joint", "fixed", "in-domain", "heavy"): 78.3,
    # The paper-optimized preset is the paper's jointly optimised design (its Table 2), so the paper's
    # joint figures stand beside it too.
    ("paper-optimized", "fixed", "in-domain", "light"): 89.1,
    ("paper-optimized", "fixed", "in-domain", "heavy"): 78.3,
}
"""The paper's figures printed beside ours (a second column group); None where not recorded."""


@dataclass(frozen=True)
class DesignGroup:
    """A row group of the table: one design for all objects, or one per object (``individual``)."""

    label: str
    """As written on the command line, e.g. ``soft`` or ``joint:best.json``."""
    group: str
    """The table's row name: the preset, ``joint``, ``individual`` or ``random:SEED``."""
    design: Stiffness | None = None
    per_object: dict[str, Stiffness] = field(default_factory=dict)

    def for_object(self, name: str) -> Stiffness | None:
        """The design this group grasps ``name`` with; None where it is not evaluated."""
        if self.design is not None:
            return self.design
        return self.per_object.get(name)


def _individual(folder: Path) -> dict[str, Stiffness]:
    if not folder.is_dir():
        raise DesignError(f"individual designs: {folder} is not a folder")
    sub = folder / "designs"
    root = sub if sub.is_dir() else folder
    files = [
        f for f in sorted(root.iterdir()) if f.suffix.lower() in DESIGN_FILE_SUFFIXES and f.stem != "result"
    ]
    out = {f.stem: read_design_file(f) for f in files}
    if not out:
        raise DesignError(f"individual designs: no OBJECT.json / OBJECT.txt design file in {root}")
    return out


def parse_design_groups(text: str) -> tuple[DesignGroup, ...]:
    """``--designs``: comma-separated presets, ``random:SEED``, ``joint:FILE`` or ``individual:DIR``."""
    groups = []
    for item in parse_list(text, "designs"):
        kind, sep, arg = item.partition(":")
        if sep and kind == "joint":
            groups.append(DesignGroup(item, "joint", read_design_file(arg)))
        elif sep and kind == "individual":
            groups.append(DesignGroup(item, "individual", per_object=_individual(Path(arg))))
        else:
            try:
                groups.append(DesignGroup(item, item, Stiffness.parse(item)))
            except MjcodesignError as exc:
                raise DesignError(
                    f"design {item!r}: {exc} (a preset, random:SEED, joint:FILE or individual:DIR)"
                ) from exc
    if len({g.label for g in groups}) != len(groups):
        raise DesignError(f"a design group is listed twice: {text}")
    return tuple(groups)


def parse_list(text: str, what: str) -> tuple[str, ...]:
    """Comma-separated, non-empty, each once."""
    items = tuple(s.strip() for s in str(text).split(","))
    if not items or any(not s for s in items):
        raise DesignError(f"--{what}: an empty entry in {text!r}")
    if len(set(items)) != len(items):
        raise DesignError(f"--{what}: an entry is listed twice in {text!r}")
    return items
