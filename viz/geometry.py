"""Triangle surfaces of a compiled MuJoCo model (and of a tet mesh) to log as Rerun meshes.

A :class:`Surface` keeps its triangles and per-vertex block index fixed and computes world vertex
positions from an ``MjData``: mesh and box geoms from ``geom_xpos``/``geom_xmat`` (the chain's blocks,
the palm), a flex from ``flexvert_xpos`` (the flex fingers' deformed surface).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["Surface", "finger_surfaces", "body_geom_surface", "tet_surface", "box_corners", "BOX_TRIANGLES"]

_CHAIN_GEOM = re.compile(r"^([AB])_b(\d+)_[pd]$")
"""Chain block pieces are named ``{finger}_b{block}_{p|d}`` (:mod:`mjcodesign.models.chain`)."""
_BOX_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
BOX_TRIANGLES = np.array(
    [
        [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
        [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
    ]
)  # fmt: skip
"""Outward triangles of the 8 corners ``_BOX_CORNERS`` (x slowest, z fastest)."""


def box_corners(half: np.ndarray) -> np.ndarray:
    """The 8 corners [m] of a box with ``half`` extents (3,) about its centre, in ``BOX_TRIANGLES`` order."""
    return _BOX_CORNERS * np.asarray(half, dtype=float)


_MESH = int(mujoco.mjtGeom.mjGEOM_MESH)
_BOX = int(mujoco.mjtGeom.mjGEOM_BOX)


@dataclass
class Surface:
    """A triangle surface whose vertices follow a model's geoms or one flex."""

    triangles: np.ndarray
    """Vertex indices, shape (k, 3)."""
    vertex_block: np.ndarray
    """Block index of every vertex (base to tip), -1 where there is none, shape (n,)."""
    geom: np.ndarray | None = None
    """Geom id of every vertex, shape (n,); None for a flex surface."""
    local: np.ndarray | None = None
    """Vertices in their geom's frame [m], shape (n, 3)."""
    flex: int | None = None
    flex_slice: slice | None = None
    """This flex's rows of ``flexvert_xpos``."""

    def positions(
        self, geom_xpos: np.ndarray, geom_xmat: np.ndarray, flexvert_xpos: np.ndarray
    ) -> np.ndarray:
        """World vertex positions [m], shape (..., n, 3), from ``MjData`` arrays of one or many states.

        Shapes (..., ngeom, 3), (..., ngeom, 9) and (..., nflexvert, 3), with the same leading axes.
        """
        if self.flex is not None:
            return flexvert_xpos[..., self.flex_slice, :]
        R = geom_xmat[..., self.geom, :].reshape(*geom_xmat.shape[:-2], len(self.geom), 3, 3)
        return geom_xpos[..., self.geom, :] + np.einsum("...nij,nj->...ni", R, self.local)

    def positions_of(self, d: mujoco.MjData) -> np.ndarray:
        """World vertex positions [m] in one ``MjData``, shape (n, 3)."""
        return self.positions(d.geom_xpos, d.geom_xmat, d.flexvert_xpos)


def _ranges(counts: np.ndarray) -> np.ndarray:
    """``0..n-1`` for every n in ``counts``, concatenated."""
    ends = np.cumsum(counts)
    return np.arange(ends[-1]) - np.repeat(ends - counts, counts)


def _from_geoms(m: mujoco.MjModel, geoms: list[int], blocks: list[int]) -> Surface:
    gtype, size, mesh = m.geom_type[geoms], m.geom_size[geoms], m.geom_dataid[geoms]
    bad = (gtype != _MESH) & (gtype != _BOX)
    if bad.any():
        g = np.asarray(geoms)[bad][0]
        raise ValueError(f"geom {g} has type {m.geom_type[g]}: only mesh and box geoms are drawn")
    is_mesh = gtype == _MESH
    k = np.where(is_mesh, mesh, 0)  # a box has no mesh: its rows below are replaced
    nv = np.where(is_mesh, m.mesh_vertnum[k], len(_BOX_CORNERS))
    nf = np.where(is_mesh, m.mesh_facenum[k], len(BOX_TRIANGLES))
    # Every geom's vertices (faces) in turn: j is the index inside its geom, i the geom's position.
    j, i = _ranges(nv), np.repeat(np.arange(len(geoms)), nv)
    local = np.where(
        is_mesh[i, None], m.mesh_vert[m.mesh_vertadr[k][i] + j], _BOX_CORNERS[j % len(_BOX_CORNERS)] * size[i]
    )
    jf, f = _ranges(nf), np.repeat(np.arange(len(geoms)), nf)
    tris = np.where(
        is_mesh[f, None], m.mesh_face[m.mesh_faceadr[k][f] + jf], BOX_TRIANGLES[jf % len(BOX_TRIANGLES)]
    )
    return Surface(
        triangles=tris + (np.cumsum(nv) - nv)[f, None],
        vertex_block=np.repeat(blocks, nv),
        geom=np.repeat(geoms, nv),
        local=local.astype(float),
    )


