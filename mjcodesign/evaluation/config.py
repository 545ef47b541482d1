"""What an evaluation runs: the design groups, object sets, densities, pose rules and impulses.

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

import numpy as np

from mjcodesign.design.stiffness import DESIGN_FILE_SUFFIXES, Stiffness, read_design_file
from mjcodesign.errors import DesignError, MjcodesignError
from mjcodesign.objects import DENSITY_PRESETS

__all__ = [
    "DENSITIES",
    "DOMAINS",
    "PAPER_TABLE1",
    "POSE_SAMPLING",
    "DesignGroup",
    "EvalConfig",
    "parse_design_groups",
    "parse_list",
]

POSE_SAMPLING = ("fixed", "surrogate")
"""``fixed``: the first candidate; ``surrogate``: the best of the first :attr:`EvalConfig.candidates`
candidates by the surrogate's predicted success score, per design."""
DOMAINS = ("in-domain", "out-of-domain")
DENSITIES = tuple(DENSITY_PRESETS)

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


@dataclass(frozen=True)
class EvalConfig:
    """Everything that decides an evaluation's rollouts."""

    designs: tuple[DesignGroup, ...]
    in_domain: tuple[str, ...]
    """Objects of the in-domain column (names or paths)."""
    out_of_domain: tuple[str, ...]
    densities: tuple[str, ...] = ("light", "heavy")
    pose_sampling: tuple[str, ...] = ("fixed", "surrogate")
    impulses: tuple[float, ...] = (0.1, 0.2, 0.4)
    """Disturbances in the paper's units [N s in their 5x scene] (``paper_impulse`` maps them); the
    first is the table's, all of them make the disturbance sweep."""
    candidates: int = 10
    """Surrogate pose sampling picks among this many first candidates (the paper: 10)."""
    anygrasp: str | None = None
    """A folder of the authors' AnyGrasp ``OBJECT.npz`` files: their poses replace the sampler's for
    the objects they cover."""
    model: str = "chain"
    seed: int = 0
    cache_dir: str | None = None

    def __post_init__(self) -> None:
        if not self.designs:
            raise DesignError("an evaluation needs at least one design group")
        if not (self.in_domain or self.out_of_domain):
            raise DesignError("an evaluation needs at least one object")
        for d in self.densities:
            if d not in DENSITY_PRESETS:
                raise DesignError(f"density {d!r}: choose from {', '.join(DENSITY_PRESETS)}")
        for s in self.pose_sampling:
            if s not in POSE_SAMPLING:
                raise DesignError(f"pose sampling {s!r}: choose from {', '.join(POSE_SAMPLING)}")
        if not self.impulses or not all(np.isfinite(i) and i >= 0 for i in self.impulses):
            raise DesignError(f"impulses must be finite values >= 0 (paper N s), got {self.impulses}")
        if isinstance(self.candidates, bool) or int(self.candidates) < 1:
            raise DesignError(f"candidates must be >= 1, got {self.candidates}")
        if isinstance(self.seed, bool) or int(self.seed) < 0:
            raise DesignError(f"seed must be >= 0, got {self.seed}")

    @property
    def needs_surrogate(self) -> bool:
        """Whether a checkpoint is needed (surrogate pose sampling)."""
        return "surrogate" in self.pose_sampling
