"""The motion bounds every grasp rollout is checked against, beside the energy bound.

The energy bound (:mod:`mjcodesign.scenarios.energy`) credits the disturbance impulse with the work
``F·v̄ dt`` it did, and an impulse ``J`` can give a body of mass ``m`` up to ``J²/2m``: 1.6 kJ for the
paper's 0.0179 N s on a 1 mm cube (0.1 mg). So a rollout the impulse drives 4.8 km/s into the ground
(34 m deep in one 2 ms step; MuJoCo's soft contact then pushes it back out 17 m above the palm) keeps
the energy bound, and its outcome (``no_finger_contact``) would read as an ordinary failure. What is
wrong with it is its motion, which no grasp can produce and a fixed-step simulator cannot resolve:

- **speed**: the object moves farther than its smallest size in one step, so a contact can be
  stepped over (MuJoCo detects contacts at step positions only);
- **sinking**: the object's centre of mass, which lies inside its hull, goes below the ground plane
  (z = 0), so more than half of it passed through the ground;
- **rising**: the object rises more than the lift plus its own largest size (the fingers carry it at
  most the lift; squeezing can push it up within them by less than its size).

Such a rollout is :attr:`~mjcodesign.scenarios.outcome.Failure.IMPLAUSIBLE`, never a sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MotionBound", "motion_bound"]


@dataclass(frozen=True)
class MotionBound:
    """The motion bounds of one rollout; ``reason`` is empty when every bound holds.

    ``max_speed``: the object's largest COM speed over the steps [m/s], at step ``speed_step``;
    ``lowest_z`` and ``rise``: its lowest COM height and its largest rise above the start over the
    steps read [m].
    """

    max_speed: float
    speed_step: int
    lowest_z: float
    rise: float
    reason: str = ""

    @property
    def plausible(self) -> bool:
        """Whether every bound holds."""
        return not self.reason


def motion_bound(
    speeds: np.ndarray,
    heights: np.ndarray,
    z0: float,
    *,
    dt: float,
    extents: np.ndarray,
    lift: float,
) -> MotionBound:
    """Check the object's motion (see the module docstring).

    ``speeds`` (nstep,): the object's COM speed after each step [m/s]; ``heights`` (k,): its COM
    height at the steps read [m]; ``z0`` its height at the start [m]; ``dt`` the step [s];
    ``extents`` (3,) the object's size [m]; ``lift`` the palm's lift [m].
    """
    speeds = np.asarray(speeds, dtype=float)
    heights = np.asarray(heights, dtype=float)
    t = int(np.argmax(speeds)) if speeds.size else 0
    vmax = float(speeds[t]) if speeds.size else 0.0
    lowest = float(min(heights.min(initial=z0), z0))
    rise = float(heights.max(initial=z0) - z0)
    thin, size = float(np.min(extents)), float(np.max(extents))
    reasons = []
    if vmax * dt > thin:
        reasons.append(
            f"implausible: the object moved at {vmax:.3g} m/s at t = {(t + 1) * dt:.3f} s, more than its "
            f"smallest size ({1e3 * thin:.3g} mm) per {1e3 * dt:.3g} ms step"
        )
    if lowest < 0.0:
        reasons.append(
            f"implausible: the object's centre of mass sank {1e3 * -lowest:.3g} mm below the ground"
        )
    if rise > lift + size:
        reasons.append(
            f"implausible: the object rose {1e3 * rise:.4g} mm, more than the lift ({1e3 * lift:.3g} mm) "
            f"and its size ({1e3 * size:.3g} mm)"
        )
    return MotionBound(vmax, t, lowest, rise, "; ".join(reasons))
