"""The candidate poses of the objects to design for: what the surrogate sees and what the simulator runs.

A :class:`PoseSet` holds, for K objects, their candidate poses (the first ``per_object`` of each, in
the source's order: a dataset's pose index, a candidate file's rank), each pose as the surrogate
reads it (partial cloud, COM, world vertical and volume, gripper frame) and as the simulator runs it
(palm pose and target openings in the scene's world).

:func:`load_pose_set` reads a dataset folder (its stored poses that have a sample: a pose whose every
rollout data generation refused as a bad pose is no candidate, and the surrogate never saw it;
:func:`mjcodesign.data.open_dataset`), a grasp-candidate file (``mjcodesign poses --out``) or a folder of them. A candidate's cloud is drawn
as data generation draws it (:func:`mjcodesign.data.partial_cloud`, the dataset's point count).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.data import CLOUD_POINTS, open_dataset, partial_cloud
from mjcodesign.data.cloud import to_gripper
from mjcodesign.errors import DesignError, OutputError, PoseError
from mjcodesign.models.types import GripperPose
from mjcodesign.objects import load_object
from mjcodesign.poses import read_candidates, scene_offset

__all__ = ["PoseSet", "load_pose_set", "object_key"]

_LOAD_DENSITY = 1000.0  # [kg/m³] any density: a candidate's volume is mass / density


def object_key(source: str) -> str:
    """The name an object goes by: a YCB or egad-like name as is, a mesh file by its stem."""
    s = str(source)
    return Path(s).stem if Path(s).suffix else s


@dataclass(frozen=True, eq=False)
class PoseSet:
    """P candidate poses of K objects; pose rows of one object are contiguous, in the source's order."""

    objects: tuple[str, ...]
    """Object names, shape (K,)."""
    object_of: np.ndarray
    """Object index of each pose, shape (P,), non-decreasing."""
    clouds: np.ndarray
    """Partial point clouds in the gripper frame [m], float32, shape (P, N, 3)."""
    com: np.ndarray
    """Object COM in the gripper frame [m], shape (P, 3)."""
    palms: np.ndarray
    """Palm poses in the scene's world [m], shape (P, 4, 4); row 2 of the rotation is the world vertical
    in the gripper frame."""
    openings: np.ndarray
    """Target openings of fingers A and B [m], shape (P, 2)."""
    volume: np.ndarray
    """Object volume [m³], shape (P,)."""
    source: str = ""
    """Where the poses came from."""
    dataset_rollouts: int | None = None
    """Rollouts the source dataset ran (samples and rejected), None for candidate files."""

    def __post_init__(self) -> None:
        p = len(self.object_of)
        shapes = [np.shape(self.com), np.shape(self.palms), np.shape(self.openings), np.shape(self.volume)]
        if shapes != [(p, 3), (p, 4, 4), (p, 2), (p,)] or len(self.clouds) != p:
            raise DesignError(
                f"a pose set needs one cloud, COM, palm, opening pair and volume per pose ({p})"
            )
        if p and (np.any(np.diff(self.object_of) < 0) or self.object_of[-1] >= len(self.objects)):
            raise DesignError("a pose set's poses must be grouped by object, in object order")

    def __len__(self) -> int:
        return len(self.object_of)

    @property
    def up(self) -> np.ndarray:
        """World vertical in the gripper frame, shape (P, 3)."""
        return self.palms[:, 2, :3]

    def rows(self, k: int) -> np.ndarray:
        """Pose rows of object ``k``."""
        return np.flatnonzero(self.object_of == k)

    def gripper_pose(self, row: int) -> GripperPose:
        """Pose ``row`` as the simulator takes it."""
        return GripperPose.from_matrix(self.palms[row], tuple(float(v) for v in self.openings[row]))

    def select(self, names, per_object: int) -> PoseSet:
        """The first ``per_object`` poses of each of ``names`` (in that order).

        Raises :class:`PoseError` for an object without poses here.
        """
        if per_object < 1:
            raise DesignError(f"poses per object must be >= 1, got {per_object}")
        index = {n: k for k, n in enumerate(self.objects)}
        keys = [object_key(n) for n in names]
        missing = [n for n in keys if n not in index]
        if missing:
            raise PoseError(
                f"no poses for {', '.join(missing[:5])}{' …' if len(missing) > 5 else ''} in {self.source}"
            )
        rows = [self.rows(index[n])[:per_object] for n in keys]
        take = np.concatenate(rows)
        object_of = np.repeat(np.arange(len(keys)), [len(r) for r in rows])
        return dataclasses.replace(
            self,
            objects=tuple(keys),
            object_of=object_of,
            clouds=self.clouds[take],
            com=self.com[take],
            palms=self.palms[take],
            openings=self.openings[take],
            volume=self.volume[take],
        )


