"""Shared model types: finger discretisations, tendon modes, simulation options, poses, handles and the built model.

This module imports no builder, so the builders (:mod:`~mjcodesign.models.chain`, :mod:`~mjcodesign.models.flex`,
:mod:`~mjcodesign.models.builder`) can all depend on it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, PoseError, UnsupportedError

__all__ = [
    "CONTYPE_FINGER",
    "CONTYPE_WORLD",
    "MAX_OPENING",
    "LIFT_KP",
    "STIFFNESS_MODELS",
    "PALM_HALF",
    "TENDON_LEVERS",
    "ROUTINGS",
    "MAX_FLEXURE_HINGES",
    "PRINTED_FLEXURE_HINGES",
    "DEFAULT_TIMESTEP",
    "TIED_TIMESTEP",
    "FLEX_GRASP_REFUSAL",
    "grasp_model",
    "tendon_exit_site",
    "FingerModel",
    "TendonMode",
    "SimOptions",
    "FingerHandle",
    "GripperPose",
    "Built",
]


CONTYPE_WORLD = 1
"""Contact bit of the ground and objects."""


CONTYPE_FINGER = 2
"""Contact bit of finger geoms: they touch the world and objects, never each other."""

TENDON_LEVERS = ("constant", "path")
"""How the chain's tendon acts on its hinges (:attr:`SimOptions.tendon_lever`)."""

ROUTINGS = ("guided", "printed")
"""Where the chain's tendon runs (:attr:`SimOptions.routing`)."""

MAX_FLEXURE_HINGES = 16
"""Most chain hinges per flexure under the printed routing (:attr:`SimOptions.hinges_per_block`): with 16
the first flexure's buckling tension under the printed tendon is 0.24% short of its Euler–Bernoulli
limit (the gap falls as 1/n²)."""


PRINTED_FLEXURE_HINGES = 2
"""Hinges per flexure of the ``printed`` routing's default chain, tied to one angle
(:attr:`SimOptions.tied_flexures`). Two tied hinges buckle uniform fingers at 1.005× the converged FEM's
global modes; three at 1.12× and four at 1.16×, the tie holding an arc of equal turns, stiffer than the
flexure's own mode as n grows (docs/concepts/models.md)."""

DEFAULT_TIMESTEP = 2e-3
"""Step [s] of every model but a chain with tied flexures."""

TIED_TIMESTEP = 1e-3
"""Default step [s] of a chain with tied flexures (:attr:`SimOptions.tied_flexures`). At 2 ms the servo's
pull (up to 65 N, tens of times a soft finger's buckling tension) whips the fingers faster than a step
resolves: of 8 real-regime grasps 3 diverged and 3 broke the energy bound; at 1 ms none did
(``benchmarks/records/2026-12-05_tied_flexure_grasps.json``)."""


def tendon_exit_site(design: FingerDesign) -> np.ndarray:
    """Where the tendon leaves the palm, in the finger frame [m]: 4 mm behind the finger's base exit."""
    return design.tendon_exit() - np.array([0.004, 0.0, 0.0])


# Largest opening of one finger from the palm centre [m]: Franka Hand stroke is 80 mm in total.
MAX_OPENING = 0.06
"""Largest opening of one finger from the palm centre [m] (the gripper's stroke)."""


# Lift servo stiffness [N/m]: 0.05 kg of fingers sag it by 0.02 mm.
LIFT_KP = 20000.0
"""Lift servo stiffness [N/m]."""


PALM_HALF = np.array([0.015, 0.045, 0.01])
"""Palm box half-sizes [m]."""


STIFFNESS_MODELS = ("fem", "beam")
"""How block moduli become finger stiffness (:attr:`SimOptions.stiffness_model`)."""


