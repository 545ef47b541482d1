"""Buckling tension of the printed chain with each flexure's n hinges tied to one angle, from MuJoCo's forces.

    python3 scripts/tied_flexure_hinges.py [--log-e 15.0] [--hinges 2,3,4,8]

The printed chain with n free hinges per flexure (``SimOptions(routing="printed", hinges_per_block=n)``)
buckles close to the converged FEM but folds into an S past buckling, so grippers refuse it. Tying a
flexure's hinges to one angle (MuJoCo joint equalities, ``tied_flexures=True``, the printed routing's
default with two hinges) forbids the S. This computes the tied chain's buckling tension from the free
chain alone, the closed form the built ties are checked against (tests/test_tied_flexures.py): the
chain's tangent stiffness K(T) = K₀ + T H
(:func:`mjcodesign.models.stability.tangent_stiffness`, MuJoCo's own spring and tendon forces)
projected on the tied coordinates (one angle per block, a flexure's split equally over its hinges),
C^T K(T) C, and the smallest T that makes it singular; beside it the free chain's
(:func:`~mjcodesign.models.stability.buckling_tension`). Uniform fingers: both scale with E exactly.
"""

from __future__ import annotations

import argparse

import numpy as np


def tied_buckling_tension(built, counts: np.ndarray) -> float:
    """Smallest tension [N] at which ``built``'s tangent stiffness, restricted to tied hinges, turns singular.

    ``counts``: hinges per block in joint order (a block's hinges consecutive).
    """
    from mjcodesign.models.stability import tangent_stiffness

    nv = built.model.nv
    if int(np.sum(counts)) != nv:
        raise ValueError(f"{int(np.sum(counts))} hinges in counts, the finger has {nv}")
    C = np.zeros((nv, len(counts)))
    start = 0
    for i, n in enumerate(counts):
        C[start : start + n, i] = 1.0 / n
        start += n
    K0 = tangent_stiffness(built, 0.0)
    H = tangent_stiffness(built, 1.0) - K0
    Li = np.linalg.inv(np.linalg.cholesky(C.T @ K0 @ C))
    mu = np.linalg.eigvalsh(-Li @ (C.T @ H @ C) @ Li.T)
    return float("inf") if mu[-1] <= 0 else float(1.0 / mu[-1])


def main() -> None:
    """Print the free and tied chains' buckling tension for each hinge count."""
    from mjcodesign.design.finger import BlockKind, FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models import build_finger
    from mjcodesign.models.stability import buckling_tension
    from mjcodesign.models.types import FingerModel, SimOptions

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log-e", type=float, default=15.0, help="ln E of every block (uniform finger)")
    ap.add_argument("--hinges", default="2,3,4,8", help="hinges per flexure, comma-separated")
    a = ap.parse_args()
    design = FingerDesign()
    flexure = np.array([b.kind is BlockKind.FLEXURE for b in design.blocks()])
    for n in (int(v) for v in a.hinges.split(",")):
        opts = SimOptions(routing="printed", gravity=False, hinges_per_block=n)
        built = build_finger(design, Stiffness([a.log_e] * design.n_blocks), FingerModel.CHAIN, options=opts)
        free = buckling_tension(built)[0]
        tied = tied_buckling_tension(built, np.where(flexure, n, 1))
        print(f"{n} hinges per flexure, ln E {a.log_e}: free {free:.3f} N, tied {tied:.3f} N")


if __name__ == "__main__":
    main()
