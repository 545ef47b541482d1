"""Per-block Young's modulus of the two fingers, as log E [ln Pa]."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.errors import StiffnessError

__all__ = [
    "DESIGN_FILE_SUFFIXES",
    "LOG_E_MIN",
    "LOG_E_MAX",
    "N_LOG_E",
    "PRESETS",
    "Stiffness",
    "read_design_file",
    "write_design_file",
]

LOG_E_MIN = 13.5
"""Softest printable block, ln(E / Pa): about 0.73 MPa (TPU 95A at low infill)."""
LOG_E_MAX = 17.0
"""Stiffest printable block, ln(E / Pa): about 24 MPa (solid TPU 95A)."""

_BLOCKS_PER_FINGER = 11
_N_FINGERS = 2
N_LOG_E = _N_FINGERS * _BLOCKS_PER_FINGER
"""ln E values per design: finger A's 11 blocks base to tip, then finger B's (a dataset row, the
surrogate's input, the co-design's variables)."""

# The paper's jointly optimised design, base to tip, segment (flexure) alternating (the paper's table).
_PAPER_OPT_A = [16.05, 15.16, 14.62, 14.89, 15.31, 14.62, 15.85, 14.65, 15.23, 15.34, 15.22]
_PAPER_OPT_B = [15.54, 14.53, 14.27, 14.81, 15.00, 15.97, 14.54, 15.14, 14.95, 15.31, 15.47]

PRESETS: dict[str, np.ndarray] = {
    "soft": np.full(_N_FINGERS * _BLOCKS_PER_FINGER, 13.5),
    "semi-rigid": np.full(_N_FINGERS * _BLOCKS_PER_FINGER, 16.5),
    "paper-optimized": np.array(_PAPER_OPT_A + _PAPER_OPT_B),
}
"""Named designs, each 22 values of ln(E / Pa): finger A base to tip, then finger B."""
_RANDOM = "random:"
"""Prefix of a seeded random design in `Stiffness.parse`."""
DESIGN_FILE_SUFFIXES = (".json", ".txt", ".csv")
"""A design file (:func:`read_design_file`): JSON with ``design``, or comma-separated ln E as text."""
_DESIGN_KEY = "design"


@dataclass(frozen=True)
class Stiffness:
    """ln(E / Pa) of every block of both fingers, shape (n_fingers, n_blocks).

    Build it from 2·n values (finger A base to tip, then finger B), or n values for two equal fingers.
    """

    log_e: np.ndarray

    def __init__(self, values, n_blocks: int = _BLOCKS_PER_FINGER):
        try:
            arr = np.asarray(values, dtype=float).ravel()
        except (TypeError, ValueError) as exc:
            raise StiffnessError(f"stiffness values are not numbers: {values!r}") from exc
        if arr.size == n_blocks:
            arr = np.tile(arr, _N_FINGERS)
        if arr.size != _N_FINGERS * n_blocks:
            raise StiffnessError(
                f"stiffness needs {n_blocks} or {_N_FINGERS * n_blocks} values of log E, got {arr.size}"
            )
        if not np.all(np.isfinite(arr)):
            raise StiffnessError("stiffness contains NaN or inf")
        bad = (arr < LOG_E_MIN - 1e-9) | (arr > LOG_E_MAX + 1e-9)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise StiffnessError(
                f"log E[{i}] = {arr[i]:g} is outside the printable range [{LOG_E_MIN}, {LOG_E_MAX}]"
            )
        arr = arr.reshape(_N_FINGERS, n_blocks)
        arr.setflags(write=False)
        object.__setattr__(self, "log_e", arr)

    @classmethod
    def preset(cls, name: str, n_blocks: int = _BLOCKS_PER_FINGER) -> Stiffness:
        """A named preset (``soft``, ``semi-rigid``, ``paper-optimized``)."""
        if name not in PRESETS:
            raise StiffnessError(f"unknown stiffness preset {name!r}; choose from {sorted(PRESETS)}")
        values = PRESETS[name]
        if n_blocks != _BLOCKS_PER_FINGER:
            if name == "paper-optimized":
                raise StiffnessError("the paper-optimized preset is defined for 11 blocks only")
            values = np.full(n_blocks, values[0])
        return cls(values, n_blocks=n_blocks)

    @classmethod
    def random(cls, seed: int, n_blocks: int = _BLOCKS_PER_FINGER) -> Stiffness:
        """A random design: 2·n log E uniform in the printable range, from ``np.random.default_rng(seed)``."""
        rng = np.random.default_rng(seed)
        return cls(rng.uniform(LOG_E_MIN, LOG_E_MAX, _N_FINGERS * n_blocks), n_blocks=n_blocks)

    @classmethod
    def parse(cls, text: str, n_blocks: int = _BLOCKS_PER_FINGER) -> Stiffness:
        """Parse a preset, ``random:SEED`` (`Stiffness.random`), comma-separated log E or a design file.

        A design file is a path ending in one of :data:`DESIGN_FILE_SUFFIXES` (:func:`read_design_file`).
        """
        text = text.strip()
        if Path(text).suffix.lower() in DESIGN_FILE_SUFFIXES:
            return read_design_file(text, n_blocks)
        if text.startswith(_RANDOM):
            seed = text[len(_RANDOM) :]
            if not seed.isdigit():
                raise StiffnessError(f"random design needs a non-negative integer seed, got {text!r}")
            return cls.random(int(seed), n_blocks)
        if "," not in text and not _is_number(text):
            return cls.preset(text, n_blocks)
        fields = text.split(",")
        if not all(v.strip() for v in fields):
            raise StiffnessError(
                f"stiffness {text!r} has an empty field (field {[v.strip() for v in fields].index('') + 1})"
            )
        try:
            values = [float(v) for v in fields]
        except ValueError as exc:
            raise StiffnessError(f"cannot parse stiffness {text!r}") from exc
        return cls(values, n_blocks=n_blocks)

    @property
    def young(self) -> np.ndarray:
        """Young's modulus [Pa], shape (n_fingers, n_blocks)."""
        return np.exp(self.log_e)

    @property
    def n_blocks(self) -> int:
        """Blocks per finger."""
        return self.log_e.shape[1]

    def finger(self, i: int) -> np.ndarray:
        """Young's modulus [Pa] of finger ``i``'s blocks, base to tip, shape (n_blocks,)."""
        return self.young[i]

    def as_list(self) -> list[float]:
        """Flat list of the 2·n log E values (finger A then B)."""
        return [float(v) for v in self.log_e.ravel()]

    def __eq__(self, other) -> bool:
        return isinstance(other, Stiffness) and np.array_equal(self.log_e, other.log_e)

    def __hash__(self) -> int:
        return hash(self.log_e.tobytes())


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_design_file(path: str | Path, n_blocks: int = _BLOCKS_PER_FINGER) -> Stiffness:
    """The design in a design file; :class:`StiffnessError` for a missing or malformed one.

    JSON holding ``design`` (2·n or n ln(E/Pa)) or a bare JSON list, or text with the values comma- or
    newline-separated (``mjcodesign optimize`` writes ``design.txt``).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StiffnessError(
            f"cannot read design file {p}: {getattr(exc, 'strerror', None) or exc}"
        ) from None
    try:
        raw = json.loads(text)
    except ValueError:
        try:
            raw = [float(v) for v in text.replace("\n", ",").split(",") if v.strip()]
        except ValueError:
            raise StiffnessError(
                f"{p}: not a design file (JSON with {_DESIGN_KEY!r}, or ln E values)"
            ) from None
    if isinstance(raw, dict) and _DESIGN_KEY in raw:
        raw = raw[_DESIGN_KEY]
    if not isinstance(raw, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in raw
    ):
        raise StiffnessError(f"{p}: a design file holds {_DESIGN_KEY!r}: a list of ln(E/Pa) values")
    try:
        return Stiffness(raw, n_blocks=n_blocks)
    except StiffnessError as exc:
        raise StiffnessError(f"{p}: {exc}") from None


def write_design_file(path: str | Path, design: Stiffness, **meta) -> Path:
    """Write ``design`` as JSON (``design``: 22 ln(E/Pa), plus ``meta``), read by :func:`read_design_file`."""
    p = Path(path)
    p.write_text(json.dumps({_DESIGN_KEY: design.as_list(), **meta}, indent=1) + "\n", encoding="utf-8")
    return p
