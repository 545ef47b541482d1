"""Replay of a grasp rollout's logged states, and what the recorder works out once per model.

:func:`parts_of` gives a model's :class:`ModelParts` (surfaces, colours, tendon actuators, the layout
of a logged state); :class:`Replay` turns a rollout's logged states (captured while it stepped by
:func:`grab`, or replayed with ``mj_setState`` + ``mj_forward``) into :class:`Frames`: surfaces, object
pose, tendon paths, contacts and series, for all states at once. No Rerun calls here.
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import mujoco
import numpy as np

from mjcodesign.scenarios.grasp import STATE_SPEC, control_spec
from mjcodesign.sim.observe import Rollout
from mjcodesign.viz.batch import rgba32
from mjcodesign.viz.colormap import NEUTRAL_RGB, stiffness_rgb
from mjcodesign.viz.geometry import Surface, body_geom_surface, finger_surfaces

__all__ = ["ModelParts", "parts_of", "Contacts", "Frames", "GRABBED", "Replay", "grab", "block_colours"]

_COLOUR_CACHE = 16  # finger colourings kept per model (designs recorded again and again)


class ModelParts:
    """What the recorder works out once per model.

    The fingers' (A, B) and the rigid parts' (palm, carriages) surfaces; the fingers' triangles as one
    mesh (A's vertices first) and its colour per vertex for the designs recorded; the rigid parts'
    neutral colours; the tendon actuators per finger; the finger bodies; the layout of a logged state.
    They depend on the model only (vertices are placed per state from the geom poses), so
    :func:`parts_of` builds them once per model: rollouts of one model (repeats, poses of one design)
    are recorded again and again.
    """

    def __init__(self, m: mujoco.MjModel, scene):
        edges = np.array([b.x1 for b in scene.built.design.blocks()[:-1]])
        rigid = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("palm", "A_carriage", "B_carriage")
        ]
        self.fingers: dict[str, Surface] = finger_surfaces(m, scene.built.fingers, edges)
        self.gripper: Surface | None = body_geom_surface(m, rigid)
        surfs = list(self.fingers.values())
        first = np.cumsum([0] + [len(s.vertex_block) for s in surfs])
        self.finger_triangles = np.concatenate([s.triangles + o for s, o in zip(surfs, first, strict=False)])
        self._combined = (
            Surface(
                self.finger_triangles,
                np.concatenate([s.vertex_block for s in surfs]),
                geom=np.concatenate([s.geom for s in surfs]),
                local=np.concatenate([s.local for s in surfs]),
            )
            if all(s.geom is not None for s in surfs)
            else None
        )
        n = 0 if self.gripper is None else len(self.gripper.vertex_block)
        self.gripper_colours = np.full(n, rgba32(NEUTRAL_RGB), dtype=np.uint32)
        self._colours: dict[bytes, np.ndarray] = {}
        # Tendon actuators per finger, in finger order (A, B): their forces sum to the finger's tension.
        self.acts = [
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in h.actuators]
            for h in sorted(scene.built.fingers, key=lambda h: h.prefix)
        ]
        self.is_finger = np.zeros(m.nbody, dtype=bool)
        self.is_finger[scene.finger_bodies] = True
        self.elliptic = m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
        self._layout: tuple[list, np.ndarray] | None = None

    def layout(self, d: mujoco.MjData) -> tuple[list, np.ndarray]:
        """Layout of a logged state's flat row (:func:`grab`).

        The shapes of :data:`GRABBED`'s arrays in ``d`` (data of this model) and where each ends in
        the row.
        """
        if self._layout is None:
            shapes = [getattr(d, name).shape for name in GRABBED]
            self._layout = shapes, np.cumsum([int(np.prod(sh)) for sh in shapes])
        return self._layout

    def finger_positions(self, gpos: np.ndarray, gmat: np.ndarray, fpos: np.ndarray) -> np.ndarray:
        """World vertices of both fingers (A's first) [m], shape (..., n_vertices, 3) (:meth:`Surface.positions`)."""
        if self._combined is not None:  # block geoms: one gather for both fingers
            return self._combined.positions(gpos, gmat, fpos)
        return np.concatenate([s.positions(gpos, gmat, fpos) for s in self.fingers.values()], axis=-2)

    def finger_colours(self, log_e: np.ndarray) -> np.ndarray:
        """Colour (``0xRRGGBBAA``) of every finger vertex: its block's stiffness, else neutral.

        A vertex past the last block takes the last block's colour.
        """
        log_e = np.atleast_2d(log_e)
        key = log_e.tobytes() + bytes(log_e.shape)
        if key not in self._colours:
            if len(self._colours) >= _COLOUR_CACHE:
                self._colours.clear()
            rgb = [
                block_colours(stiffness_rgb(log_e[i]), s.vertex_block)
                for i, s in enumerate(self.fingers.values())
            ]
            self._colours[key] = rgba32(np.concatenate(rgb))
        return self._colours[key]


_PARTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def parts_of(m: mujoco.MjModel, scene) -> ModelParts:
    """The :class:`ModelParts` of ``m``, built on first use."""
    if m not in _PARTS:
        _PARTS[m] = ModelParts(m, scene)
    return _PARTS[m]


class Contacts(NamedTuple):
    """The contacts of every logged state, concatenated (state by state)."""

    pos: np.ndarray
    """Points [m], shape (k, 3)."""
    force: np.ndarray
    """Force [N] in world axes, on the object (or on geom2's body where the object is not in it), (k, 3)."""
    on_object: np.ndarray
    """A finger touches the object, shape (k,)."""
    counts: np.ndarray
    """Contacts per state, shape (n,)."""


class Frames:
    """Per logged time point (the initial state first): surfaces, object pose, tendon, contacts, series."""

    def __init__(self, n: int):
        self.surfaces: dict[str, np.ndarray] = {}
        """World vertices of ``fingers`` (both, A first) and ``gripper`` [m], shape (n, n_vertices, 3)."""
        self.object_pos = np.empty((n, 3))
        self.object_quat = np.empty((n, 4))
        self.tendon: list[list[np.ndarray]] = []
        self.contacts: Contacts | None = None
        self.series: dict[str, np.ndarray] = {}


_XYZ = np.arange(3)
GRABBED = (
    "geom_xpos",
    "geom_xmat",
    "flexvert_xpos",
    "xpos",
    "xquat",
    "xipos",
    "xmat",
    "actuator_force",
    "wrap_xpos",
    "ten_wrapadr",
    "ten_wrapnum",
)
"""``MjData`` arrays that a logged state copies (:func:`grab`), in this order, one flat row per state."""


class Replay:
    """Replays a rollout's states and extracts what is logged (no Rerun calls here).

    The loop over the logged states only runs ``mj_forward`` and copies ``MjData`` arrays; everything
    derived from them (surfaces, series, contact forces in world axes) is computed for all states at once.
    """

    def __init__(self, r: Rollout, g: ModelParts, d: mujoco.MjData):
        self.r = r
        self.m = r.model
        self.d = d
        self.g = g

    def frames(self, steps: np.ndarray) -> Frames:
        """:class:`Frames` of the initial state and the states of ``steps``.

        ``steps`` are sorted step indices (:func:`~mjcodesign.viz.recorder.logged_steps`).
        """
        r, m, d = self.r, self.m, self.d
        ob, palm = r.scene.object_body, r.scene.palm_body
        ts = np.r_[-1, steps]
        n = len(ts)
        out = Frames(n)
        rows = []
        ctrl, spec = r.ctrl, control_spec()
        for t in ts:
            row = r.captured.get(int(t))
            if row is None:  # as mjcodesign.scenarios.outcome.outcome_from_states: the state under the next control
                mujoco.mj_setState(m, d, r.x0 if t < 0 else r.states[t], STATE_SPEC)
                mujoco.mj_setState(m, d, ctrl[min(t + 1, len(ctrl) - 1)], spec)
                mujoco.mj_forward(m, d)
                row = grab(m, d, self.g.elliptic)
            rows.append(row)
        flat = np.stack([row[0] for row in rows])  # (n, sum of the arrays' sizes)
        shapes, ends = self.g.layout(d)
        gpos, gmat, fpos, xpos, xquat, xipos, xmat, act, wrap, wrap_adr, wrap_num = (
            flat[:, e - size : e].reshape(n, *sh)
            for e, size, sh in zip(ends, np.diff(ends, prepend=0), shapes, strict=True)
        )
        wrap = wrap.reshape(n, -1, 3)
        wrap_adr, wrap_num = wrap_adr.astype(int), wrap_num.astype(int)
        palm_mat = xmat[:, palm].reshape(n, 3, 3)
        out.surfaces["fingers"] = self.g.finger_positions(gpos, gmat, fpos)
        if self.g.gripper is not None:
            out.surfaces["gripper"] = self.g.gripper.positions(gpos, gmat, fpos)
        out.object_pos, out.object_quat = xpos[:, ob], xquat[:, ob]
        out.tendon = [
            [wrap[i, a : a + k] for a, k in zip(wrap_adr[i], wrap_num[i], strict=True)] for i in range(n)
        ]
        out.contacts, force = self._world_contacts([row[1] for row in rows])
        grasp = _index_of(steps, r.starts["lift"] - 1)
        tendon = np.stack([act[:, ids].sum(axis=1) for ids in self.g.acts], axis=1)
        out.series["force"] = np.column_stack([tendon, force])
        # Object COM in the palm frame; relative to the grasp (end of tightening), as Outcome.displacement,
        # and before it, vs the same state.
        rel = np.einsum("nji,nj->ni", palm_mat, xipos[:, ob] - xpos[:, palm])
        displacement = rel - (rel[grasp] if grasp is not None else rel[0])
        out.series["object"] = np.column_stack([xipos[:, ob, 2], displacement])
        return out

    def _world_contacts(self, rows) -> tuple[Contacts, np.ndarray]:
        """Contacts in world axes, and the norm of the fingers' total force on the object [N], shape (n,)."""
        counts = np.array([len(p) for p, *_ in rows])
        pos, frame, g1, g2, local = (np.concatenate(c) for c in zip(*rows, strict=True))
        b1, b2 = self.m.geom_bodyid[g1], self.m.geom_bodyid[g2]
        world = np.einsum("kji,kj->ki", frame.reshape(-1, 3, 3), local)
        ob = self.r.scene.object_body
        world[b1 == ob] *= -1.0  # show the force acting on the object
        other = np.where(b1 == ob, b2, b1)
        on_object = ((b1 == ob) | (b2 == ob)) & self.g.is_finger[other]
        state = np.repeat(np.arange(len(rows)), counts)
        total = np.zeros((len(rows), 3))
        np.add.at(total, state[on_object], world[on_object])
        return Contacts(pos, world, on_object, counts), np.linalg.norm(total, axis=1)


def grab(m: mujoco.MjModel, d: mujoco.MjData, elliptic: bool) -> tuple:
    """Copies of what a logged state needs from ``d`` after ``mj_forward`` (or a step) at that state.

    The arrays of :data:`GRABBED` (geom, flex-vertex and body poses, actuator forces, tendon wrap
    paths) as one flat float row, and the contacts: points [m], frames (normal, tangents), geoms and
    forces in the contact frame [N].
    """
    nc = d.ncon
    con = d.contact
    if nc == 0:
        contacts = (
            np.zeros((0, 3)),
            np.zeros((0, 9)),
            np.zeros(0, dtype=int),
            np.zeros(0, dtype=int),
            np.zeros((0, 3)),
        )
    else:
        if not elliptic or (con.dim == 1).any():
            local, f6 = np.zeros((nc, 3)), np.zeros(6)
            for i in range(nc):
                mujoco.mj_contactForce(m, d, i, f6)
                local[i] = f6[:3]
        else:
            # Elliptic cones: the first three efc rows of a contact are its normal and tangent forces.
            adr = con.efc_address
            if adr.min() >= 0:
                local = d.efc_force[adr[:, None] + _XYZ]
            else:
                local = d.efc_force[np.maximum(adr, 0)[:, None] + _XYZ]
                local[adr < 0] = 0.0  # excluded contacts carry no force
        contacts = (con.pos.copy(), con.frame.copy(), con.geom1.copy(), con.geom2.copy(), local)
    flat = np.concatenate([getattr(d, name) for name in GRABBED], axis=None, dtype=float)
    return flat, contacts


def block_colours(block_rgb: np.ndarray, vertex_block: np.ndarray) -> np.ndarray:
    """RGB per vertex, shape (n, 3): its block's colour in ``block_rgb``, else neutral.

    A vertex past the last block takes the last block's colour; a negative block is neutral.
    """
    out = np.tile(NEUTRAL_RGB, (len(vertex_block), 1))
    ok = vertex_block >= 0
    out[ok] = block_rgb[np.clip(vertex_block[ok], 0, len(block_rgb) - 1)]
    return out


def _index_of(steps: np.ndarray, step: int) -> int | None:
    """Index of ``step`` among the logged time points (initial state first), or None if not logged."""
    hit = np.flatnonzero(steps == step)
    return int(hit[0]) + 1 if hit.size else None
