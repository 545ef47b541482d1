"""A frozen, versioned evaluation suite: objects, their poses, and the perturbation model.

A suite is a JSON file (``format`` :data:`SUITE_FORMAT`, ``version`` :data:`SUITE_VERSION`): every
object with its domain, fold and source, the palm poses sampled once for it (4x4 matrices and the two
openings, with the seed that sampled them), and the perturbation model whose draws every design shares.
Results name the suite by ``name`` and by the SHA-256 of its file (:attr:`Suite.digest`).

The perturbation model and its ranges (each with where it comes from) are
:class:`~mjcodesign.scenarios.perturb.PerturbationModel`'s.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from mjcodesign.errors import DesignError, MjcodesignError
from mjcodesign.models.types import GripperPose
from mjcodesign.objects import YCB_IN_DOMAIN, parse_egad_index
from mjcodesign.outputs import read_versioned_json
from mjcodesign.scenarios.perturb import PerturbationModel

__all__ = [
    "DEFAULT_SUITE",
    "SUITE_FORMAT",
    "SUITE_VERSION",
    "Suite",
    "SuiteError",
    "SuiteObject",
    "add_objects",
    "build_suite",
    "deal_folds",
    "egad_sources",
    "load_suite",
    "suite_folds",
]

SUITE_FORMAT = "mjcodesign-eval-suite"
SUITE_VERSION = 1
"""The suite file format's version; a file of another version is refused."""
DEFAULT_SUITE = "default-v1"
"""The shipped suite ``--suite default`` reads: the paper's 46 in-domain objects and the 42 of the
``ood`` set, 10 poses each."""
DEFAULT_FOLDS = 5
"""Object-level folds of the in-domain objects (``fold``), for K-fold held-out surrogates."""
_FOLD_STREAM = 0xF01D  # the folds' own random stream


class SuiteError(MjcodesignError):
    """A suite file that cannot be used: unknown format or version, missing or malformed fields."""


@dataclass(frozen=True)
class SuiteObject:
    """One object of a suite and its poses."""

    name: str
    """The object's name (a YCB name, ``egad-like:N``, or a mesh file's stem)."""
    source: str
    """What loads it: the YCB name, ``egad-like:N`` or the mesh file's path."""
    domain: str
    """``in-domain`` (the paper's training objects) or ``out-of-domain``."""
    fold: int | None
    """Object-level fold of an in-domain object (None out of domain)."""
    poses: tuple[GripperPose, ...]
    pose_source: str = "sampler"
    """``sampler`` or the AnyGrasp file the poses came from."""
    source_index: tuple[int, ...] = ()
    """Row of each pose in its source."""
    note: str = ""
    """Why the object has fewer poses than asked, when it does."""


@dataclass(frozen=True)
class Suite:
    """Objects with their poses, and the perturbation model."""

    name: str
    objects: tuple[SuiteObject, ...]
    seed: int
    """The seed that sampled the poses and drew the folds."""
    poses_per_object: int
    """Poses asked per object (an object may hold fewer: its ``note`` says why)."""
    perturbation: PerturbationModel = field(default_factory=PerturbationModel)
    folds: int = DEFAULT_FOLDS
    created: str = ""
    digest: str = ""
    """SHA-256 of the file it was read from or written to ('' before either)."""

    def __post_init__(self) -> None:
        if not self.objects:
            raise SuiteError(f"suite {self.name!r} holds no object")
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise SuiteError(f"suite {self.name!r} lists an object twice")
        for o in self.objects:
            if not o.poses:
                raise SuiteError(f"suite {self.name!r}: object {o.name} has no pose")

    def to_json(self) -> dict:
        """The file's content (the digest is of this, so it is not part of it)."""
        return {
            "format": SUITE_FORMAT,
            "version": SUITE_VERSION,
            "name": self.name,
            "created": self.created,
            "seed": self.seed,
            "poses_per_object": self.poses_per_object,
            "folds": self.folds,
            "perturbation": self.perturbation.as_dict(),
            "objects": [
                {
                    "name": o.name,
                    "source": o.source,
                    "domain": o.domain,
                    "fold": o.fold,
                    "pose_source": o.pose_source,
                    "note": o.note,
                    "poses": [
                        {
                            "position": list(p.position),
                            "quat": list(p.quat),
                            "openings": list(p.openings),
                            "source_index": int(i),
                        }
                        for p, i in zip(o.poses, o.source_index or range(len(o.poses)), strict=True)
                    ],
                }
                for o in self.objects
            ],
        }

    def save(self, path: str | Path) -> Suite:
        """Write the suite to ``path`` (atomically); the suite with its digest."""
        from mjcodesign.outputs import write_atomic

        raw = json.dumps(self.to_json(), indent=1).encode()
        write_atomic(path, raw)
        return _with_digest(self, raw)


