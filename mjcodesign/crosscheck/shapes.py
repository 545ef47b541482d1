"""Hands the comparisons' rest shapes to an observer (e.g. the Rerun recorder), at no extra simulation."""

from __future__ import annotations

import numpy as np

__all__ = ["Shapes"]


class Shapes:
    """Hands crosscheck rest shapes to an observer as :class:`~mjcodesign.sim.observe.Snapshot` (finger A).

    Labels: ``{scenario}/{model}``, ``curl/{model}/{tension}N`` (grouped per model: one model's curls are
    drawn over each other), ``press/{routing}/{model}``. A MuJoCo shape is kept until its metrics are
    known (:meth:`set_metrics`) and :meth:`flush` hands everything over. Does nothing without observer.
    """

    def __init__(self, observer, stiffness):
        self.observer = observer
        self.log_e = np.asarray(stiffness.log_e[0])
        self._pending: dict[str, dict] = {}

    def mujoco(self, label: str, *, group=None, tip_load=False, plate=False):
        """An ``observe(built, data)`` callback for a MuJoCo model at rest (None without observer)."""
        if self.observer is None:
            return None

        def keep(built, data, forces=None, obstacle=None) -> None:
            import mujoco

            extra: dict = {"forces": forces, "obstacle": obstacle}
            if tip_load:
                sid = mujoco.mj_name2id(built.model, mujoco.mjtObj.mjOBJ_SITE, built.fingers[0].tip_site)
                extra["forces"] = (data.site_xpos[sid][None].copy(), None)  # force set with the metrics
            if plate:
                from mjcodesign.scenarios.press import plate_box, plate_contacts

                pts, f, _ = plate_contacts(built.model, data)
                extra["forces"] = (pts, f)
                extra["obstacle"] = plate_box(built.model, data)
            d = mujoco.MjData(built.model)  # the caller may go on using its data
            mujoco.mj_copyData(d, built.model, data)
            self._pending[label] = dict(label=label, group=group, built=built, data=d, **extra)

        return keep

    def set_metrics(self, label: str, metrics: dict, *, tip_force=None) -> None:
        """Metrics of a kept MuJoCo shape; ``tip_force`` [N] (3,): the load at its tip point."""
        kept = self._pending.get(label)
        if kept is None:
            return
        kept["metrics"] = metrics
        if tip_force is not None:
            kept["forces"] = (kept["forces"][0], np.asarray(tip_force, dtype=float)[None])

    def fem(self, label: str, fem, x: np.ndarray, metrics: dict, *, group=None, forces=None, obstacle=None):
        """Keep a FEM rest shape: positions ``x`` [m] (n, 3) of ``fem``'s mesh, with its metrics.

        ``forces``: (points [m], forces [N]) to draw; ``obstacle``: (centre, rotation, half extents).
        """
        if self.observer is None:
            return
        self._pending[label] = dict(
            label=label,
            group=group,
            metrics=metrics,
            positions=x,
            tets=fem.mesh.tets,
            tet_block=fem.mesh.tet_block,
            tendon=fem.mesh.waypoint_weights @ x,
            forces=None if forces is None else tuple(np.atleast_2d(np.asarray(v, float)) for v in forces),
            obstacle=obstacle,
        )

    def flush(self) -> None:
        """Hand every kept shape to the observer, in the order they were kept."""
        from mjcodesign.sim.observe import Snapshot

        for kw in self._pending.values():
            self.observer.snapshot(Snapshot(log_e=self.log_e, **kw))
        self._pending.clear()
