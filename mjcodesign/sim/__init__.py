"""Grasp simulators behind one protocol (:class:`Simulator`), and what they hand to observers.

MuJoCo C (:class:`MujocoBackend`) and MuJoCo Warp (:class:`MjwarpBackend`) run grasps; the Warp FEM
lives in :mod:`mjcodesign.sim.fem` (its adapter, ``FemBackend``, is what ``get_backend("fem")`` returns).
"""

from mjcodesign.sim.batch import SceneBatchSimulator
from mjcodesign.sim.mjwarp import MjwarpBackend
from mjcodesign.sim.mujoco_c import (
    MujocoBackend,
    initial_state,
    scene_with_design,
    scene_with_model,
    with_stiffness,
)
from mjcodesign.sim.observe import (
    ENTRY_POINT_GROUP,
    Capture,
    Observer,
    Rollout,
    Snapshot,
    load_observer,
    observer_class,
)
from mjcodesign.sim.protocol import BACKENDS, Simulator, get_backend

__all__ = [
    "BACKENDS",
    "SceneBatchSimulator",
    "Simulator",
    "get_backend",
    "MujocoBackend",
    "MjwarpBackend",
    "initial_state",
    "scene_with_design",
    "scene_with_model",
    "with_stiffness",
    "ENTRY_POINT_GROUP",
    "Capture",
    "Observer",
    "Rollout",
    "Snapshot",
    "load_observer",
    "observer_class",
]
