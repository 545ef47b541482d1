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
        self.inertial = g.inertial[self.free]
        self.weight = g.mass[self.free, None] * np.asarray(grasp.dyn.gravity, dtype=float)[None]
        self.offsets = grasp.schedule.offsets(grasp.placement.axes)
        self.gravity = np.asarray(grasp.dyn.gravity, dtype=float)
        self.start = None
        self.last = None
        self.work = 0.0
        self.excess = -np.inf
        self.at = 0
        self.work_then = 0.0
        self.speed = 0.0

    def _energy(self, x, v, pos, quat_xyzw, vel, omega) -> float:
        g = self.grasp.gripper
        o = self.grasp.object
        kinetic = 0.5 * float(np.sum(self.inertial * np.sum(v[self.free] ** 2, axis=1)))
        potential = -float(np.sum(self.weight * x[self.free]))
        R = quat_matrix(np.r_[quat_xyzw[3], quat_xyzw[:3]])
        rot = 0.5 * float(omega @ (R @ o.inertia @ R.T) @ omega)
        body = 0.5 * o.mass * float(vel @ vel) + rot - o.mass * float(self.gravity @ pos)
        return kinetic + potential + g.energy(x) + body

    def _powers(self, x, v, vel, f_int, s: int, now: int) -> np.ndarray:
        """(tendon, base, push) power [W] at the state (x, v) after substep ``now``, drivers of substep ``s``.

        In position mode the servo writes a substep's tension as it steps, so the tendon takes the
        last one written (``now``; none before the first substep).
        """
        grasp = self.grasp
        sch = grasp.schedule
        s = min(max(s, 1), sch.n_steps)
        row = min(s, now) if grasp.position_mode else s
        tendon = 0.0
        if row >= 1:
            tendon = float(np.sum(grasp.tendon_forces(x, row)[self.free] * v[self.free]))
        rate = (self.offsets[s] - self.offsets[s - 1]) / sch.dt
        base = -float(np.sum(f_int * rate[self.pinned_finger]))
        return np.array([tendon, base, float(sch.push[s] @ vel)])

    def sample(self, s: int, x, v, pos, quat_xyzw, vel, omega) -> None:
        """The state at the end of substep ``s`` (numpy): the work since the last sample, and the excess."""
        e = self._energy(x, v, pos, quat_xyzw, vel, omega)
        f_int = self.grasp.gripper.elastic_forces(x)[~self.free]
        if self.start is None:
            self.start = e
        else:
            s0, p0 = self.last
            ends = self._powers(x, v, vel, f_int, s, s)  # the drivers that brought it here
            trap = 0.5 * (p0 + ends) * (s - s0) * self.grasp.schedule.dt
            self.work += float(max(trap[0], 0.0) + max(trap[1], 0.0) + trap[2])
            excess = e - self.start - self.work
            if excess > self.excess:
                self.excess, self.at, self.work_then = excess, s, self.work
                self.speed = float(np.linalg.norm(vel))
        self.last = (s, self._powers(x, v, vel, f_int, s + 1, s))  # the drivers that take it on

    def balance(self) -> EnergyBalance:
        """The bound over the samples so far: its largest excess, with the work and time of it."""
        return EnergyBalance(
            excess=float(self.excess) if np.isfinite(self.excess) else 0.0,
            work=self.work_then,
            step=self.at // self.grasp.schedule.per_step - 1,
            object_speed=self.speed,
            total_work=self.work,
        )
