"""The Warp FEM behind the simulator interface: what ``get_backend("fem")`` returns.

The FEM models one finger with its base clamped; it has no two-finger gripper and no free object, so
the three grasp methods of :class:`~mjcodesign.sim.protocol.Simulator` raise
:class:`~mjcodesign.errors.UnsupportedError`. The scenarios it does run are typed methods: the
cantilever, the free curl, the press onto a plate, and the single-finger grasp against a static box.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NoReturn

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import UnsupportedError
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.grasp import grasp_scene
from mjcodesign.sim.fem.options import FemDynamics, FemOptions
from mjcodesign.sim.fem.press import press_fem
from mjcodesign.sim.fem.results import FemCantilever, FemContactRun, FemCurl, FemPress

__all__ = ["FemBackend"]

_NO_GRASP = (
    "the Warp FEM has no two-finger grasp with a free object yet; it runs the cantilever, curl and "
    "press scenarios and a single-finger grasp against a static box (mjcodesign.sim.fem.FemBackend)"
)


def _refuse(self, *args, **kwargs) -> NoReturn:
    """Refuse a grasp rollout (``run``, ``run_batch``, ``run_poses``): raises UnsupportedError."""
    raise UnsupportedError(_NO_GRASP)


class FemBackend:
    """The Warp FEM as a simulator: one finger (A of the stiffness), linear or quadratic tets.

    ``options`` set the mesh and material (default :class:`~mjcodesign.sim.fem.options.FemOptions`);
    ``dynamics`` the explicit dynamics of :meth:`grasp` (default the paper's). The press and the grasp
    use linear tets whatever ``options.order`` says (contact acts at vertices; explicit dynamics needs
    them).
    """

    name = "fem"
    """Short name, as in JSON output."""

    def __init__(self, options: FemOptions | None = None, *, dynamics: FemDynamics | None = None):
        self.options = options or FemOptions()
        self.dynamics = dynamics or FemDynamics()

    run = run_batch = run_poses = _refuse
    """The grasp methods of :class:`~mjcodesign.sim.protocol.Simulator`: each raises
    :class:`~mjcodesign.errors.UnsupportedError` (one line naming the scenarios the FEM does run)."""

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
