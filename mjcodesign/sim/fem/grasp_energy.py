"""The FEM grasp's energy bound: nothing gains energy that was not put in (as `mjcodesign.scenarios.energy`).

The mechanical energy of the FEM grasp's free part, sampled at every MuJoCo step,

    E = ½ Σ m̃_i v_i² + Ψ(x) − Σ m_i g·x_i + ½ M v_c² + ½ ωᵀ R I Rᵀ ω − M g·c,

(free vertices with their inertial masses m̃, gravity on their true masses m; the elastic energy Ψ of
every tet; the object's translation, rotation and height) can rise at most by the work the drivers did:

    E(t) − E(0) ≤ W⁺_tendon(t) + W⁺_base(t) + W_push(t),

* the tendons: Σ f_T(x)·v over the free vertices (the kernel's own law, `FemGrasp.tendon_forces`);
* the clamped bases, which the carriages and the lift move: −Σ f_int·v_base over the clamped vertices
  (what the moving clamp feeds into the elastic energy);
* the disturbance: F·v_c on the object;

each power sampled at the MuJoCo steps and integrated with the trapezoid rule, the tendons' and the
bases' positive part only (what they give; what they absorb can only lower the true bound). Every other
force is passive: friction, mass damping and the contacts' damping take energy, and a penalty contact
(finger–object, ground, the segments across a gap) stores at most what it took, so leaving its store out
of E keeps the bound. A rollout that breaks it by more than `ENERGY_TOL` of the work put in (and
`ENERGY_FLOOR`) made energy: a penalty found deep inside the object pushes it out, or a force law that
is not a potential's (the authors' tendon law, `FemOptions.tendon_law`) pumps it in. Such a rollout is
`Failure.IMPLAUSIBLE`, as in MuJoCo.
"""

from __future__ import annotations

import numpy as np

from mjcodesign.scenarios.energy import EnergyBalance
from mjcodesign.sim.fem.gripper import quat_matrix

__all__ = ["EnergyLedger"]


class EnergyLedger:
    """The energy bound of one `FemGrasp` run, fed one state per MuJoCo step (`EnergyLedger.sample`)."""

    def __init__(self, grasp):
        g = grasp.gripper
        self.grasp = grasp
        self.free = ~g.pinned.astype(bool)
        self.pinned_finger = g.finger_of[~self.free]
        self.finger = g.finger_of
        self.inertial = g.inertial * self.free  # the clamped vertices' motion is prescribed: left out
        self.weight = (g.mass * self.free)[:, None] * np.asarray(grasp.dyn.gravity, dtype=float)[None]
        self.offsets = grasp.base_offsets
        self.gravity = np.asarray(grasp.dyn.gravity, dtype=float)
        self.start = None
        self.last = None
        self.work = 0.0
        self.excess = -np.inf
        self.at = 0
        self.work_then = 0.0
        self.speed = 0.0

    def _energy(self, x, v, pos, quat_xyzw, vel, omega, xw) -> float:
        g = self.grasp.gripper
        o = self.grasp.object
        kinetic = 0.5 * float(self.inertial @ np.einsum("ij,ij->i", v, v))
        potential = -float(np.einsum("ij,ij->", self.weight, x))
        R = quat_matrix(np.r_[quat_xyzw[3], quat_xyzw[:3]])
        rot = 0.5 * float(omega @ (R @ o.inertia @ R.T) @ omega)
        body = 0.5 * o.mass * float(vel @ vel) + rot - o.mass * float(self.gravity @ pos)
        return kinetic + potential + g.energy(xw) + body

    def _powers(self, tendon: np.ndarray, f_int, vel, s: int) -> np.ndarray:
        """(tendon, base, push) power [W] under the drivers of substep ``s``; ``tendon``: each finger's."""
        sch = self.grasp.schedule
        s = min(max(s, 1), sch.n_steps)
        rate = (self.offsets[s] - self.offsets[s - 1]) / sch.dt
        base = 0.0 if f_int is None else -float(np.sum(f_int * rate[self.pinned_finger]))
        return np.array([float(tendon.sum()), base, float(sch.push[s] @ vel)])

    def sample(self, s: int, st) -> None:
        """The grasp's state ``st`` at the end of substep ``s``: the work since the last sample, the excess.

        The tendons' force is the kernel's at substep ``s`` (in position mode the tension the servo
        last wrote; none before the first substep); in force mode the next substep's is the same force
        scaled by its tension (both laws are linear in T).
        """
        grasp = self.grasp
        sch = grasp.schedule
        x, v = st.x.numpy(), st.v.numpy()
        pos, quat, vel, omega = (a.numpy()[0] for a in (st.pos, st.rot, st.vel, st.omega))
        e = self._energy(x, v, pos, quat, vel, omega, st.x)
        row, nxt = min(s, sch.n_steps), min(s + 1, sch.n_steps)
        f_int = None  # the clamp's force, needed only while a base moves
        if any(np.any(self.offsets[k] != self.offsets[max(k - 1, 0)]) for k in (max(row, 1), nxt)):
            f_int = grasp.gripper.elastic_forces(st.x)[~self.free]
        tendon = np.zeros(2)
        if row >= 1 and not (sch.tension[row] == 0.0).all():  # NaN (position mode) is computed
            p = np.einsum("ij,ij->i", grasp.tendon_forces(st.x, row), v) * self.free
            tendon = np.bincount(self.finger, weights=p, minlength=2)
        if self.start is None:
            self.start = e
        else:
            s0, p0 = self.last
            ends = self._powers(tendon, f_int, vel, s)  # the drivers that brought it here
            trap = 0.5 * (p0 + ends) * (s - s0) * sch.dt
            self.work += float(max(trap[0], 0.0) + max(trap[1], 0.0) + trap[2])
            excess = e - self.start - self.work
            if excess > self.excess:
                self.excess, self.at, self.work_then = excess, s, self.work
                self.speed = float(np.linalg.norm(vel))
        if not grasp.position_mode:
            t_now, t_next = sch.tension[max(row, 1)], sch.tension[nxt]
            tendon = np.where(t_now > 0, tendon * t_next / np.where(t_now > 0, t_now, 1.0), 0.0)
        self.last = (s, self._powers(tendon, f_int, vel, nxt))  # the drivers that take it on

    def balance(self) -> EnergyBalance:
        """The bound over the samples so far: its largest excess, with the work and time of it."""
        return EnergyBalance(
            excess=float(self.excess) if np.isfinite(self.excess) else 0.0,
            work=self.work_then,
            step=self.at // self.grasp.schedule.per_step - 1,
            object_speed=self.speed,
            total_work=self.work,
        )
