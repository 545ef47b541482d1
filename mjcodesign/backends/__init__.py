"""Grasp simulators behind one interface: build a scene, roll out one or a batch, read outcomes.

* :class:`MujocoBackend` (MuJoCo C): single rollouts step by step with a warning check after every
  step, and batches through ``mujoco.rollout`` on all cores.
"""

from mjcodesign.backends.mujoco_c import GraspBackend, MujocoBackend, with_stiffness

__all__ = ["GraspBackend", "MujocoBackend", "with_stiffness", "get_backend"]


def get_backend(name: str, **kwargs) -> GraspBackend:
    """A backend by name: ``mujoco``."""
    from mjcodesign.errors import DesignError

    if name == "mujoco":
        return MujocoBackend(**kwargs)
    if name == "mjwarp":
        raise DesignError("the mjwarp grasp backend is not implemented yet; use --backend mujoco")
    raise DesignError(f"unknown backend {name!r}; choose mujoco or mjwarp")
