"""The tendon tensions of the cross-simulator comparisons, scaled per design so every finger bends alike."""

from __future__ import annotations

import numpy as np

__all__ = ["default_tensions", "press_tension"]

_CURL_TENSION_FRACTIONS = (0.25, 0.5, 1.0)
"""Curl tensions as fractions of the tension that curls the chain model by about 1 rad."""
_CURL_TENSION_SOFT = 0.08
"""Tension [N] that bends the soft (ln E = 13.5) chain finger by about 1 rad; scaled by E for others."""
_PRESS_TENSION_FRACTION = 0.5
"""Press tension as a fraction of the 1-rad curl tension: the free tip would rise ~30 mm, far past the
0.5 mm gap, so the whole finger is pressed onto the plate."""


def default_tensions(stiffness) -> list[float]:
    """Curl tensions [N] for finger A: the soft finger's, scaled by its linear tendon compliance.

    The compliance S = Σ h_i / k_i (tendon lever h_i over block i's hinge stiffness k_i, the chain's
    small-bend curl per newton) of the soft finger over this one's: every design then bends about as
    far as the soft finger at its tensions (~0.25, 0.5 and 1 rad for the chain). For a uniform design
    this is the ratio of moduli. (Scaling by the mean ln E instead sent random:0 to 1.1–2.4 rad, where
    a quadratic FEM curl takes minutes to an hour.)
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.models.chain import hinge_stiffness

    design = FingerDesign()
    lever = design.waypoint_heights()

    def compliance(young) -> float:
        return float(np.sum(lever / hinge_stiffness(design, np.asarray(young, dtype=float), "beam")))

    scale = compliance(np.full(design.n_blocks, np.exp(13.5))) / compliance(stiffness.finger(0))
    return [_CURL_TENSION_SOFT * scale * f for f in _CURL_TENSION_FRACTIONS]


def press_tension(stiffness) -> float:
    """Press (and `bench fem` grasp) tension [N]: half the soft finger's 1-rad curl tension, scaled.

    Scaled by the ratio of mean ln E (paper-optimized: 0.2138 N); the free finger would curl far past
    the plate.
    """
    scale = float(np.exp(np.mean(stiffness.log_e[0]) - 13.5))
    return _PRESS_TENSION_FRACTION * _CURL_TENSION_SOFT * scale
