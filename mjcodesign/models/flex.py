"""Soft finger as a MuJoCo flex with interpolated (trilinear or quadratic) dofs.

The flex spans the finger's bounding box with an interpolation grid of ``n x 1 x 1`` cells; the
finger's real surface (segments, V gaps, flexures) is the collision mesh, carried by the grid.
MuJoCo computes each cell's stiffness for the whole box cell, and stores it linearly in Young's
modulus (``m.flex_stiffness``, one ``(3 n_node)^2`` record per cell). Per-block stiffness is written by
scaling each cell's record to an *effective* modulus:

* **Homogenisation.** A box cell has section ``I_box = w H^3 / 12``, the real finger inside it has
  ``I(x)`` (a 2 mm flexure, a tapered segment). The cell gets
  ``E_cell = l_cell / (I_box ∫_cell dx / (E(x) I(x)))``, so its bending compliance equals the real
  one (series springs). When cells coincide with blocks (the default design) every cell holds exactly
  one block.
* **Calibration.** MuJoCo 4.0 integrates each cell's stiffness over the real mesh volume
  (finite-cell quadrature), so thin flexures are soft as they should be; but a cell-wide interpolation
  field cannot concentrate bending in a 2 mm flexure (trilinear: parasitic shear) or in the trapezoid
  cut zones of a segment (quadratic). On the paper's finger the uncalibrated flex is 9.3x (trilinear,
  17 cells) and 1.6x (quadratic, 17 cells) too stiff. One factor per discretisation, measured as
  ``r = δ_flex / δ_EB`` on this finger with uniform E (:func:`locking_factor`, a linear static solve,
  cached), scales every cell: ``E_cell ← r E_cell``. It is computed, not tuned; piecewise designs
  are then checked against beam theory, not fitted.

Known limit: the homogenised box bends about its mid-height, while the real finger bends about its
spine, and a flexure cell is softer axially than the real flexure. Tip-load bending matches beam
theory; tendon curl is cross-checked against FEM separately.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from mjcodesign.design.beam import block_tip_rotation, cantilever_tip_deflection, section_compliance
from mjcodesign.design.calibration import calibration_for
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.tendon_law import tendon_forces
from mjcodesign.errors import DesignError
from mjcodesign.models.spec import new_spec
from mjcodesign.models.types import (
    CONTYPE_FINGER,
    CONTYPE_WORLD,
    FingerHandle,
    FingerModel,
    SimOptions,
    tendon_exit_site,
)

__all__ = [
    "add_flex_finger",
    "apply_cell_young",
    "fit_cell_young",
    "flex_block_rotations",
    "rescale_cell_young",
    "cell_young",
    "effective_young",
    "finger_mesh",
    "lagrange_weights",
    "locking_factor",
    "flex_cells",
    "TipLoad",
    "grid_weights",
    "assemble_stiffness",
    "static_tip_deflection",
    "linear_curl",
    "linear_tendon_load",
    "grid_rest",
    "static_tip_solve",
    "load_nodes",
]

_E_REF = 1e6
"""Modulus the flex is compiled with [Pa]; every cell record is then scaled from it."""
_FLEX_RADIUS = 5e-4
"""Collision radius of the flex surface [m]."""
_NODE_INERTIA = 1e-9
"""Rotational inertia of node bodies [kg m^2]; they only translate, so it never acts."""


def finger_mesh(design: FingerDesign) -> tuple[np.ndarray, np.ndarray]:
    """Watertight surface of the finger in the finger frame: vertices (n, 3) [m], faces (m, 3)."""
    import trimesh
    from shapely.geometry import Polygon

    top = []
    for b in reversed(design.blocks()):
        top.extend(b.side_profile()[2:].tolist())
    pts = [(0.0, 0.0), (design.length, 0.0)] + [tuple(p) for p in top]
    clean = [pts[0]]
    for p in pts[1:]:
        if np.hypot(p[0] - clean[-1][0], p[1] - clean[-1][1]) > 1e-9:
            clean.append(p)
    mesh = trimesh.creation.extrude_polygon(Polygon(clean), height=design.width)
    v = mesh.vertices.copy()
    verts = np.c_[v[:, 0], v[:, 2] - 0.5 * design.width, v[:, 1]]
    faces = mesh.faces[:, ::-1].copy()  # swapping y and z mirrors, so flip the winding back
    return verts, faces


def flex_cells(design: FingerDesign, options: SimOptions, *, quadratic: bool = False) -> int:
    """Cells along the finger.

    Aligned with block boundaries when the design allows (17 for the paper's finger, segments two
    cells, flexures one), otherwise one cell per block. Misaligned cells mix flexure and segment
    material under one smooth field: 11 quadratic cells were 11x too stiff against 1.6x for 17.
    """
    if options.flex_cells is not None:
        if options.flex_cells < 1:
            raise DesignError("flex_cells must be >= 1")
        return int(options.flex_cells)
    unit = design.flexure_len
    n = round(design.length / unit)
    edges = np.array([b.x1 for b in design.blocks()])
    if np.allclose(edges / (design.length / n), np.round(edges / (design.length / n)), atol=1e-6):
        return int(n)
    return design.n_blocks


def cell_young(design: FingerDesign, young: np.ndarray, n_cells: int) -> np.ndarray:
    """Modulus of each cell [Pa], shape (n_cells,): the block's E when a cell lies in one block.

    A cell that straddles blocks gets the series (compliance-weighted) average
    ``E_cell = ∫ dx / I(x) / ∫ dx / (E(x) I(x))`` over the real sections inside it.
    """
    edges = np.linspace(0.0, design.length, n_cells + 1)
    out = np.empty(n_cells)
    blocks = design.blocks()
    for c in range(n_cells):
        a, b = edges[c], edges[c + 1]
        geo = sum(section_compliance(blk, a, b) for blk in blocks)
        comp = sum(section_compliance(blk, a, b) / e for blk, e in zip(blocks, young, strict=True))
        out[c] = geo / comp
    return out


def effective_young(design: FingerDesign, young: np.ndarray, model: str = "fem") -> np.ndarray:
    """Block moduli [Pa] that make beam theory's block rotations the calibrated FEM's, (n_blocks,).

    ``fem``: ``E_i Δφ_i(beam) / Δφ_i(FEM)`` with Δφ_i block i's rotation under a tip load (the
    per-block correction of :mod:`mjcodesign.design.calibration`: ~0.8 for a flexure between stiff
    segments, up to 5x softer for a segment's flexure roots); ``beam``: ``young`` itself. The cells are
    then homogenised from these moduli as before.
    """
    young = np.asarray(young, dtype=float)
    if model == "beam":
        return young
    fem = np.diff(np.r_[0.0, calibration_for(design).face_angles(young)])
    return young * block_tip_rotation(design, young) / fem


def node_weights(order: int) -> np.ndarray:
    """Consistent 1-D nodal weights of a uniform load over one cell: (1/2, 1/2) or Simpson (1, 4, 1)/6."""
    return np.array([0.5, 0.5]) if order == 1 else np.array([1.0, 4.0, 1.0]) / 6.0


def lagrange_weights(xi: np.ndarray, order: int) -> np.ndarray:
    """1-D Lagrange shape functions on [0, 1] with ``order + 1`` equispaced nodes, shape (len(xi), order+1)."""
    xi = np.asarray(xi, dtype=float)
    if order == 1:
        return np.stack([1 - xi, xi], axis=-1)
    return np.stack([2 * (xi - 0.5) * (xi - 1), -4 * xi * (xi - 1), 2 * xi * (xi - 0.5)], axis=-1)


def _grid_box(design: FingerDesign) -> tuple[np.ndarray, np.ndarray]:
    """Lower corner and extent [m] of the flex's bounding box in the finger frame."""
    lo = np.array([0.0, -0.5 * design.width, 0.0])
    ext = np.array([design.length, design.width, design.height_base])
    return lo, ext