class FingerModel(enum.Enum):
    """Which MuJoCo discretisation of the finger."""

    CHAIN = "chain"
    """Pseudo-rigid body: one hinge per block at its midpoint (:mod:`mjcodesign.models.chain`).

    Hinge stiffness by :attr:`SimOptions.stiffness_model`: ``fem`` (default) k_i = 1 / c_i, block i's
    compliance in the calibrated FEM, about its fitted bending axis; ``beam`` k_i = E_i I_i / l_i.
    """
    FLEX = "flex"
    """MuJoCo flex with trilinear interpolated dofs."""
    FLEX_QUADRATIC = "flex-quadratic"
    """MuJoCo flex with quadratic interpolated dofs (high fidelity, slow)."""

    @property
    def is_flex(self) -> bool:
        """True for the flex models."""
        return self is not FingerModel.CHAIN


FLEX_GRASP_REFUSAL = (
    "the flex models cannot grasp: their tendon curl is 37-49% short of the FEM's on a 22-block design "
    "and no flex grasp holds the tests' 50 g box (the native tendon rides on the wrong interpolation "
    "nodes); grasp with the chain (flex stays for curl, validate beam, crosscheck curl and finger export)"
)
"""Why :func:`grasp_model` refuses the flex models (docs/benchmarks.md, flex grasp)."""


def grasp_model(model: FingerModel | str) -> FingerModel:
    """``model`` as a :class:`FingerModel` that may grasp; :class:`UnsupportedError` for the flex models.

    The one rule for every grasp: a job (:class:`mjcodesign.jobs.GraspJob`), and a command's
    ``--model`` before any work.
    """
    model = FingerModel(model)
    if model.is_flex:
        raise UnsupportedError(f"{model.value}: {FLEX_GRASP_REFUSAL}")
    return model


class TendonMode(enum.Enum):
    """How the tendon acts on the finger."""

    NATIVE = "native"
    """A MuJoCo spatial tendon through one site per waypoint, pulled by a force actuator."""
    POINT_FORCE = "point-force"
    """The paper's model: forces at the waypoints, applied each step (see :mod:`mjcodesign.models.tendon`)."""


_ROUTING_DEPENDENT = ("timestep", "hinges_per_block", "tied_flexures")
"""The :class:`SimOptions` fields whose None default the routing resolves."""