def _flex_surface(m: mujoco.MjModel, f: int, block_edges: np.ndarray) -> Surface:
    if m.flex_dim[f] != 2:
        raise ValueError(f"flex {f} has dim {m.flex_dim[f]}: only surface (dim 2) flexes are drawn")
    a, n = m.flex_vertadr[f], m.flex_vertnum[f]
    e = m.flex_elemdataadr[f]
    tris = np.asarray(m.flex_elem[e : e + 3 * m.flex_elemnum[f]]).reshape(-1, 3)
    # flex_vert is in the finger frame (x along the finger), so a vertex's block follows from its x.
    x = np.asarray(m.flex_vert[a : a + n, 0])
    return Surface(
        triangles=tris, vertex_block=np.searchsorted(block_edges, x), flex=f, flex_slice=slice(a, a + n)
    )


def _geom_names(m: mujoco.MjModel) -> list[str]:
    """Every geom's name ('' if unnamed), read from ``m.names`` at once."""
    names = bytes(m.names)
    return [names[a : names.index(b"\0", a)].decode() for a in m.name_geomadr]


def finger_surfaces(m: mujoco.MjModel, fingers, block_edges: np.ndarray) -> dict[str, Surface]:
    """One surface per finger, keyed by its letter (``A``, ``B``), from its flex or its block geoms.

    ``fingers`` are the model's :class:`~mjcodesign.models.types.FingerHandle`; ``block_edges`` the inner
    block boundaries along the finger [m] (``[b.x1 for b in blocks[:-1]]``).
    """
    parsed = [_CHAIN_GEOM.match(name) for name in _geom_names(m)]
    out = {}
    for h in fingers:
        letter = h.prefix.rstrip("_")
        if h.flex is not None:
            out[letter] = _flex_surface(
                m, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, h.flex), block_edges
            )
            continue
        hits = [(g, int(p.group(2))) for g, p in enumerate(parsed) if p and p.group(1) == letter]
        if not hits:
            raise ValueError(f"finger {letter} has no block geoms named {_CHAIN_GEOM.pattern}")
        out[letter] = _from_geoms(m, [g for g, _ in hits], [b for _, b in hits])
    return out


def body_geom_surface(m: mujoco.MjModel, bodies: list[int]) -> Surface | None:
    """Every mesh and box geom of ``bodies`` as one rigid-part surface (no blocks), or None."""
    mine = np.zeros(m.nbody, dtype=bool)
    mine[bodies] = True
    gtype = m.geom_type
    geoms = np.flatnonzero(mine[m.geom_bodyid] & ((gtype == _MESH) | (gtype == _BOX))).tolist()
    return _from_geoms(m, geoms, [-1] * len(geoms)) if geoms else None


def tet_surface(tets: np.ndarray, tet_block: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boundary triangles of a tet mesh (faces used by one tet only) and their tets' blocks.

    Uses the 4 corner nodes of each tet (quadratic tets are drawn flat). Returns (triangles (k, 3),
    block (k,)); triangles are wound outwards for positively oriented tets.
    """
    corners = np.asarray(tets)[:, :4]
    # Faces opposite each corner, ordered so that the normal points away from that corner.
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = corners[:, local].reshape(-1, 3)
    owner = np.repeat(np.arange(len(corners)), 4)
    _, inv, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    once = counts[inv.ravel()] == 1
    return faces[once], np.asarray(tet_block)[owner[once]]
