"""What a real robot does differently each time: one perturbed draw of a grasp, written into a scene copy.

A :class:`Perturbation` moves and turns the palm (arm repeatability and camera calibration), scales the
object's mass (inertia with it: same shape, uniform density), the fingers' sliding friction (the finger–object
pair's) and
the tendon drive (the force mode's tension, or the position servo's gain and tension limit).
:func:`perturbed_scene` writes one into a copy of a compiled scene without recompiling, so a batch of
perturbed scenes shares one model structure and runs through one ``mujoco.rollout`` call.

A :class:`PerturbationModel` holds the ranges draws come from (uniform, independent, each ± its value);
:func:`draw_perturbations` draws a pose's perturbations from a seeded stream, drawing again where a
draw's start overlaps the object or the ground. The ranges and where each comes from:

- palm position ±2 mm per axis and rotation ±2° per axis: the Franka arm's pose repeatability
  (±0.1 mm, its datasheet) is small beside a wrist or fixed camera's hand–eye calibration error, which
  is of the order of millimetres and a degree or two; ±2 mm and ±2° stand for the two together;
- object mass ±10 %: a household object's mass varies with its filling and the scale's error;
- finger–object friction ±20 %: the spread of friction coefficients of a rubbery gripping surface
  against common object materials (paper, plastic, fruit skin, metal);
- tendon drive ±5 %: the XL330's torque constant and current sensing vary from unit to unit, and the
  spool radius with the print.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import zlib
from collections.abc import Callable
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from mjcodesign.errors import DesignError, PoseError
from mjcodesign.models.builder import make_data
from mjcodesign.models.types import GripperPose
from mjcodesign.scenarios.drive import TendonForce
from mjcodesign.scenarios.grasp import GraspScenario, GraspScene, drive_scene, scene_at_pose

__all__ = [
    "MAX_REDRAWS",
    "NOMINAL",
    "Perturbation",
    "PerturbationModel",
    "draw_perturbations",
    "perturbed_pose",
    "perturbed_scene",
    "start_penetration",
]

MAX_REDRAWS = 50
"""Draws tried per perturbation before it is given up (:func:`draw_perturbations` returns None for it)."""
_PERTURB_STREAM = 0x5E7  # the perturbation draws' own random stream, apart from the suite's pose seed


@dataclass(frozen=True, kw_only=True)
class Perturbation:
    """One draw of the differences between two executions of the same grasp."""

    palm_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Palm position offset in the world frame [m]."""
    palm_rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Palm rotation about its own origin, a rotation vector in the world frame [rad]."""
    mass_scale: float = 1.0
    """Object mass and inertia factor [-]."""
    friction_scale: float = 1.0
    """Finger–object sliding friction factor [-]."""
    tendon_scale: float = 1.0
    """Tendon drive factor [-]: the tension (force mode) or the servo's gain and tension limit."""

    def __post_init__(self) -> None:
        for name in ("palm_offset", "palm_rotation"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise DesignError(f"perturbation {name} must be 3 finite numbers, got {getattr(self, name)}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        for name in ("mass_scale", "friction_scale", "tendon_scale"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise DesignError(f"perturbation {name} must be a finite factor > 0, got {v}")
            object.__setattr__(self, name, float(v))

    @property
    def is_nominal(self) -> bool:
        """Whether this draw changes nothing."""
        return self == NOMINAL

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return dataclasses.asdict(self)

    def as_array(self) -> np.ndarray:
        """The nine numbers, shape (9,): palm offset [m] (3), rotation [rad] (3), mass, friction, tendon [-]."""
        return np.array(
            [*self.palm_offset, *self.palm_rotation, self.mass_scale, self.friction_scale, self.tendon_scale]
        )


NOMINAL = Perturbation()
"""The draw that changes nothing."""


@dataclass(frozen=True, kw_only=True)
class PerturbationModel:
    """Uniform ranges (± each value) of what a real robot does differently on each execution."""

    palm_position_m: float = 0.002
    """Palm position error per world axis [m]."""
    palm_rotation_deg: float = 2.0
    """Palm rotation error per world axis [deg] (a rotation vector's components)."""
    mass: float = 0.10
    """Object mass error, relative [-]."""
    friction: float = 0.20
    """Finger–object friction error, relative [-]."""
    tendon: float = 0.05
    """Tendon tension or servo gain error, relative [-]."""

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise DesignError(f"perturbation range {name} must be a finite value >= 0, got {value!r}")
        for name in ("mass", "friction", "tendon"):
            if getattr(self, name) >= 1:
                raise DesignError(
                    f"perturbation range {name} must be < 1 (a factor 1 ± it), got {getattr(self, name)}"
                )

    def draw(self, rng: np.random.Generator) -> Perturbation:
        """One draw (nine uniform numbers from ``rng``, in a fixed order)."""
        u = rng.uniform(-1.0, 1.0, size=9)
        return Perturbation(
            palm_offset=tuple(self.palm_position_m * u[0:3]),
            palm_rotation=tuple(np.deg2rad(self.palm_rotation_deg) * u[3:6]),
            mass_scale=1.0 + self.mass * u[6],
            friction_scale=1.0 + self.friction * u[7],
            tendon_scale=1.0 + self.tendon * u[8],
        )

    def stream(self, seed: int, obj: str, pose: int) -> np.random.Generator:
        """The draws' generator of one (object, pose): shared by every design (common random numbers)."""
        return np.random.default_rng([int(seed), _PERTURB_STREAM, zlib.crc32(obj.encode()), int(pose)])

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def draw_perturbations(
    model: PerturbationModel,
    rng: np.random.Generator,
    n: int,
    scene: GraspScene,
    scenario: GraspScenario,
    pose: GripperPose,
    *,
    max_penetration: float,
    max_redraws: int = MAX_REDRAWS,
    keep: Callable[[Perturbation, GraspScene], None] | None = None,
) -> tuple[list[Perturbation | None], int]:
    """``n`` draws of ``model`` from ``rng`` for ``scene`` at ``pose``, and how many were drawn again.

    A draw whose start penetrates deeper than ``max_penetration`` [m] (:func:`start_penetration`), or
    whose pose cannot be simulated, is drawn again, at most ``max_redraws`` times; then that draw is
    None (given up). The draws come from ``rng`` in order, so ``n`` draws and then ``m`` more from the
    same generator are the first ``n + m`` draws of one call. ``keep`` receives each accepted draw and
    its :func:`perturbed_scene`, so that a caller can roll out that scene instead of building it again.
    """
    out: list[Perturbation | None] = []
    redrawn = 0
    for _ in range(n):
        for _attempt in range(max_redraws):
            p = model.draw(rng)
            try:
                moved = perturbed_scene(scene, scenario, p, pose=pose)
                if start_penetration(moved) <= max_penetration:
                    out.append(p)
                    if keep is not None:
                        keep(p, moved)
                    break
            except PoseError:
                pass
            redrawn += 1
        else:
            out.append(None)
    return out, redrawn


def perturbed_pose(pose: GripperPose, p: Perturbation) -> GripperPose:
    """``pose`` moved by ``p.palm_offset`` and turned by ``p.palm_rotation`` about the palm's origin."""
    q_rot = np.zeros(4)
    mujoco.mju_axisAngle2Quat(q_rot, *_axis_angle(np.asarray(p.palm_rotation)))
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, q_rot, np.asarray(pose.quat, dtype=float))
    q /= np.linalg.norm(q)
    return GripperPose(tuple(np.asarray(pose.position) + np.asarray(p.palm_offset)), tuple(q), pose.openings)


def _axis_angle(rotvec: np.ndarray) -> tuple[np.ndarray, float]:
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return np.array([0.0, 0.0, 1.0]), 0.0
    return rotvec / angle, angle


def perturbed_scene(
    scene: GraspScene, scenario: GraspScenario, p: Perturbation, *, pose: GripperPose | None = None
) -> GraspScene:
    """``scene`` at ``pose`` (default: its own) under draw ``p``, driven for ``scenario``.

    The result's ``drive`` names the scenario's tendon drive, so that backends leave it as it is.

    Writes into a model copy: object ``body_mass`` and ``body_inertia`` times ``mass_scale``; the sliding
    friction of the fingers' geoms times ``friction_scale`` (MuJoCo takes the larger of two geoms'
    coefficients and the object's geoms carry MuJoCo's minimum, so the finger–object pair scales); the tendon actuators'
    gear (force mode: tension = gear · control) or the servo's gain, bias and force range (position mode)
    times ``tendon_scale``. Then the palm moves (:func:`perturbed_pose`, :func:`scene_at_pose`, whose
    ``mj_setConst`` also takes the new mass into the derived constants). Raises :class:`PoseError` when
    the perturbed pose cannot be simulated.
    """
    m = copy.copy(scene.model)
    b = scene.object_body
    m.body_mass[b] *= p.mass_scale
    m.body_inertia[b] *= p.mass_scale
    # The pair takes the larger coefficient, the fingers' (the object's geoms carry MuJoCo's minimum).
    m.geom_friction[scene.finger_mask[m.geom_bodyid], 0] *= p.friction_scale
    force_mode = isinstance(scenario.tendon, TendonForce)
    actuators = [
        mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        for h in scene.built.fingers
        for name in h.actuators
    ]
    if force_mode:  # before mj_setConst, which derives actuator_acc0 from the gear
        m.actuator_gear[actuators, 0] *= p.tendon_scale
    staged = copy.copy(scene)
    staged.built = dataclasses.replace(scene.built, model=m)
    staged.model = m
    target = scene.pose if pose is None else pose
    if any(p.palm_offset) or any(p.palm_rotation) or target != scene.pose:
        moved = scene_at_pose(staged, perturbed_pose(target, p))
    else:
        mujoco.mj_setConst(m, mujoco.MjData(m))
        moved = staged
    driven = drive_scene(moved, scenario)
    if not force_mode:  # the servo's parameters, as apply_drive wrote them into the driven copy
        dm = driven.model
        dm.actuator_gainprm[actuators, 0] *= p.tendon_scale
        dm.actuator_biasprm[actuators, 1] *= p.tendon_scale
        dm.actuator_forcerange[actuators] *= p.tendon_scale
    driven.drive = scenario.tendon
    return driven


def start_penetration(scene: GraspScene) -> float:
    """Deepest penetration at the rollout's start [m]: gripper into object or ground, object into ground.

    The initial state (start openings) after ``mj_forward``; 0 when nothing overlaps. A palm perturbation
    can push the open fingers into the object, which the settle phase would then push apart with energy
    nothing put in.
    """
    m = scene.model
    d = make_data(scene.built)
    gripper = scene.finger_mask.copy()
    gripper[[scene.palm_body, scene.mount_body]] = True
    deepest = 0.0
    for c in d.contact[: d.ncon]:
        b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
        obj = scene.object_body in (b1, b2)
        ground = scene.ground_geom in (c.geom1, c.geom2)
        grip = gripper[b1] or gripper[b2]
        if (obj and (grip or ground)) or (ground and grip):
            deepest = max(deepest, -float(c.dist))
    return deepest
