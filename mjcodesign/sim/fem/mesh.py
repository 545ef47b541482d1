"""Structured tetrahedral mesh of one finger, for the Warp FEM reference (`mjcodesign.sim.fem`).

The finger's side profile (x, z) is meshed column by column and extruded over the width (y):

* x grid lines pass through every block face, every trapezoid-cut corner and every block midpoint
  (the tendon waypoints' x), and split the pieces between them into cells of at most ``h`` [m];
* the spine, ``0 <= z <= t``, is one zone of ``spine_layers`` layers under the whole finger;
* above the spine each segment has its own zone, mapped to ``t .. h(x)`` column by column, with one
  layer boundary through the segment's tendon waypoint. Where a trapezoid cut brings ``h(x)`` down to
  ``t`` (the segment's faces towards the flexures) the zone collapses onto the spine's top nodes and the
  degenerate tetrahedra are dropped, so the mesh follows the profile exactly;
* y grid lines are uniform with an even count of cells, so ``y = 0`` is a grid line.

Every hexahedron is split into 6 tetrahedra around its main diagonal (Freudenthal/Kuhn), which is
conforming on a structured grid. Hex-to-tet is chosen over an unstructured mesher because it puts a vertex
exactly on each segment waypoint and on the tip point ``(L, 0, t/2)``, follows the block faces (one
Young's modulus per tet) and makes mesh refinement a single parameter, which the convergence study in
`mjcodesign.sim.fem.finger` records.

Waypoints of segment blocks are mesh vertices. A flexure's waypoint lies above the 2 mm spine, in the
air gap between two segments (the tendon spans the gap), so it is carried by the flexure's mid-section:
``P = (1 + a) p_top - a p_bottom`` with ``a = (z_wp - t) / t`` over the section's top and bottom node
lines, a rigid-normal (Kirchhoff) lever; its nodal forces follow by virtual work. This matches the chain
model, whose flexure waypoint is a site on the flexure body.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.errors import DesignError, MeshError

__all__ = ["FingerMesh", "mesh_finger", "to_quadratic", "embed_points", "P2_EDGES"]

_DEGENERATE = 1e-9
"""Tets below this fraction of a cell's volume are collapsed wedges (dropped)."""
_COINCIDENT = 1e-12
"""Positions closer than this [m] are the same grid line."""
_OUTSIDE = 4e-5
"""Farthest [m] a point to embed may lie outside the mesh. A trapezoid cut's face is curved (the taper
times a linear fall to the spine, curvature ~24 /m on the default design) and the mesh's is its chord
between x grid lines, up to 2 µm inside it on a 1 mm grid: a channel's mouth on that face lies just
outside the mesh, where its weights extrapolate it exactly. Where ``h_flexure`` exceeds a cut's 2.5 mm
(the grasp study's 8 mm) one chord spans the whole cut, 36.7 µm from the face at most on the default
design; its channel mouths lie 5.0-10.3 µm outside it."""


@dataclass(frozen=True)
class FingerMesh:
    """A tetrahedral mesh of one finger in the finger frame [m]."""

    vertices: np.ndarray
    """Rest positions [m], shape (n_vertices, 3)."""
    tets: np.ndarray
    """Node indices, corners positively oriented, shape (n_tets, 4), or (n_tets, 10) for quadratic tets
    (corners, then the midpoints of edges 01, 12, 02, 03, 13, 23)."""
    tet_block: np.ndarray
    """Block index of every tet, base to tip, shape (n_tets,)."""
    base: np.ndarray
    """Indices of the vertices on the base face x = 0 (clamped), shape (n_base,)."""
    tip_face: np.ndarray
    """Indices of the vertices on the tip face x = L, shape (n_tip,)."""
    tip_face_weight: np.ndarray
    """Lumped area weights of ``tip_face`` vertices, summing to 1, shape (n_tip,)."""
    tip: int
    """Index of the vertex at the tip point (L, 0, t/2)."""
    waypoint_weights: np.ndarray
    """Tendon waypoints as combinations of vertices, shape (n_blocks, n_vertices): P = W @ x."""
    h: float
    """Smallest target cell size along x [m]."""

    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return len(self.vertices)

    @property
    def n_tets(self) -> int:
        """Number of tetrahedra."""
        return len(self.tets)

    def volumes(self) -> np.ndarray:
        """Rest volume of every tet [m^3], shape (n_tets,)."""
        x = self.vertices[self.tets[:, :4]]
        return np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6.0


