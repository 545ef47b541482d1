"""MjSpec builders shared by the finger models: options, scene, finger frames and the gripper.

Models are built with :class:`mujoco.MjSpec`; the static scene (ground, light, visual) is the file
``models_xml/scene.xml``, attached into the spec.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mjcodesign import models_xml
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, PoseError

__all__ = [
    "FingerModel",
    "TendonMode",
    "SimOptions",
    "FingerHandle",
    "GripperPose",
    "Built",
    "CONTYPE_FINGER",
    "CONTYPE_WORLD",
    "finger_frame_quat",
    "new_spec",
    "build_finger",
    "build_gripper",
    "set_openings",
    "make_data",
]

CONTYPE_WORLD = 1
"""Contact bit of the ground and objects."""
CONTYPE_FINGER = 2
"""Contact bit of finger geoms: they touch the world and objects, never each other."""

# Largest opening of one finger from the palm centre [m]: Franka Hand stroke is 80 mm in total.
_MAX_OPENING = 0.06
# Lift servo stiffness [N/m]: 0.05 kg of fingers sag it by 0.02 mm.
_LIFT_KP = 20000.0
_PALM_HALF = np.array([0.015, 0.045, 0.01])  # palm box half-sizes [m]


class FingerModel(enum.Enum):
    """Which MuJoCo discretisation of the finger."""

    CHAIN = "chain"
    """Pseudo-rigid body: one hinge per block at its midpoint, k = E I / l."""
    FLEX = "flex"
    """MuJoCo flex with trilinear interpolated dofs."""
    FLEX_QUADRATIC = "flex-quadratic"
    """MuJoCo flex with quadratic interpolated dofs (high fidelity, slow)."""

    @property
    def is_flex(self) -> bool:
        """True for the flex models."""
        return self is not FingerModel.CHAIN


class TendonMode(enum.Enum):
    """How the tendon acts on the finger."""

    NATIVE = "native"
    """A MuJoCo spatial tendon through one site per waypoint, pulled by a force actuator."""
    POINT_FORCE = "point-force"
    """The paper's model: forces at the waypoints, applied each step (see :mod:`mjcodesign.tendon`)."""


@dataclass(frozen=True, kw_only=True)
class SimOptions:
    """Numerical options of a finger or gripper model."""

    timestep: float = 2e-3
    """Step [s]."""
    damping_time: float = 5e-3
    """Stiffness-proportional (Rayleigh) damping time [s]: hinge damping b = β k, flex damping β.

    With implicit damping, β >= dt/2 keeps the explicit hinge springs stable whatever their stiffness.
    """
    iterations: int = 200
    """Constraint-solver iterations (flex models need more, see ``flex_iterations``)."""
    flex_iterations: int = 2000
    """Iteration cap of the solver and M+K solve for trilinear flex (they stop on ``flex_tolerance``)."""
    flex_quadratic_iterations: int = 10000
    """Iteration cap for quadratic flex: 2000 under-converged (residual 2.5e-6) during a 1-s curl."""
    tolerance: float = 1e-8
    """Solver tolerance (chain)."""
    flex_tolerance: float = 1e-6
    """Solver and M+K tolerance for flex models: 1e-6 moves a 0.4-s curl's tip by < 1 µm from 1e-12."""
    gravity: bool = True
    """Enable gravity."""
    flex_cells: int | None = None
    """Interpolation cells along the finger; None aligns cells with blocks where the design allows."""
    poisson: float = 0.45
    """Poisson ratio of TPU (paper)."""
    friction: float = 1.0
    """Sliding friction coefficient of finger contacts (paper: mu = 1)."""
    max_tension: float = 50.0
    """Upper bound of the tendon actuator [N]."""

    def __post_init__(self) -> None:
        if not (0 < self.timestep <= 0.01):
            raise DesignError(f"timestep must be in (0, 0.01] s, got {self.timestep}")
        if self.damping_time < 0.5 * self.timestep:
            raise DesignError("damping_time must be at least timestep/2 for stable hinge springs")
        if not (0 <= self.poisson < 0.5):
            raise DesignError("poisson must be in [0, 0.5)")


@dataclass
class FingerHandle:
    """Names of one finger's elements in a compiled model."""

    prefix: str
    model: FingerModel
    base_body: str
    waypoint_sites: list[str]
    tip_site: str
    tendons: list[str] = field(default_factory=list)
    actuators: list[str] = field(default_factory=list)
    """Native mode: tension actuators; the finger's tension is split equally among them."""
    site_chains: list[list[str]] = field(default_factory=list)
    """Waypoint site chains, one per native tendon copy."""
    grid: tuple[int, int, int, int, int] | None = None
    """Flex: (nx, ny, nz, n_cells, order) of the node grid."""
    joints: list[str] = field(default_factory=list)
    """Chain: hinge names, base to tip."""
    bodies: list[str] = field(default_factory=list)
    """Chain: block bodies base to tip; flex: node bodies."""
    flex: str | None = None
    cell_young: np.ndarray | None = None
    """Flex: effective modulus written into each cell [Pa]."""


