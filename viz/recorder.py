"""The Rerun observer: grasp rollouts and crosscheck rest shapes, side by side in one recording.

A grasp rollout is replayed from its states (``mj_setState`` + ``mj_forward`` at the logged steps) and
logged on the ``sim_time`` timeline [s] in three Arrow record batches (:mod:`viz.batch`: the static
parts, the logged time points, the phase starts), which Rerun splits into one chunk per entity:

* ``/designs/{label}``: a static offset (runs side by side along world x), ``ground``, ``object``
  (pose per step, mesh static), ``fingers/A``, ``fingers/B`` (deformed surface per step, coloured per
  block by stiffness; triangles and colours at the first time point), ``gripper`` (palm and
  carriages), ``tendon`` (native wrap path per step),
  ``contacts`` (force arrows), ``phases`` (a text log entry at every phase start), ``outcome``;
* ``/designs/{label}/series/``: ``tendon_force`` (fingers A, B) [N], ``object_height`` (COM) [m],
  ``contact_force`` (norm of the fingers' force on the object) [N], ``displacement`` (object COM
  relative to the palm, palm frame, since the grasp: x, y, z) [m];
* ``/crosscheck/{label}``: a rest shape (``finger``, ``tendon``, ``metrics``), static;
* ``/legend``: the stiffness colour scale and every design's ln E (``/legend/colorbar`` in 3-D).
"""

from __future__ import annotations

import json
import os
import uuid
import weakref
from pathlib import Path

import mujoco
import numpy as np
import rerun as rr

from mjcodesign.errors import OutputError
from mjcodesign.observe import Rollout, Snapshot
from mjcodesign.scenario import STATE_SPEC, control_spec
from viz.batch import ColumnBatch, rgba32
from viz.colormap import NEUTRAL_RGB, legend_markdown, legend_ticks, stiffness_rgb
from viz.geometry import BOX_TRIANGLES, Surface, body_geom_surface, box_corners, finger_surfaces, tet_surface

__all__ = ["RerunRecorder", "DEFAULT_FRAME_RATE", "TIMELINE", "logged_steps"]

TIMELINE = "sim_time"
DEFAULT_FRAME_RATE = 10.0
"""Logged states per simulated second by default [Hz], for smooth playback. The cost of a recording is
mostly fixed (stream, chunks, geometry), not per state; ``mjcodesign bench viz`` measures it."""
_SPACING_DESIGNS = 0.25  # runs side by side along world x [m]: gripper is 0.09 m wide along y, 0.04 along x
_SPACING_SHAPES = 0.06  # crosscheck fingers side by side along world y [m] (finger width 20 mm)
_ARROW_M_PER_N = 0.01  # force arrows: 1 N is drawn 10 mm long
_ARROW_RADIUS = 0.0008  # [m]
_SHAPE_ARROW_MAX = 0.015  # crosscheck forces (mN to N): the largest arrow is drawn 15 mm long [m]
_TENDON_RADIUS = 0.0006  # [m]
_GROUND_HALF = 0.12  # drawn ground square half-side [m]
_COLORBAR_ORIGIN = np.array([-0.1, -0.15, 0.0])  # legend swatches in 3-D, away from the runs [m]
_COLORBAR_STEP = 0.02  # [m]
_OBJECT_RGB = (200, 190, 80)
_GROUND_RGB = (60, 80, 100)
_FINGER_CONTACT_RGB = (230, 60, 200)
_OTHER_CONTACT_RGB = (150, 150, 150)
_TENDON_RGB = (30, 30, 30)
_SERIES_NAMES = {"tendon_force": ["finger A", "finger B"], "displacement": ["x", "y", "z"]}


