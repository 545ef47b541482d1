"""Ranked grasp candidates: the :class:`Candidates` type, its file and its provenance.

The file (``mjcodesign poses --out FILE.npz``, read by ``grasp --pose FILE.npz[:ROW]`` and data
generation) is an ``.npz`` with these keys, one row per pose, best first (README, Grasp candidates):

- ``matrices`` (n, 4, 4): palm poses in the grasp scene's world [m] (:mod:`mjcodesign.poses.gripper`);
- ``openings`` (n, 2): target openings of fingers A and B [m];
- ``scores`` (n,), ``min_signed_distance`` (n,) [m], ``loss`` (n,);
- ``source`` (str): ``sampler``, or the imported file's name; ``source_index`` (n,): the row of the
  imported file (the sampler's candidate number for sampled poses); ``copy_index`` (n,): 0 for the
  pose itself, k for its k-th noisy copy;
- ``refused_source_index``, ``refused_copy_index`` (m,) and ``refused_reason`` (m,): every dropped
  pose and why;
- ``object`` (str), ``format`` (int, ``FILE_FORMAT``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.errors import PoseError
from mjcodesign.models.types import GripperPose
from mjcodesign.poses.gripper import rotvec

__all__ = [
    "FILE_FORMAT",
    "MAX_PENETRATION",
    "NOISE_ROTATION",
    "NOISE_TRANSLATION",
    "Candidates",
    "approach_spread_deg",
    "augment_poses",
    "load_numpy",
    "rank_order",
    "read_candidates",
    "to_gripper_pose",
]

FILE_FORMAT = 2
"""Version of the candidate file (1: matrices, openings, scores, min_signed_distance, object)."""

MAX_PENETRATION = 1e-3
"""Accepted poses penetrate the object or the ground by at most this much [m] (dense point set)."""
NOISE_TRANSLATION = 3e-3
"""Augmentation noise σ on the palm position [m] (the paper)."""
NOISE_ROTATION = 5e-3
"""Augmentation noise σ on each component of the rotation vector [rad] (the paper)."""


@dataclass
class Candidates:
    """Ranked palm poses [m] in the scene's world, best first, with where each came from."""

    matrices: np.ndarray
    """Palm poses, shape (n, 4, 4)."""
    openings: np.ndarray
    """(s1, s2) per pose [m], shape (n, 2)."""
    scores: np.ndarray
    """Higher is better, in (0, 1], shape (n,)."""
    min_signed_distance: np.ndarray
    """Smallest signed distance of the gripper to the object and the ground [m], shape (n,)."""
    loss: np.ndarray
    """Refinement loss, shape (n,)."""
    rejected: dict[str, int] = field(default_factory=dict)
    """Dropped poses per reason."""
    source_index: np.ndarray | None = None
    """Row of the source each pose came from (imported file row, or sampler candidate), shape (n,)."""
    copy_index: np.ndarray | None = None
    """0 for a source pose itself, k for its k-th noisy copy, shape (n,)."""
    source: str = "sampler"
    """``sampler``, or the imported file's name."""
    refused: list[tuple[int, int, str]] = field(default_factory=list)
    """(source_index, copy_index, reason) of every dropped pose."""

    def __post_init__(self) -> None:
        n = len(self.scores)
        if self.source_index is None:
            self.source_index = np.arange(n, dtype=np.int64)
        if self.copy_index is None:
            self.copy_index = np.zeros(n, dtype=np.int64)

    def __len__(self) -> int:
        return len(self.scores)

    def head(self, n: int) -> Candidates:
        """The best ``n`` (the refusals are kept whole)."""
        return Candidates(
            self.matrices[:n],
            self.openings[:n],
            self.scores[:n],
            self.min_signed_distance[:n],
            self.loss[:n],
            dict(self.rejected),
            source_index=self.source_index[:n],
            copy_index=self.copy_index[:n],
            source=self.source,
            refused=list(self.refused),
        )

    def in_source_order(self) -> Candidates:
        """The same poses sorted by (``source_index``, ``copy_index``): an imported file's row order."""
        order = np.lexsort((self.copy_index, self.source_index))
        return Candidates(
            **{k: getattr(self, k)[order] for k in _ARRAYS},
            rejected=dict(self.rejected),
            source=self.source,
            refused=list(self.refused),
        )

    @classmethod
    def concat(cls, parts: list[Candidates]) -> Candidates:
        """One ranked set from several (:func:`rank_order`); ``rejected`` is the last part's dict."""
        cat = {k: np.concatenate([getattr(c, k) for c in parts]) for k in _ARRAYS}
        order = rank_order(cat["scores"], cat["source_index"])
        return cls(
            **{k: v[order] for k, v in cat.items()},
            rejected=dict(parts[-1].rejected),
            source=parts[0].source,
            refused=[r for c in parts for r in c.refused],
        )

    def approaches(self) -> np.ndarray:
        """Approach directions (palm −z) in the world, shape (n, 3)."""
        return -self.matrices[:, :3, 2]

    def as_dicts(self) -> list[dict]:
        """JSON-ready rows."""
        return [
            {
                "matrix": self.matrices[i].tolist(),
                "openings": self.openings[i].tolist(),
                "score": float(self.scores[i]),
                "min_signed_distance_m": float(self.min_signed_distance[i]),
                "source_index": int(self.source_index[i]),
                "copy_index": int(self.copy_index[i]),
            }
            for i in range(len(self))
        ]

    def refused_dicts(self) -> list[dict]:
        """JSON-ready refusals: ``source_index``, ``copy_index``, ``reason``."""
        return [{"source_index": i, "copy_index": c, "reason": r} for i, c, r in self.refused]

    def save(self, path: str | Path, object_name: str) -> None:
        """The candidate file (module docstring) that ``mjcodesign grasp --pose FILE[:ROW]`` reads."""
        refused = self.refused or [(0, 0, "")][:0]
        np.savez(
            Path(path),
            matrices=self.matrices,
            openings=self.openings,
            scores=self.scores,
            min_signed_distance=self.min_signed_distance,
            loss=self.loss,
            source=np.array(self.source),
            source_index=np.asarray(self.source_index, dtype=np.int64),
            copy_index=np.asarray(self.copy_index, dtype=np.int64),
            refused_source_index=np.array([r[0] for r in refused], dtype=np.int64),
            refused_copy_index=np.array([r[1] for r in refused], dtype=np.int64),
            refused_reason=np.array([r[2] for r in refused], dtype=str),
            object=np.array(object_name),
            format=np.array(FILE_FORMAT),
        )