def grid_weights(design: FingerDesign, n_cells: int, order: int, points: np.ndarray) -> np.ndarray:
    """Interpolation weights of finger-frame points onto the node grid, shape (n_points, n_nodes)."""
    nx, ny, nz = n_cells * order + 1, order + 1, order + 1
    lo, ext = _grid_box(design)
    u = (points - lo) / ext
    W = np.zeros((len(points), nx * ny * nz))
    cx = np.clip(np.floor(u[:, 0] * n_cells).astype(int), 0, n_cells - 1)
    lx = u[:, 0] * n_cells - cx
    wx, wy, wz = (
        lagrange_weights(lx, order),
        lagrange_weights(u[:, 1], order),
        lagrange_weights(u[:, 2], order),
    )
    for p in range(len(points)):
        for a in range(order + 1):
            gi = cx[p] * order + a
            for b in range(order + 1):
                for c in range(order + 1):
                    W[p, gi * ny * nz + b * nz + c] += wx[p, a] * wy[p, b] * wz[p, c]
    return W


def _node_masses(design: FingerDesign, n_cells: int, order: int, shape: tuple[int, int, int]) -> np.ndarray:
    """Lumped nodal mass [kg], shape ``shape``.

    Each cell's real mass is split by Simpson (quadratic) or equal (trilinear) weights.
    """
    edges = np.linspace(0.0, design.length, n_cells + 1)
    w1 = node_weights(order)
    node_mass = np.zeros(shape)
    for c in range(n_cells):
        vol = sum(_overlap_volume(b, edges[c], edges[c + 1]) for b in design.blocks())
        cell_m = vol * design.density
        node_mass[c * order : c * order + order + 1] += cell_m * np.einsum("i,j,k->ijk", w1, w1, w1)
    return node_mass


