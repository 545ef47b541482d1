"""Rerun visualisation of grasp rollouts and crosscheck shapes (needs ``rerun-sdk``).

The core never imports this package: it finds :class:`RerunRecorder` through the ``mjcodesign.observers``
entry point ``rerun`` (:func:`mjcodesign.sim.observe.load_observer`).
"""

from mjcodesign.viz.colormap import stiffness_rgb
from mjcodesign.viz.recorder import DEFAULT_FRAME_RATE, TIMELINE, RerunRecorder, logged_steps

__all__ = ["RerunRecorder", "DEFAULT_FRAME_RATE", "TIMELINE", "logged_steps", "stiffness_rgb"]
