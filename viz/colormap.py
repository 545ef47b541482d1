"""Stiffness colours (paper: green = stiff, red = soft) and their legend."""

from __future__ import annotations

import numpy as np

from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN

__all__ = ["NEUTRAL_RGB", "stiffness_rgb", "legend_markdown", "legend_ticks"]

NEUTRAL_RGB = np.array([120, 120, 128], dtype=np.uint8)
"""Colour of everything that has no stiffness (palm, carriages)."""
# Red (soft, ln E = 13.5) -> yellow (mid) -> green (stiff, ln E = 17.0), linear in ln E.
_STOPS = np.array([[215, 40, 30], [235, 200, 40], [40, 170, 60]], dtype=float)
_N_TICKS = 8  # colour-bar swatches from LOG_E_MIN to LOG_E_MAX


def stiffness_rgb(log_e) -> np.ndarray:
    """RGB colours (uint8) of ln(E / Pa) values, shape (..., 3); values outside the range are clipped."""
    s = np.clip((np.asarray(log_e, dtype=float) - LOG_E_MIN) / (LOG_E_MAX - LOG_E_MIN), 0.0, 1.0)
    x = s * (len(_STOPS) - 1)
    i = np.minimum(x.astype(int), len(_STOPS) - 2)
    f = (x - i)[..., None]
    return np.round((1.0 - f) * _STOPS[i] + f * _STOPS[i + 1]).astype(np.uint8)


def legend_ticks() -> np.ndarray:
    """ln(E / Pa) of the colour-bar swatches, shape (_N_TICKS,)."""
    return np.linspace(LOG_E_MIN, LOG_E_MAX, _N_TICKS)


def legend_markdown(designs: dict[str, np.ndarray]) -> str:
    """The colour scale and every design's ln E per block (finger rows, base to tip), as Markdown."""
    lines = [
        "## Block colour = stiffness",
        "",
        f"ln(E/Pa), linear: **red** {LOG_E_MIN} ({np.exp(LOG_E_MIN) / 1e6:.2f} MPa, soft) → **yellow** "
        f"{0.5 * (LOG_E_MIN + LOG_E_MAX):.2f} → **green** {LOG_E_MAX} ({np.exp(LOG_E_MAX) / 1e6:.1f} MPa, "
        "stiff). Grey: rigid parts (palm, carriages). Each design is listed under the first run that used it.",
        "",
    ]
    for name, log_e in designs.items():
        rows = np.atleast_2d(log_e)
        lines += [f"### {name}", "", "| finger | " + " | ".join(str(j) for j in range(rows.shape[1])) + " |"]
        lines.append("|---" * (rows.shape[1] + 1) + "|")
        for letter, row in zip("AB", rows, strict=False):
            lines.append(f"| {letter} | " + " | ".join(f"{v:.2f}" for v in row) + " |")
        lines.append("")
    return "\n".join(lines)
