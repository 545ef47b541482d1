"""What the FEM grasp measures, and its outcome computed as MuJoCo's is.

`mjcodesign.scenarios.outcome.outcome_from_states` reads a MuJoCo rollout at a few states; the FEM
reads the same quantities at the same times (`mjcodesign.sim.fem.schedule.GraspSchedule`):

* body force: the fingers' wrench on the object (force, torque about the COM), rotated into the palm
  frame. MuJoCo averages five contact-force solves over the second half of the first hold; a penalty
  force rings at the vertices' contact frequency, so the FEM averages every substep of the same span;
* displacement: the COM relative to the palm, in the palm frame, from the end of tightening to the end;
* lift height, ground contact (an object collision point below z = 0) and finger contact (a finger
  vertex inside the object) at the end; the same failure kinds and reasons.

`paper_loss` is the authors' co-design loss L_opt on these outputs (their ``optimize.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mjcodesign.scenarios.energy import EnergyBalance
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome

__all__ = ["Frames", "FemGraspRun", "LOSS_WEIGHT", "LOSS_PENALTY", "grade", "paper_loss"]

_FORCE_EPS = 1e-6
"""A finger force below this is "no force" [N] (as `mjcodesign.scenarios.outcome`)."""
LOSS_WEIGHT = 1e-3
"""The authors' base weight of every output's |value| in L_opt."""
LOSS_PENALTY = 1e3
"""The authors' weight on a negative vertical force, a negative vertical displacement and ground contact."""


@dataclass
class Frames:
    """The grasp sampled at every MuJoCo step (row k: time k·dt_MuJoCo), world frame."""

    time: np.ndarray
    """[s], (k,)."""
    pos: np.ndarray
    """Object COM [m], (k, 3)."""
    rot: np.ndarray
    """Object rotation, quaternion (x, y, z, w), (k, 4)."""
    vel: np.ndarray
    """Object COM velocity [m/s], (k, 3)."""
    omega: np.ndarray
    """Object angular velocity [rad/s], (k, 3)."""
    finger_force: np.ndarray
    """Each finger's force on the object in the substep before the sample [N], (k, 2, 3)."""
    ground_force: np.ndarray
    """The ground's force on the object in that substep [N], (k, 3)."""
    max_depth: np.ndarray
    """Deepest finger vertex inside the object [m], (k,)."""
    n_inside: np.ndarray
    """Finger vertices inside the object, (k,)."""
    n_ground: np.ndarray
    """Object collision points below the ground, (k,)."""

    @classmethod
    def empty(cls, k: int) -> Frames:
        """NaN-filled frames for ``k`` samples (a sample never taken stays NaN; counts −1)."""
        nan = lambda *s: np.full(s, np.nan)  # noqa: E731
        return cls(
            nan(k), nan(k, 3), nan(k, 4), nan(k, 3), nan(k, 3), nan(k, 2, 3), nan(k, 3), nan(k),
            np.full(k, -1), np.full(k, -1),
        )  # fmt: skip

    def record(self, k: int, t: float, st, buf, *, initial: bool = False) -> None:
        """Row ``k`` at time ``t`` [s] from a state and the step's buffers (the initial state: no step)."""
        self.time[k] = t
        self.pos[k] = st.pos.numpy()[0]
        self.rot[k] = st.rot.numpy()[0]
        self.vel[k] = st.vel.numpy()[0]
        self.omega[k] = st.omega.numpy()[0]
        if initial:
            self.finger_force[k] = self.ground_force[k] = 0.0
            self.max_depth[k], self.n_inside[k], self.n_ground[k] = 0.0, 0, 0
            return
        w = buf.wrench.numpy()
        self.finger_force[k], self.ground_force[k] = w[[0, 2]], w[4]
        self.max_depth[k] = float(np.max(buf.depth.numpy(), initial=0.0))
        self.n_inside[k] = int(buf.count.numpy()[0])
        self.n_ground[k] = int(buf.ground.numpy()[0])

    def cut(self, k: int) -> Frames:
        """The first ``k`` rows."""
        return Frames(*(getattr(self, f)[:k] for f in self.__dataclass_fields__))


