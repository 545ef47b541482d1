"""The outcome of a grasp rollout: the wrench the fingers hold the object with, its displacement, contacts, and a typed failure kind.

:func:`outcome_from_states` reads a rollout's states the same way for every MuJoCo backend; the
single-step and batched paths share it.
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass

import mujoco
import numpy as np

from mjcodesign.scenarios.energy import energy_balance
from mjcodesign.scenarios.grasp import STATE_SPEC, GraspScenario, GraspScene, control_spec
from mjcodesign.scenarios.motion import motion_bound

__all__ = ["Failure", "Outcome", "failed_outcome", "finger_wrench", "outcome_from_states", "outcome_steps"]

_FORCE_EPS = 1e-6  # a finger wrench below this is "no force" [N]
# Body force: mean over this many states in the second half of the first hold (each costs an
# mj_forward replay; 10 cost the pipeline ~10% of the rollout time).
_HOLD_SAMPLES = 5


class Failure(enum.Enum):
    """Why a grasp failed.

    A rollout can fail for several ordinary reasons at once; the first three kinds are the simulator's
    or the input's fault and carry no grasp information.
    """

    DIVERGED = "diverged"
    """The solver warned or the state became non-finite (the reason names the step and warning)."""
    IMPLAUSIBLE = "implausible"
    """The rollout broke a physical bound: the object gained more energy than could be put in, or moved
    in a way no grasp can (``mjcodesign.scenarios.motion``)."""
    BAD_POSE = "bad_pose"
    """The pose cannot be simulated: gripper below the ground, object too wide for the stroke."""
    NOT_LIFTED = "not_lifted"
    """The object rose less than the scenario's ``lifted_fraction`` of the lift."""
    GROUND_CONTACT = "ground_contact"
    """The object touches the ground at the end."""
    NO_FINGER_CONTACT = "no_finger_contact"
    """No finger touches the object at the end."""
    ZERO_FORCE = "zero_force"
    """The fingers' mean force on the object during the hold is zero."""

    @property
    def is_sample_error(self) -> bool:
        """True for kinds that make a rollout unusable as a data sample (diverged, implausible, bad pose)."""
        return self in (Failure.DIVERGED, Failure.IMPLAUSIBLE, Failure.BAD_POSE)