@dataclass(frozen=True, kw_only=True)
class SimOptions:
    """Numerical options of a finger or gripper model.

    Derive options with :meth:`replace`, which resolves the routing's defaults again.
    """

    timestep: float | None = None
    """Step [s]; None: :data:`DEFAULT_TIMESTEP`, or :data:`TIED_TIMESTEP` for a chain with
    :attr:`tied_flexures`."""
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
    hinge_armature: float = 1e-6
    """Rotor-like inertia added to every chain hinge [kg m²] (selective mass scaling). A tendon at
    tension T pulling a block over a lever d adds a geometric stiffness ~T d to its hinge; on the 2-g tip
    block (3e-8 kg m² about its hinge) at 50 N that is ω dt ≈ 3.5 at dt = 2 ms, past the explicit limit
    of 2, and the grasp blew up (BADQACC) or made energy. 1e-6 brings ω dt below 1 up to the tension
    limit; it is 3% of one finger's inertia about its base, so the slow grasp motion hardly sees it
    (docs/benchmarks.md, time step and armature)."""
    hinges_per_block: int | None = None
    """Chain hinges per block (None: 1, or :data:`PRINTED_FLEXURE_HINGES` per flexure for the ``printed``
    :attr:`routing`, tied, unless :attr:`tied_flexures` is False): 1, at its middle; or 2, at its quarter points, each twice as stiff (the
    same small-deflection compliance), with the middle link carrying the block's tendon waypoint. Two
    hinges keep a spatial tendon's lever as the block bends (the curl within 4.4% of the FEM's to 1.4 rad,
    6.7% at 3.3 rad); the default single hinge gets the same from :attr:`tendon_lever` ``constant``
    (within 7.0% on 30 random designs to 1.6 rad) and has the stops, which the split chain lacks: its
    grasps fold a flexure's middle link and lose the tests' box (docs/benchmarks.md, large-bend curl). An
    experiment option, kept for the FEM curls recorded with it (docs/validation/experiment-options.md).

    Under the ``printed`` :attr:`routing` it counts each flexure's hinges, 1 to :data:`MAX_FLEXURE_HINGES`;
    the segments, which carry the channels, keep their one hinge. n hinges sit at the middles of the
    flexure's n equal parts, each n times as stiff, and the tendon's straight span across the gap crosses
    all of them, as it crosses a flexure that bends along its length: one hinge at the middle would buckle
    at k (a+b)/(ab), n → ∞ at an Euler–Bernoulli flexure's tension, 1.75× that on the first flexure (the
    single hinge's guides give it that tension: :attr:`routing`). A
    flexure's stop holds the sum of its hinges (a limited fixed tendon) where a single hinge's range
    holds its angle (:mod:`mjcodesign.models.chain`). Free, its hinges fold into an S past buckling, so
    :func:`~mjcodesign.models.build_gripper` refuses them (``FLEXURE_HINGES_GRASP_REFUSAL``) unless they
    are :attr:`tied_flexures`."""
    tendon_lever: str = "constant"
    """How the chain's guided native tendon (:attr:`routing`) acts on its hinges. ``constant`` (default): a fixed tendon,
    ``ℓ = Σ_j (dℓ/dθ_j)₀ θ_j``, every hinge's lever frozen at the straight finger's
    (:attr:`FingerHandle.joint_levers`): the same force on the straight finger as ``path``, and the FEM's
    behaviour at large bends, where each waypoint rides on its block's middle section and its lever stays
    within 2% (5.50-5.59 mm to 0.63 rad on a soft flexure of random:0). ``path``: a spatial tendon through
    the waypoints; on one hinge per block a waypoint sits on the distal body above its hinge and swings
    back over it, the lever falls (5.41 to 3.35 mm at 0.63 rad) and the curl misses the FEM's by up to 31%
    at 1.1-1.6 rad (the default: 7.0%); an experiment option, kept for the records that compare the two
    (docs/validation/experiment-options.md). The point-force mode and the flex models always act at their
    waypoints."""
    routing: str = "guided"
    """Where the chain's native tendon runs. ``guided`` (default): through a waypoint on every block, the
    flexures included, acting as :attr:`tendon_lever` says. ``printed``: as in the printed finger, through
    each segment's channel (sites at its entry, middle and exit at the heights measured on the authors'
    STL, :mod:`mjcodesign.models.channels`) and straight across each flexure gap in air: a spatial tendon
    whose lever and geometric stiffness come from its path. A span from α before a flexure's hinge to β
    after it (along the span) adds −T·αβ/(α+β) to that hinge's stiffness, so a hinge of stiffness k
    buckles past T = k (α+β)/(αβ), 2k/d for α = β = d. A flexure of one hinge is crossed through two
    guides on the span, placed so that it buckles as the flexure bending along its length
    (:func:`~mjcodesign.models.channels.flexure_guides`, 1.74× the span's ends on the first flexure); their
    short span lines up with the hinge at large bends (flexure 1's lever reverses at 0.8 rad). The
    segments' stops are the same. The chain's native tendon only (:class:`UnsupportedError` for a flex
    model or the point-force mode). By default each flexure is :data:`PRINTED_FLEXURE_HINGES` hinges tied
    to one angle (:attr:`tied_flexures`), crossed end to end, at :data:`TIED_TIMESTEP`;
    ``hinges_per_block=1`` gives the one hinge between guides, ``n`` free hinges per flexure."""
    tied_flexures: bool | None = None
    """None: True for the ``printed`` :attr:`routing`'s default flexures (:attr:`hinges_per_block` not
    given), False otherwise. Under the ``printed`` :attr:`routing` with several hinges per flexure (:attr:`hinges_per_block` > 1):
    tie each flexure's hinges to one angle, every consecutive pair by a MuJoCo joint equality
    (``θ_j = θ_{j+1}``; :mod:`mjcodesign.models.chain`). The flexure keeps the n-hinge chain's path for
    the tendon (straight from one channel's exit to the next one's entry across all n) and bends as one
    arc of n equal turns; its hinges cannot fold into an S. :class:`DesignError` where there is nothing to
    tie (the guided routing, or one hinge per flexure)."""
    stiffness_model: str = "fem"
    """How block moduli become finger stiffness: ``fem``, calibrated to the converged Warp FEM
    (:mod:`mjcodesign.design.calibration`; the default finger geometry only), or ``beam``,
    Euler–Bernoulli (exact for uniform designs only; any geometry)."""

    def __post_init__(self) -> None:
        # what the caller gave, before the defaults that depend on the routing fill it (see replace)
        object.__setattr__(self, "_given", {f: getattr(self, f) for f in _ROUTING_DEPENDENT})
        self._resolve_defaults()
        if self.stiffness_model not in STIFFNESS_MODELS:
            raise DesignError(
                f"stiffness_model must be one of {STIFFNESS_MODELS}, got {self.stiffness_model!r}"
            )
        if not (0 < self.timestep <= 0.01):
            raise DesignError(f"timestep must be in (0, 0.01] s, got {self.timestep}")
        if self.damping_time < 0.5 * self.timestep:
            raise DesignError("damping_time must be at least timestep/2 for stable hinge springs")
        if not (np.isfinite(self.hinge_armature) and self.hinge_armature >= 0):
            raise DesignError("hinge_armature must be a finite inertia >= 0 kg m²")
        if not (0 <= self.poisson < 0.5):
            raise DesignError("poisson must be in [0, 0.5)")
        if self.tendon_lever not in TENDON_LEVERS:
            raise DesignError(f"tendon_lever must be one of {TENDON_LEVERS}, got {self.tendon_lever!r}")
        if self.routing not in ROUTINGS:
            raise DesignError(f"routing must be one of {ROUTINGS}, got {self.routing!r}")
        hinges = self.hinges_per_block
        if self.routing == "printed":
            if (
                isinstance(hinges, bool)
                or not isinstance(hinges, int)
                or not 1 <= hinges <= MAX_FLEXURE_HINGES
            ):
                raise DesignError(
                    f"the printed routing's hinges_per_block (hinges per flexure) must be a whole number "
                    f"from 1 to {MAX_FLEXURE_HINGES}, got {hinges!r}"
                )
        elif hinges not in (1, 2) or isinstance(hinges, bool):
            raise DesignError(f"hinges_per_block must be 1 or 2, got {hinges!r}")
        if not isinstance(self.tied_flexures, bool):
            raise DesignError(f"tied_flexures must be True, False or None, got {self.tied_flexures!r}")
        if self.tied_flexures and (self.routing != "printed" or hinges == 1):
            raise DesignError(
                "tied_flexures ties the hinges of a printed chain's flexure to one angle: it needs "
                f"routing='printed' and hinges_per_block > 1 (got {self.routing!r}, {hinges!r})"
            )

    def replace(self, **changes) -> SimOptions:
        """These options with ``changes``; the fields left None here are resolved again for the result.

        :attr:`timestep`, :attr:`hinges_per_block` and :attr:`tied_flexures` default by the
        :attr:`routing`: ``SimOptions().replace(routing="printed")`` is the printed routing's default
        (tied flexures at :data:`TIED_TIMESTEP`), as ``SimOptions(routing="printed")`` is, where
        :func:`dataclasses.replace` would pass the guided routing's resolved single hinge and 2 ms step
        on as if they were given.
        """
        unknown = sorted(set(changes) - {f for f in self.__dataclass_fields__})
        if unknown:
            raise DesignError(f"SimOptions has no field {', '.join(unknown)}")
        kept = {f: getattr(self, f) for f in self.__dataclass_fields__ if f not in _ROUTING_DEPENDENT}
        return SimOptions(**{**kept, **self._given, **changes})

    __replace__ = replace  # copy.replace (Python 3.13)

    def _resolve_defaults(self) -> None:
        """Fill the fields left None: the routing's flexure model, then its step."""
        printed = self.routing == "printed"
        tied, hinges = self.tied_flexures, self.hinges_per_block
        if tied is None:
            tied = printed and hinges is None
        if hinges is None:
            hinges = PRINTED_FLEXURE_HINGES if printed and tied else 1
        object.__setattr__(self, "tied_flexures", tied)
        object.__setattr__(self, "hinges_per_block", hinges)
        if self.timestep is None:
            object.__setattr__(self, "timestep", TIED_TIMESTEP if tied is True else DEFAULT_TIMESTEP)


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
    joint_blocks: list[int] = field(default_factory=list)
    """Chain: the block of every hinge in ``joints`` (a block has one, or ``hinges_per_block``: every block
    under the guided routing, the flexures under the printed one)."""
    joint_levers: list[float] = field(default_factory=list)
    """Chain: the waypoint tendon's length change per hinge angle on the straight finger [m/rad], one per
    hinge in ``joints`` (negative: bending shortens the tendon); the coefficients of a constant-lever
    tendon (:attr:`SimOptions.tendon_lever`)."""
    bodies: list[str] = field(default_factory=list)
    """Chain: block bodies base to tip; flex: node bodies."""
    flex: str | None = None
    cell_young: np.ndarray | None = None
    """Flex: effective modulus written into each cell [Pa]."""
    unit_records: np.ndarray | None = None
    """Flex: the compiled cells' stiffness records per pascal, (n_cells, record size), kept when the
    model is compiled so that a design rewritten later (:func:`mjcodesign.models.flex.rescale_cell_young`)
    is fitted from the same numbers as a recompile."""
    fem_fit: tuple[FingerDesign, np.ndarray] | None = None
    """Flex under the ``fem`` stiffness model: the design and the calibrated FEM's block rotations under a
    unit tip load [rad/N] that the cells are fitted to when the model is compiled
    (:func:`mjcodesign.models.flex.apply_cell_young`)."""