def _add_nodes(
    parent, design: FingerDesign, shape: tuple[int, int, int], node_mass: np.ndarray, handle: FingerHandle
) -> tuple[list[str], list[np.ndarray]]:
    """Node bodies (three slide joints each) under ``parent``; the base face is clamped to it.

    Returns the flex's ``nodebody`` names and ``node`` positions (in each node body's frame).
    """
    nx, ny, nz = shape
    lo, ext = _grid_box(design)
    nodebody, node = [], []
    for gi in range(nx):
        for gj in range(ny):
            for gk in range(nz):
                p = lo + ext * np.array([gi / (nx - 1), gj / (ny - 1), gk / (nz - 1)])
                if gi == 0:  # the base face is clamped to the parent body
                    nodebody.append(parent.name)
                    node.append(p)
                    continue
                b = parent.add_body(name=f"{handle.prefix}n{gi}_{gj}_{gk}", pos=p)
                b.explicitinertial = True
                b.ipos = [0.0, 0.0, 0.0]  # without it, MjSpec.to_xml drops the inertial element
                b.mass = float(node_mass[gi, gj, gk])
                b.inertia = [_NODE_INERTIA] * 3
                for d in range(3):
                    ax = np.zeros(3)
                    ax[d] = 1.0
                    b.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=ax)
                nodebody.append(b.name)
                node.append(np.zeros(3))
                handle.bodies.append(b.name)
    return nodebody, node