_ARRAYS = ("matrices", "openings", "scores", "min_signed_distance", "loss", "source_index", "copy_index")


def rank_order(scores: np.ndarray, source_index: np.ndarray) -> np.ndarray:
    """Best first, one pose per source before any second copy of a source: the order (n,).

    Sorted by (how many better poses share the source, −score), so the first rows are distinct grasps
    and noisy copies come after them.
    """
    by_score = np.argsort(-np.asarray(scores), kind="stable")
    seen: dict[int, int] = {}
    rank = np.empty(len(by_score), dtype=np.int64)
    for k in by_score:
        s = int(source_index[k])
        rank[k] = seen.get(s, 0)
        seen[s] = rank[k] + 1
    return np.lexsort((np.arange(len(scores)), -np.asarray(scores), rank))


def load_numpy(path: str | Path, what: str):
    """``np.load`` of an ``.npy``/``.npz`` (no pickles); :class:`PoseError` with one line if unreadable.

    ``what`` names the expected content in the message (e.g. "poses file").
    """
    path = Path(path)
    if not path.is_file():
        raise PoseError(f"{what} not found: {path}")
    if path.stat().st_size == 0:
        raise PoseError(f"{path}: not a {what} (the file is empty)")
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:  # numpy raises ValueError, EOFError, BadZipFile, OSError... on bad bytes
        raise PoseError(f"{path}: not a {what} (not a NumPy .npy/.npz file: {type(exc).__name__})") from exc
    if isinstance(data, np.lib.npyio.NpzFile):
        # An .npz reads its members lazily: one of object dtype (pickled) or damaged would fail at first
        # access, wherever the caller reads it. Read each once here, so that every reader refuses it alike.
        for key in data.files:
            try:
                data[key]
            except Exception as exc:  # ValueError (object arrays: pickles refused), BadZipFile, EOFError...
                data.close()
                reason = (
                    "an object array: pickled data is refused"
                    if isinstance(exc, ValueError)
                    else type(exc).__name__
                )
                raise PoseError(f"{path}: not a {what} (its array {key!r} is {reason})") from exc
    return data


