"""Collision geometry: a CoACD convex decomposition of an object, cached on disk.

The cache lives under a caller-given directory, keyed by the mesh's hash and the settings. A mesh that
is already convex is its own single hull and never reaches CoACD.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from mjcodesign.errors import MeshError
from mjcodesign.objects.mesh import GraspObject
from mjcodesign.objects.sets import check_seed

__all__ = ["CoacdSettings", "convex_decomposition"]


@dataclass(frozen=True, kw_only=True)
class CoacdSettings:
    """CoACD parameters; the defaults are the fast settings (6.8 s, 15 hulls on a 5k-face mesh)."""

    threshold: float = 0.1
    mcts_iterations: int = 40
    mcts_max_depth: int = 2
    resolution: int = 1000
    preprocess_resolution: int = 30
    decimate: bool = True
    max_ch_vertex: int = 64
    max_convex_hull: int = 16
    """Cap on the hull count: collision cost grows with hulls."""
    seed: int = 0

    def __post_init__(self) -> None:
        if not (0.01 <= self.threshold <= 1.0):
            raise MeshError(f"coacd threshold must be in [0.01, 1], got {self.threshold}")
        if self.max_convex_hull < 1 or self.max_ch_vertex < 4:
            raise MeshError("coacd needs max_convex_hull >= 1 and max_ch_vertex >= 4")
        check_seed(self.seed)


def _mesh_key(mesh, settings: CoacdSettings) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(json.dumps(asdict(settings), sort_keys=True).encode())
    return h.hexdigest()[:32]


def _read_cache(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    with np.load(path) as z:
        n = int(z["n"])
        return [(z[f"v{i}"], z[f"f{i}"]) for i in range(n)]


def _write_cache(path: Path, hulls: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """Write ``hulls`` to ``path`` through a temporary file, so a reader never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {"n": np.array(len(hulls))}
    for i, (v, f) in enumerate(hulls):
        arrays[f"v{i}"], arrays[f"f{i}"] = v, f
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(path)


def _run_coacd(mesh, settings: CoacdSettings, name: str) -> list[tuple[np.ndarray, np.ndarray]]:
    try:
        import coacd
    except ImportError as exc:
        raise MeshError("convex decomposition needs the coacd package") from exc
    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)),
        threshold=settings.threshold,
        max_convex_hull=settings.max_convex_hull,
        mcts_iterations=settings.mcts_iterations,
        mcts_max_depth=settings.mcts_max_depth,
        resolution=settings.resolution,
        preprocess_resolution=settings.preprocess_resolution,
        decimate=settings.decimate,
        max_ch_vertex=settings.max_ch_vertex,
        seed=settings.seed,
    )
    hulls = [(np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64)) for v, f in parts]
    if not hulls:
        raise MeshError(f"{name}: convex decomposition returned no pieces")
    return hulls


def convex_decomposition(
    obj: GraspObject, settings: CoacdSettings | None = None, *, cache_dir: str | Path | None = None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Convex pieces of ``obj`` (COM frame), stored in ``obj.hulls`` and cached in ``cache_dir``.

    The cache file is ``<cache_dir>/coacd/<sha256(vertices, faces, settings)>.npz``; a convex mesh is
    returned as one hull without running CoACD.
    """
    settings = settings or CoacdSettings()
    mesh = obj.mesh
    if mesh.is_convex:
        obj.hulls = [(np.asarray(mesh.vertices), np.asarray(mesh.faces))]
        return obj.hulls
    path = None
    if cache_dir is not None:
        path = Path(cache_dir) / "coacd" / f"{_mesh_key(mesh, settings)}.npz"
        if path.is_file():
            obj.hulls = _read_cache(path)
            return obj.hulls
    hulls = _run_coacd(mesh, settings, obj.name)
    if path is not None:
        _write_cache(path, hulls)
    obj.hulls = hulls
    return hulls