def _add_flex_element(
    spec: mujoco.MjSpec,
    parent,
    design: FingerDesign,
    handle: FingerHandle,
    options: SimOptions,
    cells: tuple[int, int],
    nodes: tuple[list[str], list[np.ndarray]],
) -> None:
    """The flex itself: the finger mesh as surface, carried by ``nodes`` on a (n_cells, order) grid."""
    n_cells, order = cells
    nodebody, node = nodes
    verts, faces = finger_mesh(design)
    f = spec.add_flex()
    f.name = handle.flex
    f.dim = 2
    f.order = order
    f.cellcount = [n_cells, 1, 1]
    f.nodebody = nodebody
    f.node = np.asarray(node).ravel().tolist()
    f.vert = verts.ravel().tolist()
    f.vertbody = [parent.name] * len(verts)
    f.elem = faces.ravel().tolist()
    f.young = _E_REF
    f.poisson = options.poisson
    f.damping = options.damping_time
    f.radius = _FLEX_RADIUS
    f.selfcollide = mujoco.mjtFlexSelf.mjFLEXSELF_NONE
    f.contype = CONTYPE_FINGER
    f.conaffinity = CONTYPE_WORLD
    f.friction = [options.friction, 0.005, 0.0001]
    f.rgba = [0.2, 0.6, 0.85, 1]


def _add_waypoint_sites(
    spec: mujoco.MjSpec, design: FingerDesign, prefix: str, shape: tuple[int, int, int], order: int
) -> list[list[str]]:
    """Tendon waypoint sites on the node nearest in (x, z), one site chain per tendon copy.

    Trilinear grids have no mid-width node, so the tendon is split into two half-tension copies on
    the left and right nodes (symmetric).
    """
    nx, ny, nz = shape
    lo, ext = _grid_box(design)
    wps = design.waypoints()
    sides = [order // 2] if order == 2 else [0, 1]
    chains = []
    for gj in sides:
        chain = []
        for i, w in enumerate(wps):
            u = (w - lo) / ext
            gi = max(1, int(round(u[0] * (nx - 1))))
            gk = int(round(u[2] * (nz - 1)))
            body = spec.body(f"{prefix}n{gi}_{gj}_{gk}")
            p_node = lo + ext * np.array([gi / (nx - 1), gj / (ny - 1), gk / (nz - 1)])
            s = body.add_site(name=f"{prefix}wp{i}_{gj}", pos=w - p_node, size=[0.0008, 0, 0], group=3)
            chain.append(s.name)
        chains.append(chain)
    return chains


def add_flex_finger(
    spec: mujoco.MjSpec,
    parent,
    design: FingerDesign,
    young: np.ndarray,
    prefix: str,
    options: SimOptions,
    *,
    quadratic: bool,
    locking: float | None = None,
) -> FingerHandle:
    """Add a flex finger under ``parent`` (whose frame is the finger frame); base face pinned."""
    order = 2 if quadratic else 1
    n_cells = flex_cells(design, options, quadratic=quadratic)
    shape = (n_cells * order + 1, order + 1, order + 1)
    model = FingerModel.FLEX_QUADRATIC if quadratic else FingerModel.FLEX
    handle = FingerHandle(
        prefix=prefix,
        model=model,
        base_body=parent.name,
        waypoint_sites=[],
        tip_site=f"{prefix}tip",
        flex=f"{prefix}flex",
    )
    node_mass = _node_masses(design, n_cells, order, shape)
    nodes = _add_nodes(parent, design, shape, node_mass, handle)
    _add_flex_element(spec, parent, design, handle, options, (n_cells, order), nodes)
    e_cell = cell_young(design, effective_young(design, young, options.stiffness_model), n_cells)
    r = locking if locking is not None else locking_factor(design, n_cells, options.poisson, order)
    handle.cell_young = e_cell * r
    if options.stiffness_model == "fem" and locking is None:
        target = np.diff(np.r_[0.0, calibration_for(design).face_angles(np.asarray(young, float))])
        handle.fem_fit = (design, target)
    chains = _add_waypoint_sites(spec, design, prefix, shape, order)
    handle.waypoint_sites = chains[0]
    handle.site_chains = chains
    tip_body = spec.body(f"{prefix}n{shape[0] - 1}_0_0")
    tip_body.add_site(
        name=handle.tip_site,
        pos=[0, 0.5 * design.width, 0.5 * design.flexure_thickness],
        size=[0.0008, 0, 0],
        group=3,
    )
    handle.grid = (*shape, n_cells, order)
    return handle


def _overlap_volume(block, a: float, b: float) -> float:
    lo, hi = max(a, block.x0), min(b, block.x1)
    if hi <= lo:
        return 0.0
    xg, wg = np.polynomial.legendre.leggauss(16)
    x = 0.5 * (hi - lo) * xg + 0.5 * (hi + lo)
    return float(0.5 * (hi - lo) * np.sum(wg * block.height(x)) * block.width)


def _cell_records(m: mujoco.MjModel, handle: FingerHandle) -> np.ndarray:
    """The handle's flex stiffness records in ``m``, one row per cell (a view: writes go to ``m``)."""
    fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, handle.flex)
    n_cells = len(handle.cell_young)
    adr = int(m.flex_stiffnessadr[fid])
    nxt = [int(m.flex_stiffnessadr[j]) for j in range(m.nflex) if m.flex_stiffnessadr[j] > adr]
    end = min(nxt) if nxt else m.flex_stiffness.size
    size = (end - adr) // n_cells
    if size * n_cells != end - adr:
        raise DesignError("unexpected flex stiffness layout; cannot write per-cell modulus")
    return m.flex_stiffness[adr:end].reshape(n_cells, size)