def read_candidates(path: str | Path) -> Candidates:
    """Candidates saved by :meth:`Candidates.save` (``mjcodesign poses --out``); older files too."""
    path = Path(path)
    z = load_numpy(path, "poses file")
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise PoseError(f"{path}: not a poses file (an .npy array, not an .npz of named arrays)")
    try:
        with z:
            M, s = np.asarray(z["matrices"], dtype=float), np.asarray(z["openings"], dtype=float)
            sc, sd = np.asarray(z["scores"], dtype=float), np.asarray(z["min_signed_distance"], dtype=float)
            src = np.asarray(z["source_index"], dtype=np.int64) if "source_index" in z.files else None
            cpy = np.asarray(z["copy_index"], dtype=np.int64) if "copy_index" in z.files else None
            source = str(z["source"]) if "source" in z.files else "sampler"
    except (KeyError, ValueError, TypeError) as exc:
        raise PoseError(f"{path}: not a poses file ({type(exc).__name__}: {exc})") from exc
    if M.ndim != 3 or M.shape[1:] != (4, 4) or s.shape != (len(M), 2) or len(M) == 0:
        raise PoseError(f"{path}: expected matrices (n, 4, 4) and openings (n, 2), n >= 1")
    if sc.shape != (len(M),) or sd.shape != (len(M),):
        raise PoseError(f"{path}: scores and min_signed_distance must have one value per pose")
    for name, a in (("source_index", src), ("copy_index", cpy)):
        if a is not None and a.shape != (len(M),):
            raise PoseError(f"{path}: {name} must have one value per pose")
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(s))):
        raise PoseError(f"{path}: poses file contains NaN or inf")
    return Candidates(M, s, sc, sd, np.zeros(len(M)), source_index=src, copy_index=cpy, source=source)


def to_gripper_pose(c: Candidates, index: int = 0) -> GripperPose:
    """Row ``index`` as a :class:`~mjcodesign.models.types.GripperPose`; :class:`PoseError` if none."""
    if not (0 <= index < len(c)):
        raise PoseError(f"no grasp candidate {index} (of {len(c)}); rejected: {c.rejected}")

    return GripperPose.from_matrix(c.matrices[index], tuple(float(v) for v in c.openings[index]))


def approach_spread_deg(approaches: np.ndarray) -> float:
    """Mean angle [deg] between each approach direction and their mean direction (0: all alike)."""
    a = np.asarray(approaches, dtype=float)
    if len(a) < 2:
        return 0.0
    m = a.mean(axis=0)
    if np.linalg.norm(m) < 1e-12:
        return 90.0
    m /= np.linalg.norm(m)
    return float(np.degrees(np.mean(np.arccos(np.clip(a @ m, -1.0, 1.0)))))


def augment_poses(T: np.ndarray, copies: int, rng: np.random.Generator) -> np.ndarray:
    """Each pose followed by ``copies`` noisy copies, shape (P (1 + copies), 4, 4)."""
    if copies == 0:
        return T
    rep = np.repeat(T[:, None], copies, axis=1).reshape(-1, 4, 4)
    noise_r = rotvec(rng.normal(0.0, NOISE_ROTATION, size=(len(rep), 3)))
    rep[:, :3, :3] = noise_r @ rep[:, :3, :3]
    rep[:, :3, 3] += rng.normal(0.0, NOISE_TRANSLATION, size=(len(rep), 3))
    return np.concatenate([T[:, None], rep.reshape(len(T), copies, 4, 4)], axis=1).reshape(-1, 4, 4)
