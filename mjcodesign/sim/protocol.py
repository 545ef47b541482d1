"""The one interface every grasp simulator implements, and how to pick one by name.

* :class:`~mjcodesign.sim.mujoco_c.MujocoBackend` (MuJoCo C): single rollouts step by step with a
  warning check, batches through ``mujoco.rollout`` on all cores.
* :class:`~mjcodesign.sim.mjwarp.MjwarpBackend` (MuJoCo Warp): the designs or poses of a batch are
  worlds; chain only. Imports ``mujoco_warp`` and ``warp`` when it is constructed.
* :class:`~mjcodesign.sim.fem.backend.FemBackend` (Warp FEM): an adapter for the scenarios the FEM
  supports; it raises :class:`~mjcodesign.errors.UnsupportedError` for the rest.

A simulator never raises for a rollout that goes wrong: a divergence is an outcome with
:attr:`~mjcodesign.scenarios.outcome.Failure.DIVERGED` and its reason.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.models.types import GripperPose
from mjcodesign.scenarios.grasp import GraspScenario, GraspScene
from mjcodesign.scenarios.outcome import Outcome
from mjcodesign.sim.observe import Observer

__all__ = ["BACKENDS", "Simulator", "get_backend"]

BACKENDS = ("mujoco", "mjwarp", "fem")
"""Names accepted by :func:`get_backend`."""


@runtime_checkable
class Simulator(Protocol):
    """What every grasp simulator offers: one rollout, a batch of designs, a batch of poses."""

    name: str
    """Short name (``mujoco``, ``mjwarp``, ``fem``), as in JSON output."""

    def run(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
        label: str = "grasp",
    ) -> Outcome:
        """One rollout of ``scenario`` in ``scene`` (its model as compiled, or as rewritten for a design).

        ``observer`` receives the whole rollout (:class:`~mjcodesign.sim.observe.Rollout`) as ``label``.
        """
        ...

    def run_batch(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        stiffnesses: list[Stiffness],
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """One rollout per design on the scene's object and pose, in the order of ``stiffnesses``."""
        ...

    def run_poses(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        poses: list[GripperPose],
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """One rollout per pose of the scene's design, in the order of ``poses``."""
        ...


def get_backend(name: str, **kwargs) -> Simulator:
    """A simulator by name (:data:`BACKENDS`); ``kwargs`` go to its constructor.

    ``mjwarp`` and ``fem`` import Warp when they are constructed, not before.
    """
    if name == "mujoco":
        from mjcodesign.sim.mujoco_c import MujocoBackend

        return MujocoBackend(**kwargs)
    if name == "mjwarp":
        from mjcodesign.sim.mjwarp import MjwarpBackend

        return MjwarpBackend(**kwargs)
    if name == "fem":
        from mjcodesign.sim.fem.backend import FemBackend

        return FemBackend(**kwargs)
    raise DesignError(f"unknown backend {name!r}; choose from {', '.join(BACKENDS)}")