@dataclass(frozen=True, eq=False)
class FemGraspRun:
    """One FEM grasp: its outcome and what a physical check needs."""

    outcome: Outcome | None
    """The grasp's outcome; None for a run stopped early on request."""
    frames: Frames
    """Samples at every MuJoCo step up to the end (or the divergence)."""
    hold_wrench: np.ndarray
    """Mean wrench of the fingers on the object over the hold span, world frame: torque about the COM
    [N·m] (3), force [N] (3)."""
    final_x: np.ndarray
    """Finger vertices at the end [m], (n_vertices, 3)."""
    final_depth: np.ndarray
    """Depth of every finger vertex inside the object at the end [m] (0 outside), (n_vertices,)."""
    ground_points: int
    """Object collision points below the ground at the end."""
    substeps: int
    """Substeps taken."""
    dt: float
    """Substep [s]."""
    n_vertices: int
    """Finger vertices (both fingers)."""
    added_mass_fraction: float
    """Mass added by selective mass scaling, as a fraction of the fingers' mass."""
    wall_time_s: float
    starts: dict = field(default_factory=dict)
    """First MuJoCo step of every phase, and ``end`` (frame k is the state after MuJoCo step k − 1)."""
    energy: EnergyBalance | None = None
    """The energy bound over the run (`mjcodesign.sim.fem.grasp_energy`)."""
    checkpoints: dict = field(default_factory=dict, repr=False)
    """Substep → its start state (numpy x, v, pos, rot, vel, omega; the previous substep's normal load
    on the object [N]), if asked for."""

    @property
    def vertex_substeps_per_s(self) -> float:
        """Throughput: vertices × substeps per wall-clock second."""
        return self.n_vertices * self.substeps / self.wall_time_s


def grade(
    body_force: np.ndarray,
    displacement: np.ndarray,
    rise: float,
    ground: bool,
    finger: bool,
    scenario,
    path: np.ndarray,
    *,
    energy: EnergyBalance | None = None,
    mujoco_dt: float = 0.0,
) -> Outcome:
    """The outcome of measured outputs, with MuJoCo's failure kinds, order and reasons.

    ``body_force`` (6) and ``displacement`` (3) in the palm frame, ``rise`` [m] of the COM, the flags
    at the end; ``path``: the COM at the outcome's sample times; ``energy``: the rollout's energy bound
    (`mjcodesign.sim.fem.grasp_energy`), whose breach is `Failure.IMPLAUSIBLE`, listed first (its
    reason reads times in MuJoCo steps of ``mujoco_dt`` [s]).
    """
    if not (np.all(np.isfinite(body_force)) and np.all(np.isfinite(displacement)) and np.isfinite(rise)):
        return failed_outcome(Failure.DIVERGED, "diverged: non-finite outcome")
    checks = (
        (
            rise < scenario.lifted_fraction * scenario.lift,
            Failure.NOT_LIFTED,
            f"not lifted (rose {1000 * rise:.1f} mm of {1000 * scenario.lift:.0f})",
        ),
        (ground, Failure.GROUND_CONTACT, "ground contact"),
        (not finger, Failure.NO_FINGER_CONTACT, "no finger contact"),
        (float(np.linalg.norm(body_force[3:])) <= _FORCE_EPS, Failure.ZERO_FORCE, "zero finger force"),
    )
    hits = [(kind, text) for hit, kind, text in checks if hit]
    if energy is not None and not energy.plausible:
        hits.insert(0, (Failure.IMPLAUSIBLE, energy.reason(mujoco_dt)))
    return Outcome(
        success=not hits,
        body_force=tuple(body_force),
        displacement=tuple(displacement),
        ground_contact=bool(ground),
        reason="; ".join(text for _, text in hits) or "ok",
        failures=tuple(kind for kind, _ in hits),
        finger_contact=bool(finger),
        lift_height=float(rise),
        object_path=np.asarray(path, dtype=float),
    )


def paper_loss(body_force, displacement, ground_points: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The authors' L_opt and its gradient w.r.t. the body force (6) and the displacement (3).

    ``L = Σ w_i |o_i|`` over the body force (torque, force), the displacement and the ground contact, with
    w = `LOSS_WEIGHT`, or `LOSS_PENALTY` on a negative vertical force (palm z, index 5), a negative
    vertical displacement (index 2) and a positive ground contact (its count of points, piecewise
    constant: no gradient). Outputs are in the palm frame (the Outcome's; the authors' are y-up world).
    """
    f = np.asarray(body_force, dtype=float)
    d = np.asarray(displacement, dtype=float)
    wf = np.full(6, LOSS_WEIGHT)
    wd = np.full(3, LOSS_WEIGHT)
    wf[5] = LOSS_PENALTY if f[5] < 0 else LOSS_WEIGHT
    wd[2] = LOSS_PENALTY if d[2] < 0 else LOSS_WEIGHT
    wc = LOSS_PENALTY if ground_points > 0 else LOSS_WEIGHT
    loss = float(wf @ np.abs(f) + wd @ np.abs(d) + wc * abs(ground_points))
    return loss, wf * np.sign(f), wd * np.sign(d)