def logged_steps(n_steps: int, dt: float, starts: dict[str, int], decimation: int | None) -> np.ndarray:
    """Steps whose states are logged, sorted, unique and below ``n_steps``.

    Every ``decimation``-th step, the grasp (the last step before the lift) and the last step, so that
    the two states :attr:`~mjcodesign.scenario.Outcome.displacement` compares are always logged.
    ``decimation`` None logs :data:`DEFAULT_FRAME_RATE` states per simulated second.
    """
    every = decimation or max(1, int(round(1.0 / (DEFAULT_FRAME_RATE * dt))))
    if every < 1:
        raise ValueError(f"decimation must be >= 1 step, got {every}")
    keep = set(range(every - 1, n_steps, every)) | {starts["lift"] - 1, n_steps - 1}
    return np.array(sorted(t for t in keep if 0 <= t < n_steps), dtype=int)


class RerunRecorder:
    """Write (``path``) and/or show (``spawn``) grasp rollouts and rest shapes in one Rerun recording.

    ``spawn`` starts a desktop viewer on ``port`` of 127.0.0.1, or reuses the viewer (or ``rerun
    --serve-grpc`` proxy) already listening there. ``decimation``: log every n-th step (None:
    :data:`DEFAULT_FRAME_RATE` per simulated second). Call :meth:`close` to flush; the file is complete
    afterwards.
    """

    def __init__(
        self,
        path: str | Path | None = None,
        *,
        spawn: bool = False,
        port: int = 9876,
        decimation: int | None = None,
        application_id: str = "mjcodesign",
        recording_id: str | None = None,
    ):
        if path is None and not spawn:
            raise OutputError("the Rerun recorder needs an .rrd path, a viewer (spawn), or both")
        if decimation is not None and decimation < 1:
            raise OutputError(f"decimation must be >= 1 step, got {decimation}")
        self.decimation = decimation
        self.path = Path(path) if path is not None else None
        if self.path is not None:
            _check_writable(self.path)
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id or str(uuid.uuid4()))
        sinks = []
        if spawn:
            self.rec.spawn(port=port, connect=False)
            sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{port}/proxy"))
        if self.path is not None:
            sinks.append(rr.FileSink(str(self.path)))
        self.rec.set_sinks(*sinks)
        self._designs: dict[str, np.ndarray] = {}
        self._scratch: tuple[mujoco.MjModel, mujoco.MjData] | None = None
        self._n_rollouts = 0
        self._groups: dict[str, int] = {}
        self._shape_arrow_scale: float | None = None

    # -- observer protocol ------------------------------------------------------------------------
    def rollout(self, r: Rollout) -> None:
        """Log one grasp rollout under ``/designs/{label}``.

        Three record batches (:class:`viz.batch.ColumnBatch`): the static parts, everything on the
        logged time points (with the triangles, colours and series names that never change at the first
        one), and the phase starts.
        """
        root = f"/designs/{_safe(r.label)}"
        m = r.model
        scene = r.scene
        log_e = np.asarray(scene.built.stiffness.log_e) if r.model is scene.built.model else _log_e_of(r)
        static = ColumnBatch()
        self._legend(r.label, log_e, static)
        static.add(root, "Transform3D", "translation", [[_SPACING_DESIGNS * self._n_rollouts, 0.0, 0.0]])
        self._n_rollouts += 1
        steps = logged_steps(len(r.states), m.opt.timestep, r.starts, self.decimation)
        fingers, gripper = _gripper_surfaces(m, scene)
        timed = ColumnBatch(np.r_[0.0, (steps + 1) * m.opt.timestep], TIMELINE)
        self._geometry(static, timed, root, r, fingers, gripper, log_e)
        for name, names in _SERIES_NAMES.items():
            timed.add_once(f"{root}/series/{name}", "SeriesLines", "names", names)
        static.add(f"{root}/outcome", "TextDocument", "text", [json.dumps(r.outcome.as_dict(), indent=1)])
        static.add(f"{root}/outcome", "TextDocument", "media_type", ["text/plain"])
        static.send(self.rec)

        frames = _Replay(r, fingers, gripper, self._data(r)).frames(steps)
        for name, pos in frames.surfaces.items():
            timed.add(
                f"{root}/{name}", "Mesh3D", "vertex_positions", pos.reshape(-1, 3), [pos.shape[1]] * len(pos)
            )
        timed.add(f"{root}/object", "Transform3D", "translation", frames.object_pos)
        timed.add(f"{root}/object", "Transform3D", "quaternion", frames.object_quat[:, [1, 2, 3, 0]])
        timed.add(
            f"{root}/tendon",
            "LineStrips3D",
            "strips",
            [s for row in frames.tendon for s in row],
            _lengths(frames.tendon),
        )
        pos, vec, on_object = (np.concatenate(c) for c in zip(*frames.contacts, strict=True))
        counts = _lengths(frames.contacts, 0)
        timed.add(f"{root}/contacts", "Arrows3D", "origins", pos, counts)
        timed.add(f"{root}/contacts", "Arrows3D", "vectors", vec * _ARROW_M_PER_N, counts)
        colours = rgba32(np.where(on_object[:, None], _FINGER_CONTACT_RGB, _OTHER_CONTACT_RGB))
        timed.add(f"{root}/contacts", "Arrows3D", "colors", colours, counts)
        for name, values in frames.series.items():
            values = values.reshape(len(values), -1)
            timed.add(
                f"{root}/series/{name}",
                "Scalars",
                "scalars",
                values.reshape(-1),
                [values.shape[1]] * len(values),
            )
        timed.send(self.rec)

        phases = {k: v for k, v in r.starts.items() if k != "end" and v < len(r.states)}
        starts = ColumnBatch(np.array([v * m.opt.timestep for v in phases.values()]), TIMELINE)
        starts.add(f"{root}/phases", "TextLog", "text", [f"{k} (step {v})" for k, v in phases.items()])
        starts.send(self.rec)

    def snapshot(self, s: Snapshot) -> None:
        """Log one rest shape under ``/crosscheck/{label}`` (static).

        Shapes of one group share a place (groups side by side along world y); ``finger`` (coloured per
        block), ``tendon``, ``forces`` (arrows on one scale for the whole recording, set by the first
        shape with forces so that its largest is :data:`_SHAPE_ARROW_MAX` long; the scale is in
        ``metrics``), ``obstacle`` and ``metrics``.
        """
        root = _path("/crosscheck", s.label)
        group = s.group or s.label
        static = ColumnBatch()
        self._legend(f"crosscheck {group}", np.asarray(s.log_e)[None], static)
        if group not in self._groups:
            self._groups[group] = len(self._groups)
            offset = [0.0, _SPACING_SHAPES * self._groups[group], 0.0]
            static.add(_path("/crosscheck", group), "Transform3D", "translation", [offset])
        colours = stiffness_rgb(s.log_e)
        if s.built is not None:
            edges = np.array([b.x1 for b in s.built.design.blocks()[:-1]])
            surf = finger_surfaces(s.built.model, s.built.fingers[:1], edges)["A"]
            pos, tris = surf.positions_of(s.data), surf.triangles
            rgb = _block_colours(colours, surf.vertex_block)
            tendon = np.array(
                [s.data.site_xpos[_site(s.built.model, n)] for n in s.built.fingers[0].waypoint_sites]
            )
        else:
            tri, block = tet_surface(s.tets, s.tet_block)
            pos = np.asarray(s.positions)[tri].reshape(-1, 3)  # unshared vertices: one colour per face
            tris = np.arange(len(pos)).reshape(-1, 3)
            rgb = np.repeat(colours[block], 3, axis=0)
            tendon = s.tendon
        static.add(f"{root}/finger", "Mesh3D", "vertex_positions", pos)
        static.add(f"{root}/finger", "Mesh3D", "triangle_indices", tris)
        static.add(f"{root}/finger", "Mesh3D", "vertex_colors", rgba32(rgb))
        if tendon is not None and len(tendon):
            static.add(f"{root}/tendon", "LineStrips3D", "strips", [np.asarray(tendon, dtype=float)], [1])
            static.add(f"{root}/tendon", "LineStrips3D", "colors", [rgba32(_TENDON_RGB)])
        lines = [f"- {k}: {v:.6g}" for k, v in s.metrics.items()]
        if s.forces is not None and len(s.forces[0]):
            points, forces = (np.asarray(v, dtype=float).reshape(-1, 3) for v in s.forces)
            if self._shape_arrow_scale is None:  # one scale for the recording, so that shapes compare
                self._shape_arrow_scale = _SHAPE_ARROW_MAX / max(
                    float(np.linalg.norm(forces, axis=1).max()), 1e-300
                )
            scale = self._shape_arrow_scale
            static.add(f"{root}/forces", "Arrows3D", "origins", points)
            static.add(f"{root}/forces", "Arrows3D", "vectors", forces * scale)
            static.add(f"{root}/forces", "Arrows3D", "colors", [rgba32(_FINGER_CONTACT_RGB)] * len(points))
            lines.append(f"- arrows: {1e3 * scale:.6g} mm per N ({len(points)} forces)")
        if s.obstacle is not None:
            centre, rot, half = (np.asarray(v, dtype=float) for v in s.obstacle)
            corners = centre + (box_corners(half) @ rot.T)
            static.add(f"{root}/obstacle", "Mesh3D", "vertex_positions", corners)
            static.add(f"{root}/obstacle", "Mesh3D", "triangle_indices", BOX_TRIANGLES)
            static.add(f"{root}/obstacle", "Mesh3D", "albedo_factor", [rgba32(_OBJECT_RGB)])
        static.add(f"{root}/metrics", "TextDocument", "text", ["\n".join(lines)])
        static.add(f"{root}/metrics", "TextDocument", "media_type", ["text/markdown"])
        static.send(self.rec)

    def close(self) -> None:
        """Flush everything and close the sinks."""
        self.rec.flush()
        self.rec.disconnect()

    # -- helpers ----------------------------------------------------------------------------------
    def _legend(self, name: str, log_e: np.ndarray, static: ColumnBatch) -> None:
        first = not self._designs
        self._designs[name] = log_e
        static.add("/legend", "TextDocument", "text", [legend_markdown(self._designs)])
        static.add("/legend", "TextDocument", "media_type", ["text/markdown"])
        if first:
            ticks = legend_ticks()
            centers = _COLORBAR_ORIGIN + np.outer(np.arange(len(ticks)), [_COLORBAR_STEP, 0, 0])
            static.add("/legend/colorbar", "Boxes3D", "centers", centers)
            static.add(
                "/legend/colorbar",
                "Boxes3D",
                "half_sizes",
                [[0.5 * _COLORBAR_STEP, 0.005, 0.002]] * len(ticks),
            )
            static.add("/legend/colorbar", "Boxes3D", "colors", rgba32(stiffness_rgb(ticks)))
            static.add("/legend/colorbar", "Boxes3D", "labels", [f"{v:.1f}" for v in ticks])
            static.add("/legend/colorbar", "Boxes3D", "fill_mode", [rr.components.FillMode.Solid.value])

    def _geometry(self, static: ColumnBatch, timed: ColumnBatch, root, r, fingers, gripper, log_e) -> None:
        """Ground and object mesh (static); the fingers' and gripper's triangles and colours (first step)."""
        g = _GROUND_HALF
        mesh = r.scene.obj.mesh
        for name, vertices, triangles, rgb in (
            ("ground", [[-g, -g, 0], [g, -g, 0], [g, g, 0], [-g, g, 0]], [[0, 1, 2], [0, 2, 3]], _GROUND_RGB),
            ("object/mesh", mesh.vertices, mesh.faces, _OBJECT_RGB),
        ):
            static.add(f"{root}/{name}", "Mesh3D", "vertex_positions", np.asarray(vertices))
            static.add(f"{root}/{name}", "Mesh3D", "triangle_indices", np.asarray(triangles))
            static.add(f"{root}/{name}", "Mesh3D", "albedo_factor", [rgba32(rgb)])
        parts = {f"fingers/{k}": (s, stiffness_rgb(log_e[i])) for i, (k, s) in enumerate(fingers.items())}
        if gripper is not None:
            parts["gripper"] = (gripper, None)
        for name, (surf, block_rgb) in parts.items():
            rgb = _block_colours(block_rgb, surf.vertex_block) if block_rgb is not None else NEUTRAL_RGB
            timed.add_once(f"{root}/{name}", "Mesh3D", "triangle_indices", surf.triangles)
            colours = np.broadcast_to(rgba32(rgb), len(surf.vertex_block))
            timed.add_once(f"{root}/{name}", "Mesh3D", "vertex_colors", colours)

    def _data(self, r: Rollout) -> mujoco.MjData:
        """The rollout's spare ``MjData``, else one of its model, reused while rollouts of one model follow."""
        m = r.model
        if r.scratch is not None:
            return r.scratch
        if self._scratch is None or self._scratch[0] is not m:
            self._scratch = (m, mujoco.MjData(m))
        return self._scratch[1]