@dataclass(frozen=True, eq=False)
class Outcome:
    """Result of one grasp rollout. Vectors are in the gripper (palm) frame; never NaN."""

    success: bool
    body_force: tuple[float, float, float, float, float, float]
    """Wrench of the fingers on the object, shape (6,).

    Torque about the COM [N m] (3), then force [N] (3); mean over the second half of the first hold.
    """
    displacement: tuple[float, float, float]
    """Object position change relative to the palm, grasp (end of tightening) to end [m], shape (3,)."""
    ground_contact: bool
    reason: str
    """Readable reason: ``ok``, or the failures joined by ``"; "`` with their numbers."""
    failures: tuple[Failure, ...] = ()
    """Every failure kind, in the order of ``reason``; empty on success."""
    wall_time_s: float = 0.0
    """Wall time of the rollout and its outcome [s]."""
    finger_contact: bool = False
    lift_height: float = 0.0
    """Rise of the object's COM from t=0 to the end [m] (world z)."""
    object_path: np.ndarray | None = None
    """Object COM in the world at the steps of :func:`outcome_steps`, in order [m], shape (k, 3)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "body_force", tuple(float(x) for x in self.body_force))
        object.__setattr__(self, "displacement", tuple(float(x) for x in self.displacement))
        object.__setattr__(self, "failures", tuple(Failure(f) for f in self.failures))
        if len(self.body_force) != 6 or len(self.displacement) != 3:
            raise ValueError("an outcome has a 6-vector body force and a 3-vector displacement")
        if self.success == bool(self.failures):
            raise ValueError("an outcome succeeds exactly when it lists no failure")

    @property
    def failure(self) -> Failure | None:
        """The first failure kind, or None on success."""
        return self.failures[0] if self.failures else None

    def with_wall_time(self, wall_time_s: float) -> Outcome:
        """The same outcome with its wall time [s]."""
        return dataclasses.replace(self, wall_time_s=float(wall_time_s))

    def as_dict(self) -> dict:
        """JSON-ready dict (``failure``: the first kind or null, ``failures``: every kind)."""
        return {
            "success": bool(self.success),
            "body_force": list(self.body_force),
            "displacement": list(self.displacement),
            "ground_contact": bool(self.ground_contact),
            "reason": self.reason,
            "failure": None if self.failure is None else self.failure.value,
            "failures": [f.value for f in self.failures],
            "wall_time_s": float(self.wall_time_s),
            "finger_contact": bool(self.finger_contact),
            "lift_height": float(self.lift_height),
        }


def failed_outcome(kind: Failure, reason: str, wall_time_s: float = 0.0) -> Outcome:
    """A sample that could not be simulated (divergence, bad pose, ...): zeros, never NaN."""
    return Outcome(False, (0.0,) * 6, (0.0,) * 3, False, reason, (Failure(kind),), wall_time_s)


def finger_wrench(
    scene: GraspScene, d: mujoco.MjData, *, forces: bool = True
) -> tuple[np.ndarray, bool, bool]:
    """(wrench on the object by the fingers [torque about COM, force] in world, finger contact, ground).

    With ``forces=False`` only the two flags are read (``d`` needs contacts, not constraint forces).
    """
    m = scene.model
    ob = scene.object_body
    wrench = np.zeros(6)
    if d.ncon == 0:
        return wrench, False, False
    con = d.contact
    # Per contact, its side away from the object: geom, body and flex (a flex side has geom -1 and
    # its flex id in con.flex; every flex is a finger). Plain Python: ~10 contacts, called per replay.
    geoms, flexes, bodyid, mask = con.geom.tolist(), con.flex.tolist(), m.geom_bodyid, scene.finger_mask
    ground, sel, b2 = False, [], []
    for i, ((g1, g2), (f1, f2)) in enumerate(zip(geoms, flexes, strict=True)):
        b1_ = int(bodyid[g1]) if g1 >= 0 else -1
        b2_ = int(bodyid[g2]) if g2 >= 0 else -1
        if b1_ == ob:
            g, b, f = g2, b2_, f2
        elif b2_ == ob:
            g, b, f = g1, b1_, f1
        else:
            continue
        ground = ground or g == scene.ground_geom
        if f >= 0 or (b >= 0 and mask[b]):
            sel.append(i)
            b2.append(b2_)
    if not sel or not forces:
        return wrench, bool(sel), ground
    sel, b2 = np.array(sel), np.array(b2)
    local = _contact_forces(m, d, con, sel)
    # mj_contactForce gives the force of geom1 on geom2 in the contact frame (rows = axes).
    frames = np.asarray(con.frame)[sel].reshape(-1, 3, 3)
    sign = np.where(b2 == ob, 1.0, -1.0)[:, None]
    F = sign * np.einsum("kji,kj->ki", frames, local[:, :3])
    T = sign * np.einsum("kji,kj->ki", frames, local[:, 3:])
    r = np.asarray(con.pos)[sel] - d.xipos[ob]
    wrench[3:] = F.sum(axis=0)
    # Σ r × F, written out: np.cross costs more than the rest of this function on ~20 contacts.
    rxf = r[:, _NEXT] * F[:, _AFTER] - r[:, _AFTER] * F[:, _NEXT]
    wrench[:3] = rxf.sum(axis=0) + T.sum(axis=0)
    return wrench, True, ground


_NEXT, _AFTER = np.array([1, 2, 0]), np.array([2, 0, 1])  # the cross product's index rotations


def _contact_forces(m: mujoco.MjModel, d: mujoco.MjData, con, sel: np.ndarray) -> np.ndarray:
    """``mj_contactForce`` of the contacts ``sel`` (contact frame), shape (len(sel), 6).

    With elliptic cones MuJoCo's function copies each contact's first ``dim`` constraint forces (zeros
    without constraint rows); this copies them here, without a call per contact. Pyramidal cones,
    whose forces MuJoCo decodes, go through ``mj_contactForce``.
    """
    local = np.zeros((sel.size, 6))
    if m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC:
        efc = d.efc_force
        for k, (adr, dim) in enumerate(
            zip(con.efc_address[sel].tolist(), con.dim[sel].tolist(), strict=True)
        ):
            if adr >= 0:
                local[k, :dim] = efc[adr : adr + dim]
        return local
    f6 = np.zeros(6)
    for k, i in enumerate(sel.tolist()):
        mujoco.mj_contactForce(m, d, i, f6)
        local[k] = f6
    return local


def _palm_frame(scene: GraspScene, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    return d.xpos[scene.palm_body].copy(), d.xmat[scene.palm_body].reshape(3, 3).copy()


def _hold_steps(starts: dict[str, int]) -> np.ndarray:
    # States are evaluated under the control of the following step, so the last sample is h1 - 2: the
    # state after h1 - 1 would be evaluated with the impulse force applied.
    h0, h1 = starts["hold"], starts["impulse"]
    last = h1 - 2
    return np.unique(np.linspace(min(h0 + (h1 - h0) // 2, last), last, _HOLD_SAMPLES).astype(int))


def outcome_steps(starts: dict[str, int]) -> set[int]:
    """Steps whose states :func:`outcome_from_states` reads (a backend may record only these)."""
    return {int(t) for t in _hold_steps(starts)} | {starts["lift"] - 1, starts["end"] - 1}


class _Replay:
    """Loads a rollout's states into scratch data, under the control of the step that follows each."""

    def __init__(self, scene: GraspScene, ctrl: np.ndarray, data: mujoco.MjData | None):
        self.m = scene.model
        self.d = data if data is not None else mujoco.MjData(self.m)
        self.ctrl = ctrl
        self.spec = control_spec()
        self.d.qacc_warmstart[:] = 0.0  # as in a fresh MjData, so reused scratch data gives equal forces

    def load(self, x: np.ndarray, t: int, stage: str) -> mujoco.MjData:
        """State ``x`` of step ``t`` in the data, computed to ``stage``; returns the data.

        ``forward``: contact forces (mj_forward, warm-started by the previous replay); ``collide``:
        contacts only (mj_fwdPosition, which also places flex vertices); ``kinematics``: poses only.
        """
        m, d = self.m, self.d
        mujoco.mj_setState(m, d, x, STATE_SPEC)
        mujoco.mj_setState(m, d, self.ctrl[min(t + 1, len(self.ctrl) - 1)], self.spec)
        if stage == "forward":
            mujoco.mj_forward(m, d)
            d.qacc_warmstart[:] = d.qacc  # the hold samples are a few steps apart
        elif stage == "collide":
            mujoco.mj_fwdPosition(m, d)
        else:
            mujoco.mj_kinematics(m, d)
        return d