ROTATION_TOL = 1e-3
"""Largest |RᵀR − I| entry of a pose's rotation block, as ``poses --import`` checks imported grasps: a
rotation written to 4 digits is off by ~1e-4, a scaled or sheared block by far more."""


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
        if p.shape == (3,) and q.shape == (4,) and s.shape == (2,):  # tuples of floats: hashable, exact
            object.__setattr__(self, "position", tuple(float(x) for x in p))
            object.__setattr__(self, "quat", tuple(float(x) for x in q))
            object.__setattr__(self, "openings", tuple(float(x) for x in s))
        if p.shape != (3,) or q.shape != (4,) or s.shape != (2,):
            raise PoseError("pose needs position (3), quaternion (4) and two openings")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q)) and np.all(np.isfinite(s))):
            raise PoseError("pose contains NaN or inf")
        if abs(np.linalg.norm(q) - 1.0) > 1e-6:
            raise PoseError("pose quaternion must have unit norm")
        if np.any(s < 0) or np.any(s > MAX_OPENING):
            raise PoseError(f"openings must be in [0, {MAX_OPENING}] m, got {tuple(s)}")

    @classmethod
    def from_matrix(cls, T: np.ndarray, openings=(0.04, 0.04)) -> GripperPose:
        """From a 4x4 homogeneous palm pose."""
        T = np.asarray(T, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise PoseError("pose matrix must be a finite 4x4")
        R = T[:3, :3]
        # MuJoCo would turn any 3x3 block into some quaternion: a zero or scaled block is refused here.
        if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOL or np.linalg.det(R) < 0:
            raise PoseError("the pose's 3x3 block is not a rotation (orthonormal, det +1)")
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, R.ravel())
        return cls(tuple(T[:3, 3]), tuple(q), tuple(openings))

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous palm pose [m]."""
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, np.asarray(self.quat, dtype=float))
        T = np.eye(4)
        T[:3, :3] = R.reshape(3, 3)
        T[:3, 3] = self.position
        return T


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