_SURFACES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _gripper_surfaces(m: mujoco.MjModel, scene) -> tuple[dict[str, Surface], Surface | None]:
    """The fingers' and the gripper's rigid parts' surfaces of ``m``, built once per model.

    They depend on the model's geometry only (vertices are placed per state from the geom poses), and
    rollouts of one model (repeats, poses of one design) are recorded again and again.
    """
    if m not in _SURFACES:
        edges = np.array([b.x1 for b in scene.built.design.blocks()[:-1]])
        rigid = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("palm", "A_carriage", "B_carriage")
        ]
        _SURFACES[m] = (finger_surfaces(m, scene.built.fingers, edges), body_geom_surface(m, rigid))
    return _SURFACES[m]


class _Frames:
    """Per logged time point (the initial state first): surfaces, object pose, tendon, contacts, series."""

    def __init__(self, n: int, surfaces: list[str]):
        self.surfaces: dict[str, np.ndarray] = {k: np.zeros((n, 0, 3)) for k in surfaces}
        """World vertices per surface [m], shape (n, n_vertices, 3)."""
        self.object_pos = np.empty((n, 3))
        self.object_quat = np.empty((n, 4))
        self.tendon: list[list[np.ndarray]] = []
        self.contacts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.series: dict[str, np.ndarray] = {}


