"""The Warp FEM behind the simulator interface: what ``get_backend("fem")`` returns.

The three grasp methods of :class:`~mjcodesign.sim.protocol.Simulator` run the paper's grasp in the
FEM (`mjcodesign.sim.fem.gripper_grasp.FemGrasp`: two FEM fingers on the driven palm, the free object,
the ground), reading the design, pose and object from the MuJoCo scene and returning the same
`Outcome`. The single-finger scenarios are typed methods: the cantilever, the free curl, the press
onto a plate, and the single-finger grasp against a static box.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import replace

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import UnsupportedError
from mjcodesign.scenarios.grasp import GraspScenario, GraspScene, scene_at_pose
from mjcodesign.scenarios.outcome import Outcome
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.grasp import grasp_scene
from mjcodesign.sim.fem.grasp_outcome import FemGraspRun
from mjcodesign.sim.fem.gripper import FemGripper
from mjcodesign.sim.fem.gripper_grasp import GRASP_OPTIONS, FemGrasp
from mjcodesign.sim.fem.options import FemDynamics, FemOptions
from mjcodesign.sim.fem.press import press_fem
from mjcodesign.sim.fem.results import FemCantilever, FemContactRun, FemCurl, FemPress

__all__ = ["FemBackend"]

_NO_OBSERVER = (
    "the FEM grasp has no MuJoCo states for an observer to replay; record a grasp with a MuJoCo backend"
)


class FemBackend:
    """The Warp FEM as a simulator: one finger (A of the stiffness), linear or quadratic tets.

    ``options`` set the mesh and material of the single-finger scenarios (default
    :class:`~mjcodesign.sim.fem.options.FemOptions`), ``grasp_options`` the two-finger grasp's mesh
    (default `GRASP_OPTIONS`, linear tets); ``dynamics`` the explicit dynamics of both grasps (default
    the paper's). The press and the single-finger grasp use linear tets whatever ``options.order`` says
    (contact acts at vertices; explicit dynamics needs them).
    """

    name = "fem"
    """Short name, as in JSON output."""

    def __init__(
        self,
        options: FemOptions | None = None,
        *,
        dynamics: FemDynamics | None = None,
        grasp_options: FemOptions | None = None,
    ):
        self.options = options or FemOptions()
        self.dynamics = dynamics or FemDynamics()
        self.grasp_options = grasp_options or GRASP_OPTIONS
        self._gripper: FemGripper | None = None

    # -- the simulator protocol -------------------------------------------------------------------
    def grasp_run(self, scene: GraspScene, scenario: GraspScenario) -> FemGraspRun:
        """The FEM grasp of ``scene`` (its design, pose, start openings, object) with what it measured."""
        g = self._gripper
        d = scene.built.design
        if g is None or g.design != d:
            g = None
        sim = FemGrasp(scene, scenario, options=self.grasp_options, dynamics=self.dynamics, gripper=g)
        self._gripper = sim.gripper
        return sim.run()

    def run(
        self, scene: GraspScene, scenario: GraspScenario, *, observer=None, label: str = "grasp"
    ) -> Outcome:
        """One FEM grasp; a blow-up is a `Failure.DIVERGED` outcome. Raises UnsupportedError for an observer."""
        _check_input(scene, scenario)
        if observer is not None:
            raise UnsupportedError(_NO_OBSERVER)
        return self.grasp_run(scene, scenario).outcome

    def run_batch(self, scene, scenario, stiffnesses, *, observer=None, labels=None) -> list[Outcome]:
        """One FEM grasp per design (`Stiffness`) at the scene's pose, one after another (mesh reused)."""
        _check_input(scene, scenario)
        return [self.run(_with_stiffness(scene, s), scenario, observer=observer) for s in stiffnesses]

    def run_poses(self, scene, scenario, poses, *, observer=None, labels=None) -> list[Outcome]:
        """One FEM grasp per `GripperPose` of the scene's design (`scene_at_pose` raises PoseError)."""
        _check_input(scene, scenario)
        return [self.run(scene_at_pose(scene, p), scenario, observer=observer) for p in poses]

    # -- the scenarios the FEM runs ---------------------------------------------------------------
    def finger(self, design: FingerDesign, stiffness: Stiffness, *, linear: bool = False) -> FemFinger:
        """Finger A of ``stiffness`` meshed with this backend's options (``linear``: order 1 forced)."""
        options = replace(self.options, order=1) if linear else self.options
        return FemFinger(design, stiffness, options=options)

    def cantilever(
        self, design: FingerDesign, stiffness: Stiffness, *, force: float | None = None
    ) -> FemCantilever:
        """Tip load ``force`` [N] (default: 1% of the length of beam deflection) against Euler–Bernoulli."""
        return self.finger(design, stiffness).cantilever(force)

    def curl(
        self,
        design: FingerDesign,
        stiffness: Stiffness,
        tension: float,
        *,
        variant: str = "frictionless",
        steps: int | None = None,
    ) -> FemCurl:
        """Free tendon curl at ``tension`` [N] to equilibrium (gravity off)."""
        return self.finger(design, stiffness).curl(tension, variant, steps=steps)

    def press(
        self, design: FingerDesign, stiffness: Stiffness, tension: float, *, steps: int = 4
    ) -> FemPress:
        """The finger pressed onto the press scenario's plate at ``tension`` [N] (linear tets, static)."""
        return press_fem(self.finger(design, stiffness, linear=True), tension, steps=steps)

    def grasp(
        self,
        design: FingerDesign,
        stiffness: Stiffness,
        tension: float,
        duration: float,
        *,
        frames: int = 10,
    ) -> FemContactRun:
        """The single-finger grasp (`mjcodesign.sim.fem.grasp.grasp_scene`) rolled out for ``duration`` [s].

        The finger hangs from its clamped base and closes on a static box under ``tension`` [N]
        (ramped); linear tets, explicit dynamics with this backend's ``dynamics``.
        """
        fem = self.finger(design, stiffness, linear=True)
        return grasp_scene(fem, tension, dynamics=self.dynamics).run(duration, frames=frames)


def _check_input(scene, scenario) -> None:
    """Raise UnsupportedError (one line) unless ``scene`` is a `GraspScene` and ``scenario`` a `GraspScenario`."""
    for arg, cls in ((scene, GraspScene), (scenario, GraspScenario)):
        if not isinstance(arg, cls):
            raise UnsupportedError(f"the FEM grasp runs a {cls.__name__}, not {type(arg).__name__}")


def _with_stiffness(scene: GraspScene, stiffness: Stiffness) -> GraspScene:
    """The scene with another design: the FEM reads only ``built.stiffness`` (no model rewrite)."""
    other = copy.copy(scene)
    other.built = dataclasses.replace(scene.built, stiffness=stiffness)
    return other
