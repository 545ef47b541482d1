"""The finger's stiffness calibrated to the converged Warp FEM over the whole design space.

Beam theory is exact for uniform fingers but misses by up to 2.4x where neighbouring blocks differ
(docs/benchmarks.md, calibration): a stiff flexure between soft segments rotates at its roots, and a
soft flexure between stiff segments bends as a plate (E / (1 − ν²), 20% stiffer). The FEM's small-
deflection stiffness is affine in the 11 block moduli, ``K(E) = Σ_b E_b K_b``, so a Galerkin reduced
model of it (``fem_calibration.json``, built by `mjcodesign.crosscheck.calibration` from quadratic-tet
solves on a converged mesh) gives any design's response in ~0.1 ms:

* :func:`block_compliance`: each block's rotation per unit bending moment under a tip load [rad/(N·m)],
  the chain's hinge compliance;
* :data:`CalibratedFem.axis_heights`: where each block effectively bends, the height of its hinge axis
  above the spine's underside [m]. Fitted once (the mean over the training designs; they vary by
  ±0.03 mm): a segment bends at its flexure roots, 1.4 mm up, not about its mid-height (3–7 mm), so a
  tendon pulls it with a much longer lever than beam theory's section centroid says.

Both hold for the default finger geometry only (any routing); :func:`calibration_for` raises for
another geometry.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import DesignError

__all__ = [
    "CALIBRATION_FILE",
    "CalibratedFem",
    "calibration_for",
    "block_compliance",
    "geometry_key",
    "moment_arms",
]

CALIBRATION_FILE = Path(__file__).with_name("fem_calibration.json")
"""The reduced FEM and the fitted hinge axes (JSON; written by `mjcodesign.crosscheck.calibration`)."""
_FREE_FIELDS = ("routing", "tendon_height", "uniform_height", "density")
"""Design fields that move the tendon or set the mass only: the stiffness calibration holds whatever
they are."""


def geometry_key(design: FingerDesign) -> dict:
    """The fields of ``design`` that set its blocks and material (not its tendon routing)."""
    return {f.name: getattr(design, f.name) for f in fields(design) if f.name not in _FREE_FIELDS}


@dataclass(frozen=True, eq=False)
class CalibratedFem:
    """A Galerkin reduced model of the FEM finger's small-deflection statics and the fitted hinge axes.

    ``blocks`` (n_blocks, r, r): Vᵀ K_b V [N/m per Pa]; ``loads`` (r, 2): Vᵀ f of the unit tip load and
    the unit tendon; ``rows`` (n_out, r): the outputs ``outputs`` (names) as functionals of the reduced
    displacement.
    """

    geometry: dict
    blocks: np.ndarray
    loads: np.ndarray
    rows: np.ndarray
    outputs: tuple[str, ...]
    axis_heights: np.ndarray
    """Hinge axis height of every block above the spine's underside [m], shape (n_blocks,)."""
    mesh: dict
    """How the FEM was meshed (h, spine layers, order, nodes) and what it was reduced on."""

    def solve(self, young: np.ndarray) -> np.ndarray:
        """Outputs [m or rad per N] of the unit tip load and the unit tendon, shape (2, n_out)."""
        young = np.asarray(young, dtype=float)
        if young.shape != (self.blocks.shape[0],) or not np.all(np.isfinite(young)) or np.any(young <= 0):
            raise DesignError(f"need {self.blocks.shape[0]} positive moduli, got {young!r}")
        # Cholesky (LAPACK potrf/potrs, as scipy's cho_factor/cho_solve call them, without their
        # wrappers' ~0.1 ms): the reduced stiffness is symmetric positive definite. numpy's LU solve
        # went multi-threaded at this size and took 2-19 ms on the loaded 2-core machine.
        potrf, potrs, flat = self._lapack
        k = np.dot(young[None], flat).reshape(self.blocks.shape[1:])  # = tensordot(young, blocks, 1)
        c, info = potrf(k, lower=0, overwrite_a=1, clean=0)
        if info == 0:
            x, info = potrs(c, self.loads, lower=0)
        if info != 0:
            raise DesignError(f"the reduced FEM stiffness is not positive definite for E = {young!r}")
        return (self.rows @ x).T

    def output(self, young: np.ndarray, load: str, name: str) -> float:
        """One output of one load (``tip`` or ``tendon``), e.g. ``tip_face_z``."""
        y = self.solve(young)
        return float(y[("tip", "tendon").index(load), self.outputs.index(name)])

    def face_angles(self, young: np.ndarray) -> np.ndarray:
        """Section rotation at every block's distal face under the unit tip load [rad/N], (n_blocks,)."""
        return self.solve(young)[0][self._faces]

    @functools.cached_property
    def _lapack(self) -> tuple:
        from scipy.linalg import get_lapack_funcs  # lazily: importing this package stays numpy-only

        potrf, potrs = get_lapack_funcs(("potrf", "potrs"), (self.blocks, self.loads))
        return potrf, potrs, self.blocks.reshape(self.blocks.shape[0], -1)

    @functools.cached_property
    def _faces(self) -> np.ndarray:
        return np.array([self.outputs.index(f"face{i}") for i in range(self.blocks.shape[0])])