def load_pose_set(source: str | Path, *, seed: int = 0, cache_dir: str | Path | None = None) -> PoseSet:
    """Poses of a dataset folder, a candidate file (``.npz``) or a folder of candidate files.

    ``seed`` draws a candidate's cloud points. Raises :class:`PoseError` or :class:`OutputError`.
    """
    path = Path(source)
    if path.is_dir() and (path / "manifest.json").is_file():
        return _from_dataset(path)
    if path.is_dir():
        files = sorted(path.glob("*.npz"))
        if not files:
            raise PoseError(f"{path}: neither a dataset (manifest.json) nor a folder of candidate .npz files")
    elif path.suffix == ".npz" and path.is_file():
        files = [path]
    else:
        raise PoseError(f"{path}: not a candidate .npz, a folder of them or a dataset folder")
    parts = [_from_candidates(f, seed=seed, cache_dir=cache_dir) for f in files]
    names = [p.objects[0] for p in parts]
    if len(set(names)) != len(names):
        raise PoseError(f"{path}: two candidate files for one object")
    cat = {
        k: np.concatenate([getattr(p, k) for p in parts])
        for k in ("clouds", "com", "palms", "openings", "volume")
    }
    object_of = np.repeat(np.arange(len(parts)), [len(p) for p in parts])
    return PoseSet(tuple(names), object_of, source=str(path), **cat)


def _from_dataset(root: Path) -> PoseSet:
    """The stored poses that have a sample (the surrogate never saw a pose data generation refused)."""
    ds = open_dataset(root)
    t = ds.poses()
    if t.num_rows == 0:
        raise PoseError(f"{root}: the dataset holds no pose")
    names = [str(n) for n in t.column("object").to_pylist()]
    keys = np.stack([t.column(k).to_numpy() for k in ("object_index", "pose_index")], axis=1)
    s = ds.samples()
    sampled = set(zip(s.column("object_index").to_pylist(), s.column("pose_index").to_pylist(), strict=True))
    order = np.lexsort((keys[:, 1], keys[:, 0]))
    order = order[[(int(keys[i, 0]), int(keys[i, 1])) in sampled for i in order]]
    if len(order) == 0:
        raise PoseError(f"{root}: no stored pose has a sample (the simulator refused every one)")
    objects = tuple(dict.fromkeys(names[i] for i in order))
    k_of = {n: k for k, n in enumerate(objects)}

    def fixed(name: str, width: int) -> np.ndarray:
        flat = t.column(name).combine_chunks().flatten().to_numpy(zero_copy_only=False)
        return np.asarray(flat, dtype=float).reshape(-1, width)[order]

    clouds = t.column("point_cloud").combine_chunks()
    lengths = np.diff(np.asarray(clouds.offsets))
    if len(set(lengths.tolist())) != 1:
        raise OutputError(f"{root}: point clouds of different sizes")
    pts = np.asarray(clouds.flatten().flatten().to_numpy(zero_copy_only=False), dtype=np.float32)
    counts = ds.manifest.get("counts", {})
    return PoseSet(
        objects,
        np.array([k_of[names[i]] for i in order], dtype=np.int64),
        pts.reshape(len(lengths), -1, 3)[order],
        fixed("com_gripper", 3),
        fixed("palm_pose", 16).reshape(-1, 4, 4),
        fixed("openings", 2),
        (t.column("mass").to_numpy() / t.column("density").to_numpy())[order],
        source=str(root),
        dataset_rollouts=int(counts.get("samples", 0)) + int(counts.get("rejected", 0)),
    )


def _from_candidates(path: Path, *, seed: int, cache_dir) -> PoseSet:
    cands = read_candidates(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            name = str(z["object"])
    except (KeyError, ValueError, OSError) as exc:
        raise PoseError(f"{path}: a candidate file without its object's name ({type(exc).__name__})") from exc
    obj = load_object(name, _LOAD_DENSITY, seed=0, cache_dir=cache_dir)
    rng = np.random.default_rng(seed)
    com_world = scene_offset(obj)[None]
    clouds, com = [], []
    for T, op in zip(cands.matrices, cands.openings, strict=True):
        clouds.append(partial_cloud(obj, T, op, rng, n=CLOUD_POINTS).points)
        com.append(to_gripper(T, com_world)[0])
    n = len(cands)
    return PoseSet(
        (object_key(name),),
        np.zeros(n, dtype=np.int64),
        np.stack(clouds).astype(np.float32),
        np.array(com),
        np.asarray(cands.matrices, dtype=float),
        np.asarray(cands.openings, dtype=float),
        np.full(n, obj.mass / obj.density),
        source=str(path),
    )