def apply_cell_young(m: mujoco.MjModel, handle: FingerHandle) -> None:
    """Scale each cell's stiffness record of the compiled flex (at the reference modulus) to the cell moduli.

    With ``handle.fem_fit`` (the ``fem`` stiffness model) the cell moduli are first fitted so that the
    flex's own linear blocks turn as the FEM's do (:func:`fit_cell_young`).
    """
    rec = _cell_records(m, handle)
    handle.unit_records = rec / _E_REF
    if handle.fem_fit is not None:
        design, target = handle.fem_fit
        handle.cell_young = fit_cell_young(m, handle, design, handle.unit_records, handle.cell_young, target)
    rec *= (handle.cell_young / _E_REF)[:, None]


_FIT_ITER = 30
"""Fixed-point iterations of :func:`fit_cell_young` at most."""
_FIT_RTOL = 1e-4
"""It stops when no block's rotation is further than this from the FEM's (relative)."""


def _block_planes(design: FingerDesign, handle: FingerHandle) -> np.ndarray:
    """Index of the node plane at every block's distal face (the cells follow the blocks)."""
    nx = handle.grid[0]
    planes = np.array([round(b.x1 / design.length * (nx - 1)) for b in design.blocks()])
    if not np.allclose(planes / (nx - 1) * design.length, [b.x1 for b in design.blocks()], atol=1e-9):
        raise DesignError("the flex's cells do not follow the blocks: no per-block calibration")
    return planes


def flex_block_rotations(
    design: FingerDesign, handle: FingerHandle, unit: np.ndarray, cell_e: np.ndarray
) -> np.ndarray:
    """Block rotations [rad/N] of the linear flex under a unit tip load, cell moduli ``cell_e`` [Pa].

    ``unit`` (n_cells, nd²): the cells' stiffness records per pascal (MuJoCo's sign). A block's rotation
    is the change of the spine section's rotation, −(u_x(z = t) − u_x(z = 0)) / t interpolated in z and
    averaged over the width, from its proximal to its distal face, as
    `mjcodesign.sim.fem.FemFinger.section_angles` measures the FEM's.
    """
    nx, ny, nz, _, order = handle.grid
    K = _assemble(cell_e[:, None] * unit, handle.grid)
    f = _tip_load(handle)
    n = len(f)
    free = np.arange(3 * ny * nz, n)
    u = np.zeros(n)
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    ux = u.reshape(nx, ny, nz, 3)[..., 0].mean(axis=1)  # (nx, nz): mean over the width
    t = design.flexure_thickness
    spine = lagrange_weights(np.array([0.0, t / design.height_base]), order)  # u_x at z = 0 and z = t
    at = ux @ spine.T
    phi = -(at[:, 1] - at[:, 0]) / t
    return np.diff(np.r_[0.0, phi[_block_planes(design, handle)]])


