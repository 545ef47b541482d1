"""Rows of a cross-simulator comparison and the metrics shown beside each rest shape.

A row (a plain dict, as ``--json`` prints it): ``scenario``, ``model``, ``design``, ``metric``,
``value``, ``reference`` (None where the scenario has none) and ``rel_diff``, ``|value − reference| /
|reference|`` (None without a non-zero reference).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SCENARIOS", "MODELS", "TOL_CROSS", "BEAM_METRICS", "row", "curl_metrics", "pick"]

SCENARIOS = ("cantilever", "curl", "press")
"""The comparisons :func:`mjcodesign.crosscheck.crosscheck` runs."""
MODELS = ("chain", "flex", "flex-quadratic", "fem")
"""The finger models it compares: the MuJoCo models and the Warp FEM."""
TOL_CROSS = 0.10
"""Cross-simulator tolerance (curl and press against the FEM); rows above it are flagged."""
BEAM_METRICS = ("force_n", "tip_deflection_m", "analytic_m")
"""What a cantilever shape shows: tip load [N], tip deflection [m], Euler–Bernoulli's [m]."""


def _rel(value: float, reference: float | None) -> float | None:
    if reference is None or reference == 0:
        return None
    return float(abs(value - reference) / abs(reference))


def row(scenario: str, model: str, design: str, metric: str, value: float, reference: float | None) -> dict:
    """One comparison row (see the module docstring)."""
    return {
        "scenario": scenario,
        "model": model,
        "design": design,
        "metric": metric,
        "value": float(value),
        "reference": None if reference is None else float(reference),
        "rel_diff": _rel(value, reference),
    }


def curl_metrics(tension_n: float, bend_angle_rad: float, tip_displacement_m) -> dict[str, float]:
    """What a curl shape shows: tension [N], bend [rad] and the tip displacement's length [m]."""
    return {
        "tension_n": float(tension_n),
        "bend_angle_rad": float(bend_angle_rad),
        "tip_displacement_m": float(np.linalg.norm(tip_displacement_m)),
    }


def pick(result: dict, keys) -> dict[str, float]:
    """``keys`` of a result dict as floats (the metrics of a shape)."""
    return {k: float(result[k]) for k in keys}