def _with_digest(suite: Suite, raw: bytes) -> Suite:
    return replace(suite, digest=hashlib.sha256(raw).hexdigest())


def load_suite(source: str | Path) -> Suite:
    """A suite from a file, or ``default`` for the shipped one; :class:`SuiteError` if unusable."""
    if str(source) in ("default", DEFAULT_SUITE):
        ref = resources.files("mjcodesign.evaluation").joinpath(f"suites/{DEFAULT_SUITE}.json")
        raw = ref.read_bytes()
        where = f"the shipped suite {DEFAULT_SUITE}"
    else:
        path = Path(source)
        if not path.is_file():
            raise SuiteError(f"--suite {source}: no such file (give a suite file or 'default')")
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise SuiteError(f"--suite {source}: cannot read it ({exc.strerror})") from None
        where = str(path)
    data = read_versioned_json(
        raw,
        fmt=SUITE_FORMAT,
        version=SUITE_VERSION,
        what="an evaluation suite",
        where=where,
        error=SuiteError,
    )
    try:
        objects = tuple(
            SuiteObject(
                name=str(o["name"]),
                source=str(o["source"]),
                domain=str(o["domain"]),
                fold=None if o["fold"] is None else int(o["fold"]),
                poses=tuple(
                    GripperPose(tuple(p["position"]), tuple(p["quat"]), tuple(p["openings"]))
                    for p in o["poses"]
                ),
                pose_source=str(o.get("pose_source", "sampler")),
                source_index=tuple(int(p["source_index"]) for p in o["poses"]),
                note=str(o.get("note", "")),
            )
            for o in data["objects"]
        )
        suite = Suite(
            name=str(data["name"]),
            objects=objects,
            seed=int(data["seed"]),
            poses_per_object=int(data["poses_per_object"]),
            perturbation=PerturbationModel(**data["perturbation"]),
            folds=int(data.get("folds", DEFAULT_FOLDS)),
            created=str(data.get("created", "")),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise SuiteError(f"{where}: malformed suite ({type(exc).__name__}: {exc})") from None
    except MjcodesignError as exc:
        raise SuiteError(f"{where}: {exc}") from None
    return _with_digest(suite, raw)


Progress = Callable[[str, int, int], None]


def deal_folds(
    names: Sequence[str], folds: int, *, seed: int = 0, fixed: Mapping[str, int] | None = None
) -> dict[str, int]:
    """Object-level folds of ``names``: object → fold in 0..folds-1.

    ``fixed`` objects keep their fold; the others, sorted by name, are dealt into ``folds`` folds in a
    seeded order (object i of the order goes to fold ``i % folds``).
    """
    if isinstance(folds, bool) or int(folds) < 2:
        raise DesignError(f"folds must be >= 2, got {folds}")
    fixed = {n: int(fixed[n]) for n in names if fixed and n in fixed}
    free = sorted(set(names) - set(fixed))
    order = np.random.default_rng([seed, _FOLD_STREAM]).permutation(len(free))
    return {**fixed, **{free[j]: int(i % folds) for i, j in enumerate(order)}}


def suite_folds(suite: Suite, names: Sequence[str], folds: int, *, seed: int = 0) -> dict[str, int]:
    """Folds of ``names`` for a K-fold surrogate.

    The suite's own folds where it has ``folds`` of them, so that each suite object is held out by the
    fold the suite gives it; other objects are dealt (:func:`deal_folds`, ``seed``).
    """
    own = {o.name: o.fold for o in suite.objects if o.fold is not None} if suite.folds == folds else {}
    return deal_folds(names, folds, seed=seed, fixed=own)


def _pose_objects(sources, poses_per_object, seed, fold_of, anygrasp, cache_dir, progress, warn) -> list:
    """A :class:`SuiteObject` per source that loads and poses (a warning for each one left out)."""
    from mjcodesign.evaluation.candidates import object_candidates
    from mjcodesign.jobs import load_grasp_object

    objects = []
    for i, src in enumerate(sources):
        try:
            obj = load_grasp_object(src, "light", seed=seed, cache_dir=cache_dir)
            cands = object_candidates(
                obj, poses_per_object, seed=seed, anygrasp=anygrasp, cache_dir=cache_dir
            )
        except MjcodesignError as exc:
            if warn:
                warn(f"{src}: left out of the suite ({type(exc).__name__}: {exc})")
            cands = None
        if cands is not None:
            note = ""
            if len(cands) < poses_per_object:
                note = f"{len(cands)} of {poses_per_object} poses: the sampler accepted no more"
                if warn:
                    warn(f"{obj.name}: {note}")
            objects.append(
                SuiteObject(
                    name=obj.name,
                    source=str(src),
                    domain="in-domain" if src in YCB_IN_DOMAIN else "out-of-domain",
                    fold=fold_of.get(src),
                    poses=tuple(cands.poses),
                    pose_source=cands.source,
                    source_index=tuple(int(k) for k in cands.source_index),
                    note=note,
                )
            )
        if progress:
            progress("objects", i + 1, len(sources))
    return objects


def egad_sources(n: int, taken: Sequence[str] = ()) -> tuple[str, ...]:
    """``n`` procedural ``egad-like:I`` sources, I following the highest index among the sources ``taken``."""
    if isinstance(n, bool) or int(n) < 0:
        raise DesignError(f"egad-like objects: a count >= 0, got {n}")
    used = [parse_egad_index(t) for t in taken if str(t).startswith("egad-like:")]
    first = max(used) + 1 if used else 0
    return tuple(f"egad-like:{i}" for i in range(first, first + int(n)))


def add_objects(
    suite: Suite,
    sources: Sequence[str],
    *,
    label: str,
    cache_dir: str | Path | None = None,
    progress: Progress | None = None,
    warn: Callable[[str], None] | None = None,
) -> Suite:
    """``suite`` with ``sources`` posed now under its seed and poses per object, named ``NAME+label``.

    The new objects are out of domain unless they are the paper's in-domain objects (then dealt into
    the suite's folds, :func:`deal_folds` with the suite's seed, keeping the suite's own folds). An
    object already in the suite is refused (:class:`SuiteError`).
    """
    have = {o.source for o in suite.objects}
    twice = [s for s in sources if s in have]
    if twice:
        raise SuiteError(f"suite {suite.name!r} already holds {', '.join(twice[:3])}")
    own = {o.source: o.fold for o in suite.objects if o.fold is not None}
    fold_of = deal_folds(
        [*own, *(s for s in sources if s in YCB_IN_DOMAIN)], suite.folds, seed=suite.seed, fixed=own
    )
    new = _pose_objects(sources, suite.poses_per_object, suite.seed, fold_of, None, cache_dir, progress, warn)
    out = replace(suite, name=f"{suite.name}+{label}", objects=suite.objects + tuple(new))
    return _with_digest(out, json.dumps(out.to_json(), indent=1).encode())


def build_suite(
    sources: Sequence[str],
    *,
    name: str = "adhoc",
    poses_per_object: int = 10,
    seed: int = 0,
    perturbation: PerturbationModel | None = None,
    folds: int = DEFAULT_FOLDS,
    anygrasp: str | Path | None = None,
    cache_dir: str | Path | None = None,
    progress: Progress | None = None,
    warn: Callable[[str], None] | None = None,
) -> Suite:
    """Sample ``poses_per_object`` poses of every object once (seed ``seed``) and freeze them in a suite.

    ``sources``: YCB names, ``egad-like:N`` or mesh files. In-domain objects (the paper's 46) get an
    object-level fold (a seeded permutation dealt into ``folds`` folds). An object with fewer accepted
    poses than asked keeps what it has, with a note that ``warn`` also receives; one that cannot be
    loaded or posed is left out with a warning. Raises :class:`SuiteError` when no object is left.
    """
    if isinstance(poses_per_object, bool) or int(poses_per_object) < 1:
        raise DesignError(f"--poses-per-object must be >= 1, got {poses_per_object}")
    if isinstance(folds, bool) or int(folds) < 2:
        raise DesignError(f"folds must be >= 2, got {folds}")
    fold_of = deal_folds([s for s in sources if s in YCB_IN_DOMAIN], folds, seed=seed)
    objects = _pose_objects(sources, poses_per_object, seed, fold_of, anygrasp, cache_dir, progress, warn)
    if not objects:
        raise SuiteError("no object could be loaded and posed")
    suite = Suite(
        name=name,
        objects=tuple(objects),
        seed=int(seed),
        poses_per_object=int(poses_per_object),
        perturbation=perturbation or PerturbationModel(),
        folds=int(folds),
        created=_dt.datetime.now(_dt.UTC).date().isoformat(),
    )
    return _with_digest(suite, json.dumps(suite.to_json(), indent=1).encode())