def fit_cell_young(
    m: mujoco.MjModel,
    handle: FingerHandle,
    design: FingerDesign,
    unit: np.ndarray,
    start: np.ndarray,
    target: np.ndarray,
) -> np.ndarray:
    """Cell moduli [Pa] (n_cells,) whose linear flex turns every block as ``target`` [rad/N] does.

    A block's rotation goes as the inverse of its cells' modulus, so each block's cells are scaled by
    its rotation over the target's until all agree to ``_FIT_RTOL`` (a fixed point; a few iterations).
    """
    planes = _block_planes(design, handle)
    order = handle.grid[4]
    cell_block = np.searchsorted(planes, (np.arange(handle.grid[3]) + 1) * order, side="left")
    e = np.asarray(start, dtype=float).copy()
    for _ in range(_FIT_ITER):
        ratio = flex_block_rotations(design, handle, unit, e) / target
        if np.max(np.abs(ratio - 1.0)) < _FIT_RTOL:
            break
        e = e * ratio[cell_block]
    return e


def rescale_cell_young(
    m: mujoco.MjModel, handle: FingerHandle, design: FingerDesign, young: np.ndarray, options: SimOptions
) -> None:
    """Rewrite the records in ``m`` (holding ``handle.cell_young``) for block moduli ``young`` [Pa].

    The records are linear in E, so each is scaled by new / old cell modulus instead of recompiling;
    a test checks it against a recompile.
    """
    _, _, _, n_cells, order = handle.grid
    e = effective_young(design, young, options.stiffness_model)
    new = cell_young(design, e, n_cells) * locking_factor(design, n_cells, options.poisson, order)
    rec = _cell_records(m, handle)
    if options.stiffness_model == "fem":
        target = np.diff(np.r_[0.0, calibration_for(design).face_angles(np.asarray(young, float))])
        new = fit_cell_young(m, handle, design, handle.unit_records, new, target)
    rec *= (new / handle.cell_young)[:, None]


def assemble_stiffness(m: mujoco.MjModel, handle: FingerHandle) -> np.ndarray:
    """Global linear stiffness [N/m] of a flex over its node grid, from the compiled cell records.

    Dofs are ``3 * node + axis`` with ``node = (gi * ny + gj) * nz + gk`` in the flex's parent frame.
    A cell's record lists its nodes ``li, lj, lk`` (``lk`` fastest), three dofs each; rigid rotations
    lie in the null space of the assembled matrix (tested), which pins that ordering.
    """
    return _assemble(_cell_records(m, handle), handle.grid)


def _assemble(records: np.ndarray, grid: tuple) -> np.ndarray:
    """Global stiffness [N/m] from per-cell records (n_cells, nd²) in MuJoCo's sign (see above)."""
    nx, ny, nz, n_cells, order = grid
    nd = 3 * (order + 1) ** 3
    K = np.zeros((3 * nx * ny * nz,) * 2)
    for c in range(n_cells):
        idx = []
        for li in range(order + 1):
            for lj in range(order + 1):
                for lk in range(order + 1):
                    g = ((c * order + li) * ny + lj) * nz + lk
                    idx += [3 * g, 3 * g + 1, 3 * g + 2]
        K[np.ix_(idx, idx)] += records[c].reshape(nd, nd)
    # MuJoCo stores the records with the sign of the passive force (f = record @ u): negate.
    return -K


def _tip_load(handle: FingerHandle) -> np.ndarray:
    """Nodal forces [N] (3 n_nodes,) of a unit +z load on the tip face, with consistent weights."""
    nx, ny, nz, _, order = handle.grid
    w1 = node_weights(order)
    f = np.zeros(3 * nx * ny * nz)
    for gj in range(ny):
        for gk in range(nz):
            f[3 * (((nx - 1) * ny + gj) * nz + gk) + 2] = w1[gj] * w1[gk]
    return f


