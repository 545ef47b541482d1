"""The Rerun observer: grasp rollouts and crosscheck rest shapes, side by side in one recording.

A grasp rollout is logged on the ``sim_time`` timeline [s] in one Arrow record batch (:mod:`viz.batch`),
which Rerun splits into one chunk per entity. Its logged states come from the simulator while it
stepped (:class:`mjcodesign.sim.observe.Capture`), or are replayed from the states (``mj_setState`` +
``mj_forward``) when it could not take them (batched rollouts):

* ``/designs/{label}``: the offset (runs side by side along world x), the outcome (JSON text) and
  the phases (a text log entry at every phase start); ``ground``; ``object`` (pose per step, its
  mesh); ``fingers`` (both fingers' deformed surfaces per step, A's vertices first, coloured per
  block by stiffness); ``gripper`` (palm and carriages); ``tendon`` (native wrap path per step);
  ``contacts`` (force arrows). Meshes, colours and names ride on the first time point.
* ``/designs/{label}/series/``: ``force`` [N] (lines ``tendon A``, ``tendon B``: each finger's
  tendon tension; ``contact``: the norm of the fingers' force on the object) and ``object`` [m]
  (``height``: COM height; ``displacement x|y|z``: object COM relative to the palm, in the palm
  frame, since the grasp).
* ``/crosscheck/{label}``: a rest shape (``finger``, ``tendon``, ``metrics``), static;
* ``/legend``: every design's ln E (text) and the stiffness colour scale's swatches (boxes in 3-D).
"""

from __future__ import annotations

import json
import os
import uuid
from pathlib import Path

import mujoco
import numpy as np
import rerun as rr

from mjcodesign.errors import OutputError
from mjcodesign.sim.observe import Rollout, Snapshot
from mjcodesign.viz.batch import ColumnBatch, rgba32
from mjcodesign.viz.colormap import legend_markdown, legend_ticks, stiffness_rgb
from mjcodesign.viz.geometry import BOX_TRIANGLES, box_corners, finger_surfaces, tet_surface
from mjcodesign.viz.replay import ModelParts, Replay, block_colours, grab, parts_of

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
_FINGER_CONTACT_RGBA, _OTHER_CONTACT_RGBA = rgba32(_FINGER_CONTACT_RGB), rgba32(_OTHER_CONTACT_RGB)
_SERIES_NAMES = {
    "force": ["tendon A", "tendon B", "contact"],
    "object": ["height", "displacement x", "displacement y", "displacement z"],
}
"""Lines of each ``series/`` entity, in column order (:meth:`Replay.frames`)."""


