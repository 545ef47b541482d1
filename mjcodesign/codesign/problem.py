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

from mjcodesign.data import CLOUD_POINTS, PoseRows, open_dataset, partial_cloud, read_poses
from mjcodesign.data.cloud import to_gripper
from mjcodesign.errors import DesignError, MeshError, PoseError
from mjcodesign.objects import load_object, published_mass, published_mass_or_none
from mjcodesign.poses import read_candidates, scene_offset

__all__ = ["PoseSet", "load_pose_set", "object_key", "real_densities", "row_densities"]

_LOAD_DENSITY = 1000.0  # [kg/m³] any density: a candidate's volume is mass / density


def object_key(source: str) -> str:
    """The name an object goes by: a YCB or egad-like name as is, a mesh file by its stem."""
    s = str(source)
    return Path(s).stem if Path(s).suffix else s


@dataclass(frozen=True, eq=False)
class PoseSet(PoseRows):
    """P candidate poses of K objects (:class:`~mjcodesign.data.PoseRows`), in the source's order."""

    source: str = ""
    """Where the poses came from."""
    dataset_rollouts: int | None = None
    """Rollouts the source dataset ran (samples and rejected), None for candidate files."""
    sources: tuple[str, ...] = ()
    """What loads each object, shape (K,): a YCB name, ``egad-like:N`` or a mesh file's path (the
    command's or the dataset's); empty: every object loads by its name."""

    def source_of(self, name: str) -> str:
        """What loads object ``name``: its recorded source, else the name itself."""
        if self.sources:
            return self.sources[self.objects.index(name)]
        return name

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
            sources=tuple(self.source_of(n) for n in keys),
            object_of=object_of,
            clouds=self.clouds[take],
            com=self.com[take],
            palms=self.palms[take],
            openings=self.openings[take],
            volume=self.volume[take],
        )


def row_densities(poses: PoseRows, density) -> np.ndarray:
    """The object density [kg/m³] of every pose row, shape (P,).

    ``density``: one value for every object, or a mapping from object name to its density (e.g.
    :func:`real_densities`). Raises :class:`DesignError` for a missing object or a value that is not a
    finite density > 0.
    """
    if isinstance(density, dict):
        missing = [n for n in poses.objects if n not in density]
        if missing:
            raise DesignError(f"no density for {', '.join(missing[:5])}")
        per_object = np.array([float(density[n]) for n in poses.objects])
        rho = per_object[poses.object_of] if len(poses.objects) else np.zeros(0)
    else:
        rho = np.full(len(poses.object_of), float(density))
    if not np.all(np.isfinite(rho) & (rho > 0)):
        raise DesignError(f"densities must be finite values > 0 kg/m³, got {density}")
    return rho


def real_densities(poses: PoseRows, fallback: float | None = None) -> dict[str, float]:
    """Per object of ``poses``, the uniform density [kg/m³] at which it weighs its published mass.

    The volume is the poses' own (the mesh the candidates were made on). An object without a published
    mass (:func:`~mjcodesign.objects.published_mass`) gets ``fallback`` (the ``auto`` rule), or raises
    :class:`MeshError` when it is None.
    """
    out = {}
    for k, name in enumerate(poses.objects):
        volume = float(poses.volume[poses.rows(k)[0]])
        found = published_mass(name) if fallback is None else published_mass_or_none(name)
        out[name] = fallback if found is None else found.mass / volume
    return out


def load_pose_set(
    source: str | Path,
    *,
    seed: int = 0,
    cache_dir: str | Path | None = None,
    sources: dict[str, str] | None = None,
) -> PoseSet:
    """Poses of a dataset folder, a candidate file (``.npz``) or a folder of candidate files.

    ``seed`` draws a candidate's cloud points. ``sources`` maps an object's name (:func:`object_key`)
    to what loads it (a mesh file the command was given); it replaces the source the poses recorded (a
    dataset's object list, a candidate file's object name). Raises :class:`PoseError` or
    :class:`OutputError`.
    """
    path = Path(source)
    given = dict(sources or {})
    if path.is_dir() and (path / "manifest.json").is_file():
        ds = _from_dataset(path)
        return dataclasses.replace(
            ds, sources=tuple(given.get(n, s) for n, s in zip(ds.objects, ds.sources, strict=True))
        )
    if path.is_dir():
        files = sorted(path.glob("*.npz"))
        if not files:
            raise PoseError(f"{path}: neither a dataset (manifest.json) nor a folder of candidate .npz files")
    elif path.suffix == ".npz" and path.is_file():
        files = [path]
    else:
        raise PoseError(f"{path}: not a candidate .npz, a folder of them or a dataset folder")
    parts = [_from_candidates(f, seed=seed, cache_dir=cache_dir, sources=given) for f in files]
    names = [p.objects[0] for p in parts]
    if len(set(names)) != len(names):
        raise PoseError(f"{path}: two candidate files for one object")
    cat = {
        k: np.concatenate([getattr(p, k) for p in parts])
        for k in ("clouds", "com", "palms", "openings", "volume")
    }
    object_of = np.repeat(np.arange(len(parts)), [len(p) for p in parts])
    loads = tuple(p.sources[0] for p in parts)
    return PoseSet(tuple(names), object_of, source=str(path), sources=loads, **cat)


def _from_dataset(root: Path) -> PoseSet:
    """The stored poses that have a sample (the surrogate never saw a pose data generation refused)."""
    ds = open_dataset(root)
    stored = read_poses(ds)
    if len(stored.keys) == 0:
        raise PoseError(f"{root}: the dataset holds no pose")
    s = ds.samples()
    sampled = set(zip(s.column("object_index").to_pylist(), s.column("pose_index").to_pylist(), strict=True))
    keep = np.array([(int(o), int(p)) in sampled for o, p in stored.keys], dtype=bool)
    if not keep.any():
        raise PoseError(f"{root}: no stored pose has a sample (the simulator refused every one)")
    rows = stored.rows
    names = rows.names[keep]
    objects = tuple(dict.fromkeys(names))
    k_of = {n: k for k, n in enumerate(objects)}
    counts = ds.manifest.get("counts", {})
    # A dataset's object goes by its name (a mesh file's stem); its config lists what loaded it.
    recorded = {object_key(s): str(s) for s in (ds.manifest.get("config") or {}).get("objects") or []}
    return PoseSet(
        objects,
        np.array([k_of[n] for n in names], dtype=np.int64),
        rows.clouds[keep],
        rows.com[keep],
        rows.palms[keep],
        rows.openings[keep],
        rows.volume[keep],
        source=str(root),
        dataset_rollouts=int(counts.get("samples", 0)) + int(counts.get("rejected", 0)),
        sources=tuple(recorded.get(n, n) for n in objects),
    )


def _from_candidates(path: Path, *, seed: int, cache_dir, sources: dict[str, str]) -> PoseSet:
    cands = read_candidates(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            name = str(z["object"])
    except (KeyError, ValueError, OSError) as exc:
        raise PoseError(f"{path}: a candidate file without its object's name ({type(exc).__name__})") from exc
    loads = sources.get(object_key(name), name)
    try:
        obj = load_object(loads, _LOAD_DENSITY, seed=0, cache_dir=cache_dir)
    except MeshError as exc:
        raise MeshError(
            f"{path}: object {name!r} of the candidates cannot be loaded ({exc}); give its mesh file in --objects"
        ) from exc
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
        sources=(str(loads),),
    )
