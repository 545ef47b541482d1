"""Grasp simulators behind one interface: build a scene, roll out one or a batch, read outcomes.

* :class:`MujocoBackend` (MuJoCo C): single rollouts step by step with a warning check after every
  step, and batches through ``mujoco.rollout`` on all cores.
* :class:`MjwarpBackend` (MuJoCo Warp): the designs of a batch are worlds; chain only. Imports
  ``mujoco_warp`` and ``warp`` lazily, when it is constructed.
"""

from mjcodesign.sim.mjwarp import MjwarpBackend
from mjcodesign.sim.mujoco_c import GraspBackend, MujocoBackend, with_stiffness

__all__ = ["GraspBackend", "MujocoBackend", "MjwarpBackend", "with_stiffness", "get_backend"]


def get_backend(name: str, **kwargs) -> GraspBackend:
    """A backend by name: ``mujoco`` or ``mjwarp`` (on the CPU unless ``device`` is given)."""
    from mjcodesign.errors import DesignError

    if name == "mujoco":
        return MujocoBackend(**kwargs)
    if name == "mjwarp":
        return MjwarpBackend(**kwargs)
    raise DesignError(f"unknown backend {name!r}; choose mujoco or mjwarp")