class _Replay:
    """Replays a rollout's states and extracts what is logged (no Rerun calls here).

    The loop over the logged states only runs ``mj_forward`` and copies ``MjData`` arrays; everything
    derived from them (surfaces, series, contact forces in world axes) is computed for all states at once.
    """

    def __init__(self, r: Rollout, fingers: dict[str, Surface], gripper: Surface | None, d: mujoco.MjData):
        self.r = r
        self.m = r.model
        self.d = d
        self.surfaces = {f"fingers/{k}": s for k, s in fingers.items()}
        if gripper is not None:
            self.surfaces["gripper"] = gripper
        m = self.m
        # Tendon actuators per finger, in finger order (A, B): their forces sum to the finger's tension.
        self.acts = {
            h.prefix.rstrip("_"): [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in h.actuators]
            for h in sorted(r.scene.built.fingers, key=lambda h: h.prefix)
        }
        self.is_finger = np.zeros(m.nbody, dtype=bool)
        self.is_finger[r.scene.finger_bodies] = True
        self.elliptic = m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC

    def frames(self, steps: np.ndarray) -> _Frames:
        r, m, d = self.r, self.m, self.d
        ob, palm = r.scene.object_body, r.scene.palm_body
        ts = np.r_[-1, steps]
        n = len(ts)
        out = _Frames(n, list(self.surfaces))
        gpos, gmat = np.empty((n, m.ngeom, 3)), np.empty((n, m.ngeom, 9))
        fpos = np.empty((n, m.nflexvert, 3))
        xpos, xquat, xipos = np.empty((n, m.nbody, 3)), np.empty((n, m.nbody, 4)), np.empty((n, m.nbody, 3))
        palm_mat, act = np.empty((n, 9)), np.empty((n, m.nu))
        wrap = np.empty((n, 2 * m.nwrap, 3))
        wrap_adr, wrap_num = np.empty((n, m.ntendon), dtype=int), np.empty((n, m.ntendon), dtype=int)
        contacts = []  # per state: (pos, frame, geom1, geom2, force in the contact frame)
        ctrl, spec = r.ctrl, control_spec()
        for i, t in enumerate(ts):
            # As mjcodesign.scenario.outcome_from_states: the state under the control of the next step.
            mujoco.mj_setState(m, d, r.x0 if t < 0 else r.states[t], STATE_SPEC)
            mujoco.mj_setState(m, d, ctrl[min(t + 1, len(ctrl) - 1)], spec)
            mujoco.mj_forward(m, d)
            gpos[i], gmat[i], fpos[i] = d.geom_xpos, d.geom_xmat, d.flexvert_xpos
            xpos[i], xquat[i], xipos[i] = d.xpos, d.xquat, d.xipos
            palm_mat[i], act[i] = d.xmat[palm], d.actuator_force
            wrap[i], wrap_adr[i], wrap_num[i] = d.wrap_xpos.reshape(-1, 3), d.ten_wrapadr, d.ten_wrapnum
            contacts.append(self._contacts())
        for name, surf in self.surfaces.items():
            out.surfaces[name] = surf.positions(gpos, gmat, fpos)
        out.object_pos, out.object_quat = xpos[:, ob], xquat[:, ob]
        out.tendon = [
            [wrap[i, a : a + k] for a, k in zip(wrap_adr[i], wrap_num[i], strict=True)] for i in range(n)
        ]
        out.contacts, force = self._world_contacts(contacts)
        grasp = _index_of(steps, r.starts["lift"] - 1)
        out.series["tendon_force"] = np.stack([act[:, ids].sum(axis=1) for ids in self.acts.values()], axis=1)
        out.series["object_height"] = xipos[:, ob, 2]
        out.series["contact_force"] = force
        # Object COM in the palm frame; relative to the grasp (end of tightening), as Outcome.displacement,
        # and before it, vs the same state.
        rel = np.einsum("nji,nj->ni", palm_mat.reshape(n, 3, 3), xipos[:, ob] - xpos[:, palm])
        out.series["displacement"] = rel - (rel[grasp] if grasp is not None else rel[0])
        return out

    def _contacts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Contacts of the loaded state: points [m], frames (normal, tangents), geoms, local forces [N]."""
        m, d = self.m, self.d
        nc = d.ncon
        con = d.contact
        if nc == 0:
            return (
                np.zeros((0, 3)),
                np.zeros((0, 9)),
                np.zeros(0, dtype=int),
                np.zeros(0, dtype=int),
                np.zeros((0, 3)),
            )
        dim = con.dim
        if not self.elliptic or np.any(dim == 1):
            local, f6 = np.zeros((nc, 3)), np.zeros(6)
            for i in range(nc):
                mujoco.mj_contactForce(m, d, i, f6)
                local[i] = f6[:3]
        else:
            # Elliptic cones: the first three efc rows of a contact are its normal and tangent forces.
            adr = con.efc_address
            local = d.efc_force[np.maximum(adr, 0)[:, None] + np.arange(3)]
            local[adr < 0] = 0.0  # excluded contacts carry no force
        return con.pos.copy(), con.frame.copy(), con.geom1.copy(), con.geom2.copy(), local

    def _world_contacts(self, rows) -> tuple[list, np.ndarray]:
        """Contacts in world axes, and the norm of the fingers' total force on the object [N], shape (n,).

        Per state: points [m], force on the object (or on geom2's body) [N], finger-object mask.
        """
        counts = np.array([len(p) for p, *_ in rows])
        pos, frame, g1, g2, local = (np.concatenate(c) for c in zip(*rows, strict=True))
        b1, b2 = self.m.geom_bodyid[g1], self.m.geom_bodyid[g2]
        world = np.einsum("kji,kj->ki", frame.reshape(-1, 3, 3), local)
        ob = self.r.scene.object_body
        world[b1 == ob] *= -1.0  # show the force acting on the object
        other = np.where(b1 == ob, b2, b1)
        on_object = ((b1 == ob) | (b2 == ob)) & self.is_finger[other]
        state = np.repeat(np.arange(len(rows)), counts)
        total = np.zeros((len(rows), 3))
        np.add.at(total, state[on_object], world[on_object])
        cuts = np.cumsum(counts)[:-1]
        return list(
            zip(np.split(pos, cuts), np.split(world, cuts), np.split(on_object, cuts), strict=True)
        ), (np.linalg.norm(total, axis=1))


def _index_of(steps: np.ndarray, step: int) -> int | None:
    """Index of ``step`` among the logged time points (initial state first), or None if not logged."""
    hit = np.flatnonzero(steps == step)
    return int(hit[0]) + 1 if hit.size else None


def _lengths(rows, axis: int | None = None) -> list[int]:
    """Items per row of a ragged list (or of each row's ``axis``-th member)."""
    return [len(row if axis is None else row[axis]) for row in rows]


def _block_colours(block_rgb: np.ndarray, vertex_block: np.ndarray) -> np.ndarray:
    out = np.tile(NEUTRAL_RGB, (len(vertex_block), 1))
    ok = vertex_block >= 0
    out[ok] = block_rgb[np.clip(vertex_block[ok], 0, len(block_rgb) - 1)]
    return out


def _log_e_of(r: Rollout) -> np.ndarray:
    """The ln E of a rollout whose model replaces the scene's: read back from the chain's hinge stiffness."""
    from mjcodesign.beam import block_effective_ei

    built = r.scene.built
    if built.finger_model.is_flex:
        raise ValueError("a flex rollout must run the scene's own model: its stiffness is compiled in")
    out = np.empty(np.shape(built.stiffness.log_e))
    for i, h in enumerate(built.fingers):
        for j, (name, blk) in enumerate(zip(h.joints, built.design.blocks(), strict=True)):
            jid = mujoco.mj_name2id(r.model, mujoco.mjtObj.mjOBJ_JOINT, name)
            # k = E I / l is linear in E: E = k / (EI(E=1) / l).
            out[i, j] = np.log(r.model.jnt_stiffness[jid] * blk.length / block_effective_ei(blk, 1.0))
    return out


def _site(m: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)


def _path(prefix: str, label: str) -> str:
    """``prefix`` and the '/'-separated parts of ``label``, each made an entity-path part (:func:`_safe`)."""
    return "/".join([prefix, *(_safe(p) for p in label.split("/"))])


def _safe(label: str) -> str:
    """An entity-path part: letters, digits, '-', '_' and '.' kept, anything else replaced by '_'."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in label) or "_"


def _check_writable(path: Path) -> None:
    """Refuse a recording path that cannot be written, before anything is simulated.

    Asks the file system (the file, else its folder) instead of opening the file: truncating an
    existing recording costs milliseconds, and the file sink truncates it again.
    """
    if path.is_dir():
        raise OutputError(f"cannot write the recording {path}: it is a folder")
    parent = path.parent  # Path("x.rrd").parent is Path(".")
    if path.exists():
        ok, why = os.access(path, os.W_OK), "Permission denied"
    elif not parent.is_dir():
        ok, why = False, "No such file or directory"
    else:
        ok, why = os.access(parent, os.W_OK | os.X_OK), "Permission denied"
    if not ok:
        raise OutputError(f"cannot write the recording {path}: {why}")