def static_tip_deflection(m: mujoco.MjModel, handle: FingerHandle, force: float) -> float:
    """Linear static tip deflection [m] of a base-clamped flex under a transverse tip load [N].

    Solves ``K u = f`` with MuJoCo's compiled stiffness (small-deflection limit of the dynamics);
    the tip load is spread over the tip face with the consistent weights of :class:`TipLoad`.
    """
    return static_tip_solve(m, handle, force)[0]


def static_tip_solve(m: mujoco.MjModel, handle: FingerHandle, force: float) -> tuple[float, np.ndarray]:
    """:func:`static_tip_deflection` [m] and the free nodes' displacement [m] (for :func:`load_nodes`)."""
    _, ny, nz, _, _ = handle.grid
    K = assemble_stiffness(m, handle)
    weights = _tip_load(handle)
    f = force * weights
    tip = [(i, weights[i]) for i in np.flatnonzero(weights)]
    free = np.arange(3 * ny * nz, K.shape[0])  # gi = 0 is clamped
    u = np.zeros_like(f)
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    return float(sum(u[i] * w for i, w in tip)), u[free]


def load_nodes(m: mujoco.MjModel, handle: FingerHandle, displacement: np.ndarray) -> mujoco.MjData:
    """A new ``MjData`` of ``m`` holding a linear solve's free-node displacement [m], after ``mj_forward``.

    The free nodes (``gi >= 1``) are bodies with three slide joints each, in the order of the stiffness
    dofs (:func:`assemble_stiffness`), so their joints' ``qpos`` are the displacement itself.
    """
    nx, ny, nz, _, _ = handle.grid
    names = [f"{handle.prefix}n{gi}_{gj}_{gk}" for gi in range(1, nx) for gj in range(ny) for gk in range(nz)]
    adr = []
    for name in names:
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if b < 0 or m.body_jntnum[b] != 3:
            raise ValueError(f"flex node body {name!r} with three slide joints not found")
        adr += [int(m.jnt_qposadr[m.body_jntadr[b] + k]) for k in range(3)]
    if len(adr) != len(displacement):
        raise ValueError(f"{len(displacement)} displacements for {len(adr)} node dofs")
    d = mujoco.MjData(m)
    d.qpos[adr] = displacement
    mujoco.mj_forward(m, d)
    return d


def grid_rest(design: FingerDesign, handle: FingerHandle) -> np.ndarray:
    """Rest positions [m] of a flex finger's node grid in the finger frame, shape (n_nodes, 3)."""
    nx, ny, nz, _, _ = handle.grid
    lo, ext = _grid_box(design)
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), axis=-1)
    return lo + ext * g.reshape(-1, 3) / np.array([nx - 1, ny - 1, nz - 1])


def linear_tendon_load(
    design: FingerDesign, handle: FingerHandle, tension: float
) -> tuple[np.ndarray, np.ndarray]:
    """Node rest positions [m] (n_nodes, 3) and the frictionless tendon's nodal load [N] (3 n_nodes,).

    The point-force law (`mjcodesign.design.tendon_law.tendon_forces`) at the *rest* waypoints, spread to the nodes by
    the interpolation weights: the first-order load of the linear solves.
    """
    _, _, _, n_cells, order = handle.grid
    X = grid_rest(design, handle)
    W = grid_weights(design, n_cells, order, design.waypoints())
    P = W @ X
    exit_p = tendon_exit_site(design)
    return X, (W.T @ tendon_forces(P, np.zeros_like(P), exit_p, tension, "frictionless")).ravel()