def _hold_force(scene: GraspScene, replay: _Replay, states, starts, path: dict) -> np.ndarray:
    """Mean wrench of the fingers on the object over the second half of the first hold, palm frame."""
    acc = np.zeros(6)
    idx = _hold_steps(starts)
    for t in idx:
        d = replay.load(states[t], t, "forward")
        path[int(t)] = d.xipos[scene.object_body].copy()
        w, _, _ = finger_wrench(scene, d)
        _, R = _palm_frame(scene, d)
        acc[:3] += R.T @ w[:3]
        acc[3:] += R.T @ w[3:]
    return acc / len(idx)


def _displacement(scene: GraspScene, replay: _Replay, states, starts, path: dict) -> np.ndarray:
    """Object COM relative to the palm, from the grasp (end of tightening) to the end [m], palm frame.

    Leaves the final state's contacts in the replay's data.
    """
    ob = scene.object_body
    rel = []
    for t, stage in ((starts["lift"] - 1, "kinematics"), (starts["end"] - 1, "collide")):
        d = replay.load(states[t], t, stage)
        path[int(t)] = d.xipos[ob].copy()
        p, R = _palm_frame(scene, d)
        rel.append(R.T @ (d.xipos[ob] - p))
    return rel[1] - rel[0]


def outcome_from_states(
    scene: GraspScene,
    scenario: GraspScenario,
    x0: np.ndarray,
    states: np.ndarray,
    ctrl: np.ndarray,
    starts: dict[str, int],
    data: mujoco.MjData | None = None,
    *,
    sensordata: np.ndarray | None = None,
) -> Outcome:
    """The outcome of a rollout from its initial state ``x0`` and per-step states (nstep, nstate).

    ``sensordata`` (nstep, nsensordata), each step's sensors as ``mujoco.rollout`` returns them: the
    rollout is checked against the energy bound (:mod:`mjcodesign.scenarios.energy`). Every backend
    passes it; without it the energy bound is not checked. The motion bounds
    (``mjcodesign.scenarios.motion``) are always checked. A rollout that breaks a bound is
    :attr:`Failure.IMPLAUSIBLE` (listed first, with its numbers) whatever else it did.

    ``states[t]`` is the state after step t, ``ctrl`` the controls of :func:`phase_controls`. Contact
    forces are recomputed with ``mj_forward`` at the sampled states under the control of the step that
    follows (so they equal that step's), and the single-step and batched paths share this function.
    ``data`` is scratch space of the same model structure (allocated when None).
    """
    m = scene.model
    ob = scene.object_body
    replay = _Replay(scene, ctrl, data)
    # The object's body frame is at its COM (build_scene), so the free joint's position is the COM.
    z0 = float(x0[1 + m.jnt_qposadr[m.body_jntadr[ob]] + 2])  # state = (time, qpos, ...)
    path: dict[int, np.ndarray] = {}
    body_force = _hold_force(scene, replay, states, starts, path)
    displacement = _displacement(scene, replay, states, starts, path)
    d = replay.d
    _, finger, ground = finger_wrench(scene, d, forces=False)  # d holds the final contacts
    rise = float(d.xipos[ob][2]) - z0
    lifted = rise >= scenario.lifted_fraction * scenario.lift
    force_ok = float(np.linalg.norm(body_force[3:])) > _FORCE_EPS
    if not np.all(np.isfinite(body_force)) or not np.all(np.isfinite(displacement)):
        return failed_outcome(Failure.DIVERGED, "diverged: non-finite outcome")
    found = [
        (
            not lifted,
            Failure.NOT_LIFTED,
            f"not lifted (rose {1000 * rise:.1f} mm of {1000 * scenario.lift:.0f})",
        ),
        (ground, Failure.GROUND_CONTACT, "ground contact"),
        (not finger, Failure.NO_FINGER_CONTACT, "no finger contact"),
        (not force_ok, Failure.ZERO_FORCE, "zero finger force"),
    ]
    reasons = [(kind, text) for hit, kind, text in found if hit]
    # Every step's object velocity is in the states (both backends keep them); positions only at the
    # steps the outcome read.
    qv = 1 + m.nq + int(m.jnt_dofadr[m.body_jntadr[ob]])
    motion = motion_bound(
        np.linalg.norm(states[:, qv : qv + 3], axis=1),
        np.array([p[2] for p in path.values()] + [float(d.xipos[ob][2])]),
        z0,
        dt=m.opt.timestep,
        extents=scene.obj.extents,
        lift=scenario.lift,
    )
    broken = [] if motion.plausible else [motion.reason]
    if sensordata is not None:
        balance = energy_balance(m, ob, x0, states, ctrl, sensordata)
        if not balance.plausible:
            broken.insert(0, balance.reason(m.opt.timestep))
    if broken:
        reasons.insert(0, (Failure.IMPLAUSIBLE, "; ".join(broken)))
    return Outcome(
        success=not reasons,
        body_force=tuple(body_force),
        displacement=tuple(displacement),
        ground_contact=ground,
        reason="; ".join(text for _, text in reasons) if reasons else "ok",
        failures=tuple(kind for kind, _ in reasons),
        finger_contact=finger,
        lift_height=rise,
        object_path=np.array([path[t] for t in sorted(path)]),
    )