def logged_steps(n_steps: int, dt: float, starts: dict[str, int], decimation: int | None) -> np.ndarray:
    """Steps whose states are logged, sorted, unique and below ``n_steps``.

    Every ``decimation``-th step, the grasp (the last step before the lift) and the last step, so that
    the two states :attr:`~mjcodesign.scenarios.Outcome.displacement` compares are always logged.
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
    afterwards. A file alone is encoded in memory and written by :meth:`close` (a file sink's writer
    thread cost ~1 ms more per recording); with a viewer, a file sink writes it as the data comes.
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
        self._ids = (application_id, recording_id or str(uuid.uuid4()))
        self._spawn, self._port = spawn, port
        self._rec: rr.RecordingStream | None = None
        self._encoded: rr.BinaryStream | None = None
        self._closed = False
        if spawn:  # the viewer starts up while the simulation runs
            self._open()
        self._designs: dict[bytes, tuple[str, np.ndarray]] = {}  # ln E -> (first run, ln E)
        self._scratch: tuple[mujoco.MjModel, mujoco.MjData] | None = None
        self._n_rollouts = 0
        self._groups: dict[str, int] = {}
        self._shape_arrow_scale: float | None = None

    @property
    def rec(self) -> rr.RecordingStream:
        """The recording stream, opened on first use."""
        return self._rec if self._rec is not None else self._open()

    def _open(self) -> rr.RecordingStream:
        """Open the stream and its sinks.

        Not at construction (unless a viewer is spawned): an open stream's threads take CPU time while
        the simulation runs, and nothing is logged before a rollout is complete.
        """
        if self._closed:
            raise OutputError(f"the recording {self.path or ''} is closed")
        application_id, recording_id = self._ids
        rec = rr.RecordingStream(application_id, recording_id=recording_id)
        if not self._spawn:  # a file only: encoded in memory, written by close()
            self._encoded = rec.binary_stream()
        else:
            sinks = [rr.GrpcSink(f"rerun+http://127.0.0.1:{self._port}/proxy")]
            rec.spawn(port=self._port, connect=False)
            if self.path is not None:
                sinks.append(rr.FileSink(str(self.path)))
            rec.set_sinks(*sinks)
        self._rec = rec
        return rec

    # -- observer protocol ------------------------------------------------------------------------
    def capture_steps(self, n_steps: int, timestep: float, starts: dict[str, int]) -> set[int]:
        """The initial state and the logged steps (:class:`mjcodesign.sim.observe.Capture`)."""
        return {-1, *logged_steps(n_steps, timestep, starts, self.decimation).tolist()}

    def capture(self, model: mujoco.MjModel, data: mujoco.MjData) -> tuple:
        """What :meth:`rollout` logs of the state ``data`` holds the forward quantities of."""
        return grab(model, data, model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC)

    def rollout(self, r: Rollout) -> None:
        """Log one grasp rollout under ``/designs/{label}``, in one record batch.

        Its time points are the logged states and the phase starts. What never changes (meshes,
        colours, series names, the offset, the outcome, the legend) rides on the first time point
        (:meth:`viz.batch.ColumnBatch.add_once`), and each entity's values sit on its own rows (the
        states' or the phase starts'), null elsewhere.
        """
        root = f"/designs/{_safe(r.label)}"
        m = r.model
        dt = m.opt.timestep
        scene = r.scene
        log_e = r.log_e
        steps = logged_steps(len(r.states), dt, r.starts, self.decimation)
        ks, at_frame, at_phase, entries = _time_points(steps, r.starts, len(r.states))
        b = ColumnBatch(ks * dt, TIMELINE)
        self._legend(r.label, log_e, b)
        b.add_once(root, "Transform3D", "translation", [[_SPACING_DESIGNS * self._n_rollouts, 0.0, 0.0]])
        self._n_rollouts += 1
        b.add_once(root, "TextDocument", "text", [json.dumps(r.outcome.as_dict(), indent=1)])  # plain text
        g = parts_of(m, scene)
        self._geometry(b, root, r, g, log_e)
        for name, names in _SERIES_NAMES.items():
            b.add_once(f"{root}/series/{name}", "SeriesLines", "names", names)

        frames = Replay(r, g, self._data(r)).frames(steps)
        for name, pos in frames.surfaces.items():
            b.add(
                f"{root}/{name}",
                "Mesh3D",
                "vertex_positions",
                pos.reshape(-1, 3),
                pos.shape[1],
                at_frame,
            )
        b.add(f"{root}/object", "Transform3D", "translation", frames.object_pos, rows=at_frame)
        b.add(
            f"{root}/object", "Transform3D", "quaternion", frames.object_quat[:, [1, 2, 3, 0]], rows=at_frame
        )
        strips = [s for row in frames.tendon for s in row]
        b.add(f"{root}/tendon", "LineStrips3D", "strips", strips, _lengths(frames.tendon), at_frame)
        c = frames.contacts
        b.add(f"{root}/contacts", "Arrows3D", "origins", c.pos, c.counts, at_frame)
        b.add(f"{root}/contacts", "Arrows3D", "vectors", c.force * _ARROW_M_PER_N, c.counts, at_frame)
        colours = np.where(c.on_object, _FINGER_CONTACT_RGBA, _OTHER_CONTACT_RGBA)
        b.add(f"{root}/contacts", "Arrows3D", "colors", colours, c.counts, at_frame)
        for name, values in frames.series.items():
            b.add(
                f"{root}/series/{name}",
                "Scalars",
                "scalars",
                values.reshape(-1),
                values.shape[1],
                at_frame,
            )
        b.add(root, "TextLog", "text", ["; ".join(e) for e in entries.values()], rows=at_phase)
        b.send(self.rec)

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
            rgb = block_colours(colours, surf.vertex_block)
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

    def close(self, *, discard: bool = False) -> None:
        """Flush everything, close the sinks, end the stream's threads and write the file (complete).

        Rerun keeps a dropped stream, with its two threads, until an "orphan" sweep (``rr.init`` runs
        one); without the sweep every recording made in a process left two threads behind that now and
        then spun on ``sched_yield``, taking CPU time from the simulation. A second call does nothing.
        ``discard`` (a refused run): write no file, and remove the one a file sink began (``spawn``).
        """
        if self._closed:
            return
        rec = self.rec  # opened now if nothing was logged: the file holds an empty recording
        self._closed = True
        encoded = self._encoded.read(flush=True) if self._encoded is not None else None
        rec.disconnect()  # flushes the batcher into the sinks, then ends them (a file gets its footer)
        self._rec = self._encoded = None
        del rec
        import rerun_bindings  # rerun-sdk's native module; rr.init calls the same sweep

        rerun_bindings.flush_and_cleanup_orphaned_recordings()
        if discard:
            if self._spawn and self.path is not None:
                self.path.unlink(missing_ok=True)
            return
        if encoded is not None:
            try:
                if self.path.exists() and not self.path.is_symlink():
                    # A new file, not the old one truncated: ext4 writes a truncated file's old data
                    # out first (~2 ms of waiting for a recording written over the last one).
                    self.path.unlink()
                self.path.write_bytes(encoded)
            except OSError as exc:
                raise OutputError(f"cannot write the recording {self.path}: {exc.strerror or exc}") from exc

    # -- helpers ----------------------------------------------------------------------------------
    def _legend(self, name: str, log_e: np.ndarray, batch: ColumnBatch) -> None:
        """``/legend``: every design's ln E (text), and the colour scale's swatches in 3-D (once).

        A design is listed under the first run that used it; the text is logged again only when a
        run brings a new design (runs of one design, e.g. many poses, add nothing).
        """
        key = np.asarray(log_e, dtype=float).tobytes()
        if key in self._designs:
            return
        first = not self._designs
        self._designs[key] = (name, log_e)
        designs = dict(self._designs.values())
        batch.add_once("/legend", "TextDocument", "text", [legend_markdown(designs)])
        batch.add_once("/legend", "TextDocument", "media_type", ["text/markdown"])
        if first:
            ticks = legend_ticks()
            centers = _COLORBAR_ORIGIN + np.outer(np.arange(len(ticks)), [_COLORBAR_STEP, 0, 0])
            batch.add_once("/legend", "Boxes3D", "centers", centers)
            batch.add_once(
                "/legend", "Boxes3D", "half_sizes", [[0.5 * _COLORBAR_STEP, 0.005, 0.002]] * len(ticks)
            )
            batch.add_once("/legend", "Boxes3D", "colors", rgba32(stiffness_rgb(ticks)))
            batch.add_once("/legend", "Boxes3D", "labels", [f"{v:.1f}" for v in ticks])
            batch.add_once("/legend", "Boxes3D", "fill_mode", [rr.components.FillMode.Solid.value])

    def _geometry(self, b: ColumnBatch, root, r, g: ModelParts, log_e) -> None:
        """Ground, object mesh, the fingers' and gripper's triangles and colours, on the first time point.

        Both fingers are one mesh (finger A's vertices first), coloured per block by stiffness; the
        object's mesh sits on the ``object`` entity, whose per-step transform moves it.
        """
        h = _GROUND_HALF
        mesh = r.scene.obj.mesh
        for name, vertices, triangles, rgb in (
            ("ground", [[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], [[0, 1, 2], [0, 2, 3]], _GROUND_RGB),
            ("object", mesh.vertices, mesh.faces, _OBJECT_RGB),
        ):
            b.add_once(f"{root}/{name}", "Mesh3D", "vertex_positions", np.asarray(vertices))
            b.add_once(f"{root}/{name}", "Mesh3D", "triangle_indices", np.asarray(triangles))
            b.add_once(f"{root}/{name}", "Mesh3D", "albedo_factor", [rgba32(rgb)])
        b.add_once(f"{root}/fingers", "Mesh3D", "triangle_indices", g.finger_triangles)
        b.add_once(f"{root}/fingers", "Mesh3D", "vertex_colors", g.finger_colours(log_e))
        if g.gripper is not None:
            b.add_once(f"{root}/gripper", "Mesh3D", "triangle_indices", g.gripper.triangles)
            b.add_once(f"{root}/gripper", "Mesh3D", "vertex_colors", g.gripper_colours)

    def _data(self, r: Rollout) -> mujoco.MjData:
        """The rollout's spare ``MjData``, else one of its model, reused while rollouts of one model follow."""
        m = r.model
        if r.scratch is not None:
            return r.scratch
        if self._scratch is None or self._scratch[0] is not m:
            self._scratch = (m, mujoco.MjData(m))
        return self._scratch[1]


def _time_points(steps: np.ndarray, starts: dict[str, int], n_steps: int):
    """A rollout's time points in steps, and which of them hold the logged states and phase starts.

    State t is at time (t + 1) dt, the initial state at 0; a phase starting at step k at k dt. Returns
    the sorted time points ``ks`` (times ``ks * dt``), the rows of the states (initial first) and of
    the phase starts, and the phase log entries per start step (phases of no steps start with the
    next one, in one entry).
    """
    entries: dict[int, list[str]] = {}
    for k, v in starts.items():
        if k != "end" and v < n_steps:
            entries.setdefault(v, []).append(f"{k} (step {v})")
    frame_k, phase_k = np.r_[0, steps + 1], np.fromiter(entries, dtype=int)
    ks = np.union1d(frame_k, phase_k)
    return ks, np.searchsorted(ks, frame_k), np.searchsorted(ks, phase_k), entries


def _lengths(rows) -> list[int]:
    """Items per row of a ragged list."""
    return [len(row) for row in rows]


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
    existing recording costs milliseconds, and :meth:`RerunRecorder.close` replaces it anyway.
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