@dataclass(frozen=True)
class GripperPose:
    """Palm pose in the world and the two finger openings.

    The palm frame: ``-z`` is the approach direction (fingers hang along it), ``y`` is the closing axis.
    Finger A sits at ``+y`` and finger B at ``-y``; an opening is the distance from the palm's
    mid-plane to the finger's inner face [m].
    """

    position: tuple[float, float, float] = (0.0, 0.0, 0.25)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    openings: tuple[float, float] = (0.04, 0.04)

    def __post_init__(self) -> None:
        p, q, s = np.asarray(self.position), np.asarray(self.quat), np.asarray(self.openings)
        if p.shape != (3,) or q.shape != (4,) or s.shape != (2,):
            raise PoseError("pose needs position (3), quaternion (4) and two openings")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q)) and np.all(np.isfinite(s))):
            raise PoseError("pose contains NaN or inf")
        if abs(np.linalg.norm(q) - 1.0) > 1e-6:
            raise PoseError("pose quaternion must have unit norm")
        if np.any(s < 0) or np.any(s > _MAX_OPENING):
            raise PoseError(f"openings must be in [0, {_MAX_OPENING}] m, got {tuple(s)}")

    @classmethod
    def from_matrix(cls, T: np.ndarray, openings=(0.04, 0.04)) -> GripperPose:
        """From a 4x4 homogeneous palm pose."""
        T = np.asarray(T, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise PoseError("pose matrix must be a finite 4x4")
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, T[:3, :3].ravel())
        return cls(tuple(T[:3, 3]), tuple(q), tuple(openings))


@dataclass
class Built:
    """A compiled model with the handles to its fingers."""

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    fingers: list[FingerHandle]
    design: FingerDesign
    stiffness: Stiffness
    finger_model: FingerModel
    tendon_mode: TendonMode
    options: SimOptions
    openings: tuple[float, float] | None = None


def finger_frame_quat(side: int) -> np.ndarray:
    """Orientation of finger A (side=+1) or B (side=-1) in the palm frame, as a quaternion.

    Finger x (length) runs along palm -z; finger z (inner side) points to the palm's mid-plane.
    """
    x_f = np.array([0.0, 0.0, -1.0])
    z_f = np.array([0.0, -float(side), 0.0])
    y_f = np.cross(z_f, x_f)
    R = np.column_stack([x_f, y_f, z_f])
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    return q


def new_spec(
    name: str, options: SimOptions, *, flex: bool, scene: bool = True, quadratic: bool = False
) -> mujoco.MjSpec:
    """An empty spec with the simulation options (and the ground scene)."""
    if scene:
        spec = mujoco.MjSpec.from_file(str(models_xml.SCENE_XML))
    else:
        spec = mujoco.MjSpec()
    spec.modelname = name
    opt = spec.option
    opt.timestep = options.timestep
    # MuJoCo 4.0 integrates flex elasticity implicitly only under the 'discrete' integrator.
    opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE if flex else mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.solver = mujoco.mjtSolver.mjSOL_CG if flex else mujoco.mjtSolver.mjSOL_NEWTON
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    if flex:
        opt.iterations = options.flex_quadratic_iterations if quadratic else options.flex_iterations
    else:
        opt.iterations = options.iterations
    opt.tolerance = options.flex_tolerance if flex else options.tolerance
    if not options.gravity:
        opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_GRAVITY
    return spec


def _add_tendon(spec: mujoco.MjSpec, handle: FingerHandle, exit_site: str, options: SimOptions) -> None:
    """Native spatial tendon(s) from the base exit through every waypoint, pulled by force motors."""
    chains = handle.site_chains or [handle.waypoint_sites]
    for j, chain in enumerate(chains):
        suffix = "" if len(chains) == 1 else f"_{j}"
        ten = spec.add_tendon(name=f"{handle.prefix}tendon{suffix}")
        ten.wrap_site(exit_site)
        for s in chain:
            ten.wrap_site(s)
        act = spec.add_actuator(name=f"{handle.prefix}tension{suffix}", target=ten.name)
        act.trntype = mujoco.mjtTrn.mjTRN_TENDON
        # Negative gear: a positive control is a tension [N] that shortens the tendon.
        act.gear[0] = -1.0
        act.ctrllimited = True
        act.ctrlrange = [0.0, options.max_tension]
        handle.tendons.append(ten.name)
        handle.actuators.append(act.name)


def _add_finger(spec, parent, design, young, model, prefix, tendon_mode, options) -> FingerHandle:
    if model is FingerModel.CHAIN:
        from mjcodesign.models.chain import add_chain_finger

        handle = add_chain_finger(spec, parent, design, young, prefix, options)
    else:
        from mjcodesign.models.flex import add_flex_finger

        handle = add_flex_finger(
            spec, parent, design, young, prefix, options, quadratic=model is FingerModel.FLEX_QUADRATIC
        )
    exit_site = parent.add_site(
        name=f"{prefix}tendon_exit", pos=design.tendon_exit() - [0.004, 0, 0], size=[0.001, 0, 0], group=3
    )
    if tendon_mode is TendonMode.NATIVE:
        _add_tendon(spec, handle, exit_site.name, options)
    return handle


