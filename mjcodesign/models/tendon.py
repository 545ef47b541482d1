"""Tendon actuation: tension on the native tendons, or the paper's point-force model.

Point-force model (per finger, uniform tension ``f_T``, waypoints ``P_0 .. P_{n-1}`` base to tip):

* ``frictionless`` (default): the exact statics of a frictionless tendon through the waypoints,
  ``F_i = f_T (u(P_{i-1} - P_i) + u(P_{i+1} - P_i))`` with ``P_{-1}`` the base exit and the tip as the
  anchor, ``F_tip = f_T u(P_{n-2} - P_{n-1})``. It equals a MuJoCo spatial tendon through the same
  points, which the tests check.
* ``paper``: the authors' variant: the first waypoint carries no force; middle waypoints take the sum
  of the two unit vectors with the component along the block's height axis ``n`` removed (a force
  tangent to the block surface); the tip takes ``-f_T n_out`` with ``n_out`` the outward normal of the
  spine, i.e. ``f_T n`` towards the inner side.

Forces act at the waypoints: on the block bodies for the chain, and on the interpolation nodes by
their shape-function weights for the flex (virtual-work consistent).
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjcodesign.design.tendon_law import TENDON_VARIANTS, tendon_forces
from mjcodesign.errors import DesignError
from mjcodesign.models.types import Built, FingerHandle, TendonMode

__all__ = ["TendonDriver"]


class TendonDriver:
    """Applies a per-finger tendon tension [N] to a built model, in either mode."""

    def __init__(self, built: Built, variant: str = "frictionless"):
        if variant not in TENDON_VARIANTS:
            raise DesignError(f"unknown point-force variant {variant!r}; choose from {TENDON_VARIANTS}")
        self.built = built
        self.variant = variant
        m = built.model
        self.tension = np.zeros(len(built.fingers))
        self._act = [
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in h.actuators]
            for h in built.fingers
        ]
        self._fingers = [_FingerForces(m, built, h) for h in built.fingers]

    def set_tension(self, d: mujoco.MjData, tension) -> None:
        """Set each finger's tension [N] (scalar or per finger) for the following steps."""
        self.tension = np.broadcast_to(np.asarray(tension, dtype=float), (len(self.built.fingers),)).copy()
        if self.built.tendon_mode is TendonMode.NATIVE:
            for ids, f in zip(self._act, self.tension, strict=True):
                d.ctrl[ids] = f / len(ids)

    def apply(self, d: mujoco.MjData) -> None:
        """Point-force mode: write this step's waypoint forces into ``qfrc_applied`` (call before mj_step)."""
        if self.built.tendon_mode is TendonMode.NATIVE:
            return
        d.qfrc_applied[:] = 0.0
        for ff, f in zip(self._fingers, self.tension, strict=True):
            if f > 0:
                ff.apply(d, f, self.variant)


class _FingerForces:
    def __init__(self, m: mujoco.MjModel, built: Built, h: FingerHandle):
        self.m = m
        self.exit_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{h.prefix}tendon_exit")
        self.base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, h.base_body)
        if h.model.is_flex:
            from mjcodesign.models.flex import grid_weights

            nx, ny, nz, n_cells, order = h.grid
            self.W = grid_weights(built.design, n_cells, order, built.design.waypoints())
            names = []
            for gi in range(nx):
                for gj in range(ny):
                    for gk in range(nz):
                        names.append(f"{h.prefix}n{gi}_{gj}_{gk}")
            ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in names]
            self.node_ids = np.array(ids)  # -1 for pinned base nodes
            lo = np.array([0.0, -0.5 * built.design.width, 0.0])
            ext = np.array([built.design.length, built.design.width, built.design.height_base])
            grid = [
                lo + ext * np.array([gi / (nx - 1), gj / (ny - 1), gk / (nz - 1)])
                for gi in range(nx)
                for gj in range(ny)
                for gk in range(nz)
            ]
            self.node_local = np.array(grid)
            self.sites = None
        else:
            self.sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in h.waypoint_sites]
            self.site_body = [int(m.site_bodyid[s]) for s in self.sites]

    def _flex_positions(self, d: mujoco.MjData) -> np.ndarray:
        pos = np.empty((len(self.node_ids), 3))
        free = self.node_ids >= 0
        pos[free] = d.xpos[self.node_ids[free]]
        R = d.xmat[self.base].reshape(3, 3)
        pos[~free] = d.xpos[self.base] + self.node_local[~free] @ R.T
        return pos

    def _normals(self, d: mujoco.MjData, P: np.ndarray) -> np.ndarray:
        if self.sites is not None:
            return np.array([d.xmat[b].reshape(3, 3)[:, 2] for b in self.site_body])
        R = d.xmat[self.base].reshape(3, 3)
        return np.repeat(R[:, 2][None], len(P), axis=0)

    def apply(self, d: mujoco.MjData, f: float, variant: str) -> None:
        if self.sites is not None:
            P = d.site_xpos[self.sites]
        else:
            nodes = self._flex_positions(d)
            P = self.W @ nodes
        normals = self._normals(d, P) if variant == "paper" else P
        F = tendon_forces(P, normals, d.site_xpos[self.exit_site], f, variant)
        if self.sites is not None:
            for p, F_i, b in zip(P, F, self.site_body, strict=True):
                mujoco.mj_applyFT(self.m, d, F_i, np.zeros(3), p, b, d.qfrc_applied)
        else:
            node_f = self.W.T @ F
            free = self.node_ids >= 0
            for b, F_n in zip(self.node_ids[free], node_f[free], strict=True):
                mujoco.mj_applyFT(self.m, d, F_n, np.zeros(3), d.xpos[b], int(b), d.qfrc_applied)