def _subdivide(breaks: list[float], h, size=None) -> np.ndarray:
    """Grid over ``breaks`` with pieces of at most ``h`` (or ``size(a, b)`` for the piece a..b)."""
    pts = [breaks[0]]
    for a, b in itertools.pairwise(breaks):
        hp = h if size is None else size(a, b)
        n = max(1, int(np.ceil((b - a) / hp - 1e-9)))
        pts.extend(np.linspace(a, b, n + 1)[1:])
    return np.array(pts)


def _unique(values) -> list[float]:
    out: list[float] = []
    for v in sorted(values):
        if not out or v - out[-1] > _COINCIDENT:
            out.append(float(v))
    return out


# The 6 Kuhn tetrahedra of the unit cube: a path from (0,0,0) to (1,1,1) along each axis order.
_KUHN = []
for _perm in itertools.permutations(range(3)):
    _c = [0, 0, 0]
    _path = [tuple(_c)]
    for _ax in _perm:
        _c[_ax] = 1
        _path.append(tuple(_c))
    _KUHN.append(_path)


def mesh_finger(
    design: FingerDesign,
    h: float = 1e-3,
    *,
    spine_layers: int = 4,
    ny: int = 2,
    h_flexure: float | None = None,
    waypoint_layers: bool = True,
) -> FingerMesh:
    """Mesh ``design`` with cells of at most ``h`` [m] along x and z.

    ``spine_layers`` (even) layers run through the spine and ``ny`` (even) cells across the width. Along
    the flexures and the trapezoid cuts, where bending concentrates, x cells are at most ``h_flexure``
    (default: the spine layer thickness, i.e. cubic-ish cells in the spine).

    Waypoints that lie inside the spine (near the tip of the uniform-pressure routing) add a layer
    boundary through the whole spine when ``waypoint_layers`` is true. Those layers can be 30 µm thin,
    which cuts the stable explicit step tenfold; with ``waypoint_layers=False`` such a waypoint is instead
    interpolated linearly along the vertical tet edge that brackets it (exact for linear tets).
    """
    if not (np.isfinite(h) and 0 < h <= 0.01):
        raise DesignError(f"mesh size h must be in (0, 10 mm], got {h}")
    if spine_layers < 2 or spine_layers % 2 or ny < 2 or ny % 2:
        raise DesignError("spine_layers and ny must be even and at least 2")
    if h_flexure is None:
        h_flexure = design.flexure_thickness / spine_layers
    ys = np.linspace(-0.5 * design.width, 0.5 * design.width, ny + 1)
    grid = _Grid(design, _x_grid(design, h, h_flexure), ys)
    k_tip = grid.mesh_spine(spine_layers, waypoint_layers)
    for b in grid.blocks:
        if b.kind is BlockKind.SEGMENT:
            grid.mesh_segment(b, h)
    vertices, tets, tet_block, remap = grid.tetrahedra(h)
    W = grid.waypoint_matrix(len(vertices), remap)
    base = np.flatnonzero(np.abs(vertices[:, 0]) <= _COINCIDENT)
    tip_face = np.flatnonzero(np.abs(vertices[:, 0] - design.length) <= _COINCIDENT)
    tip = int(remap[grid.grid_s[grid.nx - 1, grid.ny // 2, k_tip]])
    weight = _face_weights(vertices, tets, tip_face, design.length)
    return FingerMesh(vertices, tets, tet_block, base, tip_face, weight, tip, W, float(min(h, h_flexure)))


def _x_grid(design: FingerDesign, h: float, h_flexure: float) -> np.ndarray:
    """Grid lines along x: every block face, cut corner and block midpoint.

    Cells are at most ``h`` [m], or ``h_flexure`` where the finger bends (flexures and trapezoid cuts).
    """
    blocks = design.blocks()
    breaks = _unique(
        [0.0, design.length] + [v for b in blocks for v in (b.x0, b.x1, b.mid, b.x0 + b.cut0, b.x1 - b.cut1)]
    )

    def size(a: float, b: float) -> float:
        xm = 0.5 * (a + b)
        for blk in blocks:
            if blk.x0 <= xm <= blk.x1:
                bent = blk.kind is BlockKind.FLEXURE or xm < blk.x0 + blk.cut0 or xm > blk.x1 - blk.cut1
                return min(h, h_flexure) if bent else h
        return h

    return _subdivide(breaks, h, size)


class _Grid:
    """The structured grid of one finger as :func:`mesh_finger` builds it.

    Nodes are created once per key (``("s", i, j, k)`` in the spine, ``("b", block, i, j, k)`` above
    it); ``cells`` lists hexahedra as (node grid, i, j, k) of their lowest corner; waypoints are a node
    (``wp_vertex``) or, inside the spine without a layer through them, a point on a vertical edge
    (``wp_edge``: lower node, upper node, weight of the upper).
    """

    def __init__(self, design: FingerDesign, xs: np.ndarray, ys: np.ndarray):
        self.blocks = design.blocks()
        self.width = design.width
        self.t = design.flexure_thickness
        self.wps = design.waypoints()
        self.xs, self.ys = xs, ys
        self.nx, self.ny = len(xs), len(ys) - 1
        self.index: dict[tuple, int] = {}
        self.verts: list[tuple[float, float, float]] = []
        self.cells: list[tuple] = []
        self.wp_vertex: dict[int, int] = {}
        self.wp_edge: dict[int, tuple[int, int, float]] = {}

    def node(self, key: tuple, p: tuple[float, float, float]) -> int:
        """Index of the node ``key`` at ``p`` [m], created on first use."""
        if key not in self.index:
            self.index[key] = len(self.verts)
            self.verts.append(p)
        return self.index[key]

    def top(self, x: float) -> float:
        """Height of the finger's top at ``x`` [m]: the segment's profile, or the spine's top."""
        for b in self.blocks:
            if b.x0 - _COINCIDENT <= x <= b.x1 + _COINCIDENT and b.kind is BlockKind.SEGMENT:
                return float(b.height(x))
        return self.t

    def mesh_spine(self, spine_layers: int, waypoint_layers: bool) -> int:
        """The spine zone ``0 <= z <= t`` under the whole finger; returns the layer through z = t/2."""
        t, xs, ys = self.t, self.xs, self.ys
        in_spine = (
            [float(z) for z in self.wps[:, 2] if _COINCIDENT < z < t - _COINCIDENT] if waypoint_layers else []
        )
        zs = self.zs = _subdivide(_unique([0.0, 0.5 * t, t] + in_spine), t / spine_layers)
        nz = self.spine_layers = len(zs) - 1
        grid_s = self.grid_s = np.empty((self.nx, self.ny + 1, nz + 1), dtype=int)
        for i, j, k in itertools.product(range(self.nx), range(self.ny + 1), range(nz + 1)):
            grid_s[i, j, k] = self.node(("s", i, j, k), (xs[i], ys[j], zs[k]))
        self.cells += [
            (grid_s, i, j, k) for i in range(self.nx - 1) for j in range(self.ny) for k in range(nz)
        ]
        return int(np.argmin(np.abs(zs - 0.5 * t)))

    def mesh_segment(self, b, h: float) -> None:
        """Segment ``b``'s zone above the spine, with a layer boundary through its waypoint."""
        xs, t, ny = self.xs, self.t, self.ny
        cols = [i for i in range(self.nx) if b.x0 - _COINCIDENT <= xs[i] <= b.x1 + _COINCIDENT]
        hmax = max(self.top(xs[i]) for i in cols) - t
        eta_wp = (self.wps[b.index, 2] - t) / (float(b.height(b.mid)) - t)
        etas = _subdivide(_unique([0.0, max(eta_wp, 0.0), 1.0]), h / hmax)
        grid = self._segment_nodes(b, cols, etas)
        self.cells += [
            (grid, i, j, k) for i in range(len(cols) - 1) for j in range(ny) for k in range(len(etas) - 1)
        ]
        i_mid = cols.index(int(np.argmin(np.abs(xs - b.mid))))
        if eta_wp > 0:
            k_wp = int(np.argmin(np.abs(etas - eta_wp)))
            self.wp_vertex[b.index] = int(grid[i_mid, ny // 2, k_wp])
        else:  # a waypoint inside the spine (near the tip of the uniform-pressure routing)
            self._spine_waypoint(b, cols[i_mid])

    def _segment_nodes(self, b, cols: list[int], etas: np.ndarray) -> np.ndarray:
        """Nodes of a segment zone, shape (len(cols), ny + 1, len(etas)).

        ``t .. top(x)`` is mapped column by column; where the top comes down to the spine the zone
        collapses onto the spine's top nodes.
        """
        xs, ys, t, top_k = self.xs, self.ys, self.t, self.spine_layers
        grid = np.empty((len(cols), self.ny + 1, len(etas)), dtype=int)
        for ci, i in enumerate(cols):
            dz = self.top(xs[i]) - t
            for j in range(self.ny + 1):
                grid[ci, j, 0] = self.grid_s[i, j, top_k]
                for k in range(1, len(etas)):
                    if dz <= _COINCIDENT:
                        grid[ci, j, k] = self.grid_s[i, j, top_k]
                    else:
                        grid[ci, j, k] = self.node(("b", b.index, i, j, k), (xs[i], ys[j], t + etas[k] * dz))
        return grid

    def _spine_waypoint(self, b, i: int) -> None:
        """Waypoint of ``b`` inside the spine at column ``i``: a node, or a point on a vertical edge."""
        zs = self.zs
        z_wp = float(self.wps[b.index, 2])
        k_wp = int(np.argmin(np.abs(zs - z_wp)))
        if abs(zs[k_wp] - z_wp) <= _COINCIDENT:
            self.wp_vertex[b.index] = int(self.grid_s[i, self.ny // 2, k_wp])
        else:
            k_lo = int(np.searchsorted(zs, z_wp)) - 1
            a = (z_wp - zs[k_lo]) / (zs[k_lo + 1] - zs[k_lo])
            col = self.grid_s[i, self.ny // 2]
            self.wp_edge[b.index] = (int(col[k_lo]), int(col[k_lo + 1]), float(a))

    def tetrahedra(self, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Kuhn tets of every cell, collapsed wedges dropped, positively oriented, unused nodes removed.

        Returns vertices [m] (n, 3), tets (n_tets, 4), their blocks (n_tets,) and the node index map
        (old node -> vertex, −1 if unused).
        """
        vertices = np.array(self.verts)
        tets = []
        for grid, i, j, k in self.cells:
            for path in _KUHN:
                tets.append([grid[i + a, j + c, k + d] for a, c, d in path])
        tets = np.array(tets, dtype=np.int64)
        x = vertices[tets]
        vol = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6.0
        cell_vol = h * h * self.width / self.ny
        keep = np.abs(vol) > _DEGENERATE * cell_vol
        tets, vol = tets[keep], vol[keep]
        flip = vol < 0
        tets[flip] = tets[flip][:, [0, 2, 1, 3]]
        centroid_x = vertices[tets][:, :, 0].mean(axis=1)
        edges = np.array([b.x1 for b in self.blocks[:-1]])
        tet_block = np.searchsorted(edges, centroid_x)
        used = np.unique(tets)
        remap = np.full(len(vertices), -1)
        remap[used] = np.arange(len(used))
        return vertices[used], remap[tets], tet_block, remap

    def waypoint_matrix(self, n_vertices: int, remap: np.ndarray) -> np.ndarray:
        """Tendon waypoints as combinations of the vertices, (n_blocks, n_vertices): P = W @ x.

        A flexure's waypoint is carried by its mid-section: ``(1 + a) p_top − a p_bottom`` averaged over
        the section's top and bottom node lines, ``a = (z_wp − t) / t``.
        """
        t, ny = self.t, self.ny
        W = np.zeros((len(self.blocks), n_vertices))
        for b in self.blocks:
            if b.index in self.wp_vertex:
                W[b.index, remap[self.wp_vertex[b.index]]] = 1.0
                continue
            if b.index in self.wp_edge:
                lo, hi, a = self.wp_edge[b.index]
                W[b.index, remap[lo]], W[b.index, remap[hi]] = 1.0 - a, a
                continue
            i = int(np.argmin(np.abs(self.xs - b.mid)))
            a = (self.wps[b.index, 2] - t) / t
            tops = remap[self.grid_s[i, :, self.spine_layers]]
            bots = remap[self.grid_s[i, :, 0]]
            W[b.index, tops] = (1.0 + a) / (ny + 1)
            W[b.index, bots] = -a / (ny + 1)
        return W


def _face_weights(vertices: np.ndarray, tets: np.ndarray, face: np.ndarray, x_face: float) -> np.ndarray:
    """Lumped area weights of the vertices on the plane x = x_face (each triangle's area split 1/3)."""
    on = np.zeros(len(vertices), dtype=bool)
    on[face] = True
    area = np.zeros(len(vertices))
    for tet in tets:
        tri = [v for v in tet if on[v]]
        if len(tri) == 3:
            p = vertices[tri]
            a = 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
            area[tri] += a / 3.0
    w = area[face]
    return w / w.sum()


P2_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
"""Corner pairs of the 10-node tet's edge midpoints, in node order 4..9."""


def to_quadratic(mesh: FingerMesh, length: float) -> FingerMesh:
    """The same mesh with 10-node tets: edge midpoints appended after the corner vertices.

    Corner indices, waypoints, the tip vertex and the base set keep their meaning; base and tip face
    gain their midpoints. Tip-face weights become the consistent loads of a uniform traction on
    quadratic triangles (corners 0, each edge midpoint a third of its triangles' area).
    """
    n = mesh.n_vertices
    edges = np.sort(mesh.tets[:, list(P2_EDGES)].reshape(-1, 2), axis=1)
    uniq, inv = np.unique(edges, axis=0, return_inverse=True)
    mids = 0.5 * (mesh.vertices[uniq[:, 0]] + mesh.vertices[uniq[:, 1]])
    vertices = np.vstack([mesh.vertices, mids])
    tets = np.hstack([mesh.tets, n + inv.reshape(-1, 6)])
    base = np.flatnonzero(np.abs(vertices[:, 0]) <= _COINCIDENT)
    tip_face = np.flatnonzero(np.abs(vertices[:, 0] - length) <= _COINCIDENT)
    on = np.zeros(len(vertices), dtype=bool)
    on[tip_face] = True
    load = np.zeros(len(vertices))
    corner_on = on[tets[:, :4]]
    for e in np.flatnonzero(corner_on.sum(axis=1) == 3):
        tri = [k for k in range(4) if corner_on[e, k]]
        p = vertices[tets[e, tri]]
        area = 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
        for j, (a, b) in enumerate(P2_EDGES):
            if a in tri and b in tri:
                load[tets[e, 4 + j]] += area / 3.0
    w = load[tip_face]
    W = np.hstack([mesh.waypoint_weights, np.zeros((len(mesh.waypoint_weights), len(mids)))])
    return FingerMesh(vertices, tets, mesh.tet_block, base, tip_face, w / w.sum(), mesh.tip, W, mesh.h)


def embed_points(mesh: FingerMesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rest-mesh tet holding each of ``points`` [m] (k, 3) and its shape-function weights.

    Returns (W, tet): W of shape (k, n_vertices) with ``W @ mesh.vertices == points`` to round-off, and
    the tet index of each point, shape (k,). W holds the tet's barycentric coordinates L for 4-node tets;
    for 10-node tets (straight edges, so L is exact) the quadratic shape functions, L_i (2 L_i − 1) at
    the corners and 4 L_i L_j at the midpoint of edge ij, which reproduce linear fields exactly. The tet
    is the one the point lies deepest in (largest distance to its nearest face plane, negative outside;
    lowest index on a tie); `MeshError` if that is more than ``_OUTSIDE`` outside the mesh.
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    corners = mesh.vertices[mesh.tets[:, :4]]  # (n_tets, 4, 3)
    dm_inv = np.linalg.inv(np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1)))
    grad = np.concatenate([-dm_inv.sum(axis=1, keepdims=True), dm_inv], axis=1)  # ∇L_i [1/m], (n_tets, 4, 3)
    altitude = 1.0 / np.linalg.norm(grad, axis=2)  # corner i's distance to its opposite face [m]
    W = np.zeros((len(points), mesh.n_vertices))
    tet = np.zeros(len(points), dtype=int)
    for k, p in enumerate(points):
        lam = np.einsum("tij,tj->ti", dm_inv, p[None] - corners[:, 0])
        bary = np.c_[1.0 - lam.sum(axis=1), lam]  # (n_tets, 4)
        depth = (bary * altitude).min(axis=1)  # signed distance to the nearest face plane [m]
        tet[k] = e = int(np.argmax(depth))
        if depth[e] < -_OUTSIDE:
            raise MeshError(f"point {p} [m] lies {-depth[e]:.2e} m outside the finger mesh")
        L = bary[e]
        if mesh.tets.shape[1] == 4:
            W[k, mesh.tets[e]] = L
        else:
            shape = np.r_[L * (2.0 * L - 1.0), [4.0 * L[a] * L[b] for a, b in P2_EDGES]]
            W[k, mesh.tets[e]] = shape
    return W, tet