def linear_curl(m: mujoco.MjModel, handle: FingerHandle, design: FingerDesign, tension: float) -> dict:
    """Small-deflection tendon curl of a base-clamped flex: ``K u = Wᵀ F`` with the compiled stiffness.

    F is the frictionless point-force tendon (`mjcodesign.design.tendon_law.tendon_forces`, the law of
    `mjcodesign.models.tendon`) at the *rest* waypoints, spread to the nodes by the interpolation weights W.
    It is the first-order rest state of the dynamics: on the soft trilinear flex the tip rises 29.4 mm
    against 28.9 mm from the dynamics at 0.02 N (0.3 rad), but 118 mm against 90 mm at 0.08 N
    (1.1 rad), so use it for bends of a few tenths of a radian. Returns ``tip_displacement_m`` of the
    tip point (L, 0, t/2), ``bend_angle_rad``, the direction of the spine's last cell, and
    ``node_displacement`` [m] of the free nodes (:func:`load_nodes` draws the rest shape from it).
    """
    nx, ny, nz, n_cells, order = handle.grid
    K = assemble_stiffness(m, handle)
    X, f = linear_tendon_load(design, handle, tension)
    free = np.arange(3 * ny * nz, K.shape[0])  # gi = 0 is clamped
    u = np.zeros(K.shape[0])
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    x = (X + u.reshape(-1, 3)).reshape(nx, ny, nz, 3)
    spine = x[:, :, 0].mean(axis=1)
    d = spine[-1] - spine[-2]
    tip = grid_weights(
        design, n_cells, order, np.array([[design.length, 0.0, 0.5 * design.flexure_thickness]])
    )
    return {
        "tension_n": float(tension),
        "tip_displacement_m": [float(v) for v in (tip @ u.reshape(-1, 3))[0]],
        "bend_angle_rad": float(np.arctan2(d[2], d[0])),
        "node_displacement": u[free],
    }


@functools.lru_cache(maxsize=32)
def locking_factor(design: FingerDesign, n_cells: int, poisson: float, order: int = 1) -> float:
    """δ_flex / δ_EB of the finger's flex (``order`` 1 or 2) with uniform E under a tip load (< 1: too stiff).

    Computed with the linear static solve of the compiled stiffness (:func:`static_tip_deflection`),
    which a test checks against running the dynamics to rest. Dividing every cell's modulus by it
    makes the uniform finger match beam theory exactly; piecewise designs are then checked, not fitted.
    """
    opts = SimOptions(gravity=False, flex_cells=n_cells, poisson=poisson, stiffness_model="beam")
    spec = new_spec("locking", opts, flex=True, scene=False)
    base = spec.worldbody.add_body(name="base")
    h = add_flex_finger(
        spec, base, design, np.ones(design.n_blocks), "c_", opts, quadratic=order == 2, locking=1.0
    )
    m = spec.compile()
    h.cell_young = np.full(n_cells, _E_REF)
    apply_cell_young(m, h)
    young = np.full(design.n_blocks, _E_REF)
    return static_tip_deflection(m, h, 1.0) / cantilever_tip_deflection(design, young, 1.0)


class TipLoad:
    """Consistent nodal forces of a transverse tip load on a flex's tip face, and its deflection."""

    def __init__(self, m: mujoco.MjModel, handle: FingerHandle, force: float):
        nx, ny, nz, _, order = handle.grid
        w1 = node_weights(order)
        self.ids = []
        self.w = []
        for gj in range(ny):
            for gk in range(nz):
                self.ids.append(
                    mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{handle.prefix}n{nx - 1}_{gj}_{gk}")
                )
                self.w.append(w1[gj] * w1[gk])
        self.w = np.array(self.w)
        self.force = force

    def apply(self, d: mujoco.MjData) -> None:
        """Write the nodal forces (world +z) into ``xfrc_applied``."""
        for i, w in zip(self.ids, self.w, strict=True):
            d.xfrc_applied[i, 2] = self.force * w

    def position(self, d: mujoco.MjData) -> float:
        """Weighted mean z of the tip face [m]."""
        return float(np.dot(self.w, d.xpos[self.ids, 2]))
