"""The base of the simulators that roll out a batch of scenes at once (MuJoCo C, MuJoCo Warp)."""

from __future__ import annotations

import abc

from mjcodesign.models.types import GripperPose
from mjcodesign.scenarios.grasp import GraspScenario, GraspScene, scene_at_pose
from mjcodesign.scenarios.outcome import Outcome
from mjcodesign.sim.observe import Observer

__all__ = ["SceneBatchSimulator"]


class SceneBatchSimulator(abc.ABC):
    """Base of the simulators that roll out a batch of scenes of one model structure at once.

    A subclass (MuJoCo C, MuJoCo Warp) implements :meth:`run_scenes`; a batch of poses is that batch
    over the scene moved to each pose.
    """

    @abc.abstractmethod
    def run_scenes(
        self,
        scenes: list[GraspScene],
        scenario: GraspScenario,
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """One rollout per scene, in order; ``observer`` receives each as ``labels[i]``."""

    def run_poses(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        poses: list[GripperPose],
        *,
        observer: Observer | None = None,
        labels: list[str] | None = None,
    ) -> list[Outcome]:
        """The scene's design at every pose, batched by :meth:`run_scenes`.

        A pose moves the mount and palm in a copy of the model and sets the initial openings and the
        controls (:func:`mjcodesign.scenarios.grasp.scene_at_pose`, which raises :class:`PoseError` for a
        bad pose). ``observer`` receives every rollout, labelled ``labels[i]`` (default ``pose{i}``).
        """
        labels = labels or [f"pose{i}" for i in range(len(poses))]
        scenes = [scene_at_pose(scene, p) for p in poses]
        return self.run_scenes(scenes, scenario, observer=observer, labels=labels)