def _model_spec(
    kind, design, stiffness, model: FingerModel, options: SimOptions, scene: bool
) -> mujoco.MjSpec:
    if stiffness.n_blocks != design.n_blocks:
        raise DesignError(f"stiffness has {stiffness.n_blocks} blocks per finger, design {design.n_blocks}")
    quadratic = model is FingerModel.FLEX_QUADRATIC
    return new_spec(f"{kind}_{model.value}", options, flex=model.is_flex, scene=scene, quadratic=quadratic)


def build_finger(
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel,
    *,
    tendon_mode: TendonMode = TendonMode.NATIVE,
    options: SimOptions | None = None,
    finger: int = 0,
    scene: bool = False,
) -> Built:
    """One finger clamped at its base, lying along world +x and bending towards world +z."""
    options = options or SimOptions()
    model = FingerModel(model)
    spec = _model_spec("finger", design, stiffness, model, options, scene)
    base = spec.worldbody.add_body(name="A_base", pos=[0, 0, 0.2 if scene else 0.0])
    handle = _add_finger(spec, base, design, stiffness.finger(finger), model, "A_", tendon_mode, options)
    m = _compile(spec)
    _finalise(m, [handle])
    return Built(spec, m, [handle], design, stiffness, model, tendon_mode, options)


def build_gripper(
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel,
    *,
    pose: GripperPose | None = None,
    tendon_mode: TendonMode = TendonMode.NATIVE,
    options: SimOptions | None = None,
    scene: bool = True,
) -> Built:
    """Two opposed fingers on a palm: lift slide (world z), palm at ``pose``, prismatic openings."""
    options = options or SimOptions()
    model = FingerModel(model)
    pose = pose or GripperPose()
    spec = _model_spec("gripper", design, stiffness, model, options, scene)
    # The arm holds the palm: gravity-compensate the palm and carriages, not the soft fingers.
    mount = spec.worldbody.add_body(name="mount", pos=list(pose.position), gravcomp=1.0)
    mount.add_joint(name="lift", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1], damping=50.0)
    palm = mount.add_body(name="palm", quat=list(pose.quat), gravcomp=1.0)
    palm.add_geom(
        name="palm",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=_PALM_HALF,
        pos=[0, 0, _PALM_HALF[2]],
        mass=0.5,
        rgba=[0.25, 0.25, 0.28, 1],
        contype=CONTYPE_FINGER,
        conaffinity=CONTYPE_WORLD,
    )
    lift = spec.add_actuator(name="lift", target="lift")
    lift.trntype = mujoco.mjtTrn.mjTRN_JOINT
    lift.set_to_position(kp=_LIFT_KP, dampratio=1.0)
    lift.ctrlrange = [-0.5, 0.5]
    lift.ctrllimited = True
    handles = []
    for i, (side, letter) in enumerate(((1, "A"), (-1, "B"))):
        carriage = palm.add_body(name=f"{letter}_carriage", gravcomp=1.0)
        carriage.add_joint(
            name=f"{letter}_slide",
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0, side, 0],
            range=[0, _MAX_OPENING],
            damping=20.0,
        )
        carriage.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.012, 0.004, 0.006],
            mass=0.05,
            contype=0,
            conaffinity=0,
            rgba=[0.3, 0.3, 0.3, 1],
        )
        base = carriage.add_body(
            name=f"{letter}_base", pos=[0, side * design.height_base, 0], quat=finger_frame_quat(side)
        )
        handles.append(
            _add_finger(spec, base, design, stiffness.finger(i), model, f"{letter}_", tendon_mode, options)
        )
        act = spec.add_actuator(name=f"{letter}_opening", target=f"{letter}_slide")
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=500.0, dampratio=1.0)
        act.ctrlrange = [0, _MAX_OPENING]
        act.ctrllimited = True
    m = _compile(spec)
    _finalise(m, handles)
    built = Built(spec, m, handles, design, stiffness, model, tendon_mode, options)
    built.openings = tuple(pose.openings)
    return built


def set_openings(built: Built, openings, data: mujoco.MjData, *, qpos: bool = False) -> None:
    """Command the two openings [m] (position actuators); with ``qpos`` also place the fingers there."""
    m = built.model
    for letter, s in zip("AB", openings, strict=True):
        if qpos:
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{letter}_slide")
            data.qpos[m.jnt_qposadr[jid]] = s
        data.ctrl[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{letter}_opening")] = s


def make_data(built: Built) -> mujoco.MjData:
    """Fresh MjData; for a gripper, fingers placed at the pose's openings."""
    d = mujoco.MjData(built.model)
    if built.openings is not None:
        set_openings(built, built.openings, d, qpos=True)
    mujoco.mj_forward(built.model, d)
    return d


def _compile(spec: mujoco.MjSpec) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:  # MuJoCo compile errors
        raise DesignError(f"MuJoCo could not compile the model: {exc}") from exc


def _finalise(m: mujoco.MjModel, handles: list[FingerHandle]) -> None:
    for h in handles:
        if h.model.is_flex:
            from mjcodesign.models.flex import apply_cell_young

            apply_cell_young(m, h)