@functools.lru_cache(maxsize=1)
def _load(path: str) -> CalibratedFem:
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DesignError(f"cannot read the FEM calibration {path}: {exc}") from exc
    rom = raw["reduced_model"]
    r = len(rom["loads"])
    upper = np.triu_indices(r)
    blocks = np.zeros((len(rom["blocks_upper"]), r, r))
    for b, values in zip(blocks, rom["blocks_upper"], strict=True):  # symmetric: the upper triangles
        b[upper] = values
        b.T[upper] = values
    return CalibratedFem(
        geometry=raw["geometry"],
        blocks=blocks,
        loads=np.array(rom["loads"], dtype=float),
        rows=np.array(rom["rows"], dtype=float),
        outputs=tuple(rom["outputs"]),
        axis_heights=np.array(raw["axis_heights_m"], dtype=float),
        mesh=raw["mesh"],
    )


def calibration_for(design: FingerDesign, path: str | Path = CALIBRATION_FILE) -> CalibratedFem:
    """The FEM calibration of ``design``'s geometry; :class:`DesignError` if it was made for another."""
    return _calibration_for(design, str(path))


@functools.lru_cache(maxsize=32)
def _calibration_for(design: FingerDesign, path: str) -> CalibratedFem:
    cal = _load(path)
    key = geometry_key(design)
    if set(key) != set(cal.geometry) or not all(_same(key[k], cal.geometry[k]) for k in key):
        raise DesignError(
            "the FEM stiffness calibration covers the default finger geometry only; use "
            "SimOptions(stiffness_model='beam') for another geometry"
        )
    return cal


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.isclose(float(a), float(b), rtol=1e-12, atol=0.0))


@functools.lru_cache(maxsize=32)
def moment_arms(design: FingerDesign) -> np.ndarray:
    """L − x_i at every block's middle [m]: a unit tip load's moment there."""
    return design.length - np.array([b.mid for b in design.blocks()])


def block_compliance(design: FingerDesign, young: np.ndarray) -> np.ndarray:
    """Each block's rotation per unit bending moment [rad/(N·m)] from the calibrated FEM, (n_blocks,).

    Under a unit tip load, block i's rotation (face to face) over the moment at its middle,
    ``c_i = Δφ_i / (L − x_i)``: the chain's hinge i then turns as the FEM's block does, and with the
    fitted hinge axes its tendon curl follows too (linear tip deflection and curl within 0.6% of the
    FEM on the alternating extreme designs).
    """
    phi = calibration_for(design).face_angles(np.asarray(young, dtype=float))
    c = np.diff(np.r_[0.0, phi]) / moment_arms(design)
    if not np.all(c > 0):
        raise DesignError(f"the reduced FEM gave a non-positive block compliance for E = {young!r}")
    return c
