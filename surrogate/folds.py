"""K surrogates of an object-level K-fold split, and which one may judge an object it never saw.

``mjcodesign train --folds K`` writes a folder with one checkpoint per fold (``fold0/``, ``fold1/``, …;
each a :mod:`.checkpoint` folder) and a manifest, ``folds.json``: the dataset, and per fold its
sub-folder, the objects it held out and the objects it trained on, with its held-out metrics. Every
object of the dataset is held out by exactly one fold, so that an evaluation can score every object
with a network that never trained on it (:meth:`FoldSurrogates.for_object`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mjcodesign.errors import OutputError
from mjcodesign.outputs import read_versioned_json
from mjcodesign.surrogate.checkpoint import CONFIG, load_surrogate
from mjcodesign.surrogate.inference import Surrogate

__all__ = ["FOLDS_FILE", "FOLDS_FORMAT", "FOLDS_VERSION", "FoldSurrogates", "load_any", "load_folds"]

FOLDS_FILE = "folds.json"
FOLDS_FORMAT = "mjcodesign-surrogate-folds"
FOLDS_VERSION = 1
"""Bumped when a reader of the manifest must change."""


@dataclass(frozen=True, eq=False)
class FoldSurrogates:
    """The fold networks of a K-fold folder and what each one held out and trained on."""

    surrogates: tuple[Surrogate, ...]
    held_out: tuple[frozenset[str], ...]
    """Per fold: the objects it held out (its test)."""
    trained_on: tuple[frozenset[str], ...]
    """Per fold: the objects whose samples it trained or early-stopped on."""
    meta: dict
    """The manifest (``folds.json``): ``dataset`` (as a checkpoint records it), ``folds``, metrics."""

    def fold_for(self, name: str) -> int:
        """The fold that held ``name`` out; for an object no fold trained on, the first fold."""
        for k, held in enumerate(self.held_out):
            if name in held:
                return k
        for k, seen in enumerate(self.trained_on):
            if name not in seen:
                return k
        raise OutputError(f"every fold trained on {name}: no held-out network for it")

    def for_object(self, name: str) -> Surrogate:
        """The network of :meth:`fold_for` (one that never trained on ``name``)."""
        return self.surrogates[self.fold_for(name)]

    def held_out_for(self, name: str) -> bool:
        """Whether ``name`` is an object of the folds' dataset (held out by one fold, seen by the others)."""
        return any(name in held for held in self.held_out)


def load_folds(path: str | Path) -> FoldSurrogates:
    """The fold networks of a ``train --folds`` folder; :class:`OutputError` if it is not one or is broken."""
    root = Path(path)
    what = "a K-fold surrogate folder"
    manifest = read_versioned_json(
        root / FOLDS_FILE, fmt=FOLDS_FORMAT, version=FOLDS_VERSION, what=what, where=root
    )
    try:
        folds = manifest["folds"]
        surrogates = tuple(load_surrogate(root / f["path"]) for f in folds)
        held = tuple(frozenset(map(str, f["held_out"])) for f in folds)
        seen = tuple(frozenset(map(str, f["train_objects"])) for f in folds)
    except (KeyError, TypeError) as exc:
        raise OutputError(f"{root / FOLDS_FILE}: malformed ({type(exc).__name__}: {exc})") from None
    if not surrogates:
        raise OutputError(f"{root / FOLDS_FILE}: lists no fold")
    return FoldSurrogates(surrogates, held, seen, manifest)


def load_any(path: str | Path) -> Surrogate | FoldSurrogates:
    """A checkpoint folder's :class:`Surrogate`, or a K-fold folder's :class:`FoldSurrogates`."""
    root = Path(path)
    if (root / FOLDS_FILE).is_file() and not (root / CONFIG).is_file():
        return load_folds(root)
    return load_surrogate(root)
