"""Builds the FEM stiffness calibration (`mjcodesign.design.calibration`) and its validation numbers.

:func:`build_calibration` meshes the FEM finger (quadratic tets, converged mesh), solves the training
designs (`Stiffness.random` seeds ``TRAIN_SEEDS``, both fingers: 16 designs), reduces the FEM onto their
displacements and sensitivities (:func:`mjcodesign.crosscheck.fem_linear.reduce`), fits the hinge axes
(:func:`fit_axis_heights`), and writes
``fem_calibration.json``. :func:`record_fem` solves designs the fit never saw and writes their FEM
outputs as JSON (``mjcodesign/bench/calibration_fem.json``): the reference the tests and the ``calibration``
benchmark compare against, so neither reruns the FEM (one solve takes 1–2 min here).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mjcodesign.crosscheck.fem_linear import LOADS, OUTPUTS, FemLinear, reduce

__all__ = [
    "TRAIN_SEEDS",
    "CONVERGED_MESH",
    "EXTREMES",
    "train_designs",
    "fit_axis_heights",
    "build_calibration",
    "record_fem",
]

TRAIN_SEEDS = tuple(range(1000, 1008))
"""`Stiffness.random` seeds of the training designs (fingers A and B of each); validation uses others."""
CONVERGED_MESH = {"h": 2e-3, "spine_layers": 8, "order": 2}
"""Quadratic tets, 2 mm cells, 8 layers through the 2 mm spine (0.25 mm; flexures and cuts as fine).
Refining the spine 4 → 6 → 8 layers moved the tip deflection of the extreme design 14,17,14,… by 2.1%
then 0.7% (a geometric series: 0.4% left), soft by 0.4% then 0.1%; 2 mm → 1.5 mm cells moved it 0.15%."""
EXTREMES = {
    "alt14_17": [14.0, 17.0] * 5 + [14.0],
    "alt17_14": [17.0, 14.0] * 5 + [17.0],
}
"""The alternating extremes: soft segments with stiff flexures, and the reverse."""


def train_designs() -> list[tuple[str, np.ndarray]]:
    """(name, finger-A ln E) of the 16 training designs."""
    from mjcodesign.design.stiffness import Stiffness

    out = []
    for seed in TRAIN_SEEDS:
        log_e = Stiffness.random(seed).log_e
        out += [(f"random:{seed}/A", log_e[0]), (f"random:{seed}/B", log_e[1])]
    return out


def fit_axis_heights(
    design, tip_faces: np.ndarray, tendon_faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Hinge axis heights [m] (n_blocks,) and their spread (std over designs) from FEM face angles.

    For each design, block i turns by Δφ_tip under the unit tip load and Δφ_ten under the unit tendon.
    A hinge of compliance c = Δφ_tip / (L − x_i) at height z turns by c (z_wp − z) cos α under the
    tendon (z_wp the waypoint above it, α the slope of the tendon span ending there), so
    ``z = z_wp − Δφ_ten / (c cos α)``; the mean over designs is kept.
    """
    blocks = design.blocks()
    mids = np.array([b.mid for b in blocks])
    wp = design.waypoints()
    path = np.vstack([design.tendon_exit() - [0.004, 0.0, 0.0], wp])  # the exit site of the builders
    span = np.diff(path, axis=0)
    cos_a = span[:, 0] / np.linalg.norm(span, axis=1)
    tip = np.diff(np.c_[np.zeros(len(tip_faces)), tip_faces], axis=1)
    ten = np.diff(np.c_[np.zeros(len(tendon_faces)), tendon_faces], axis=1)
    c = tip / (design.length - mids)
    z = wp[:, 2] - ten / (c * cos_a)
    return z.mean(axis=0), z.std(axis=0)


def _outputs_of(y: np.ndarray) -> dict:
    return {
        load: dict(zip(OUTPUTS, map(float, row), strict=True)) for load, row in zip(LOADS, y, strict=True)
    }


def build_calibration(
    out: str | Path,
    *,
    mesh: dict | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> dict:
    """Solve the training designs on the converged FEM, reduce it, fit the axes; write the JSON to ``out``.

    Returns the record written (without the matrices): mesh, timings, the training designs' outputs.
    """
    from mjcodesign.design.calibration import geometry_key
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.sim.fem import FemOptions

    mesh = dict(CONVERGED_MESH if mesh is None else mesh)
    design = FingerDesign()
    fem = FemLinear(design, FemOptions(**mesh))
    snaps, outs, names = [], [], []
    t0 = time.perf_counter()
    for name, log_e in train_designs():
        u, y, du = fem.solve(log_e, sensitivities=True)
        snaps += [u, du]
        outs.append(y)
        names.append(name)
        if on_progress:
            on_progress(f"{name}: tip {y[0][0] * 1e3:.4f} mm/N")
    rom = reduce(fem, np.concatenate(snaps, axis=1))
    faces = [OUTPUTS.index(f"face{i}") for i in range(design.n_blocks)]
    z, spread = fit_axis_heights(
        design, np.array([y[0][faces] for y in outs]), np.array([y[1][faces] for y in outs])
    )
    geometry = {k: (v if v is None else float(v)) for k, v in geometry_key(design).items()}
    record = {
        "geometry": geometry,
        "mesh": {
            **mesh,
            "poisson": 0.45,
            "nodes": fem.n_vertices,
            "free_dofs": fem.n_dof,
            "reduced_dim": int(rom["blocks"].shape[1]),
            "train": names,
            "setup_s": fem.setup_s,
            "solve_s_mean": (time.perf_counter() - t0) / len(names),
        },
        "axis_heights_m": z.tolist(),
        "axis_heights_spread_m": spread.tolist(),
        "reduced_model": {
            "outputs": list(OUTPUTS),
            "blocks_upper": [b[np.triu_indices(b.shape[0])].tolist() for b in rom["blocks"]],
            "loads": rom["loads"].tolist(),
            "rows": rom["rows"].tolist(),
        },
        "train_outputs": {n: _outputs_of(y) for n, y in zip(names, outs, strict=True)},
    }
    Path(out).write_text(json.dumps(record), encoding="utf-8")
    return {k: v for k, v in record.items() if k != "reduced_model"}


def record_fem(
    designs: dict[str, list[float]],
    out: str | Path,
    *,
    mesh: dict | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> dict:
    """Solve ``designs`` (name → finger-A ln E) on the FEM and write their outputs to ``out`` (JSON).

    Appends to an existing file: designs already there are skipped, so a long run can be resumed.
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.sim.fem import FemOptions

    mesh = dict(CONVERGED_MESH if mesh is None else mesh)
    path = Path(out)
    record = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {"mesh": mesh, "designs": {}}
    if record["mesh"] != mesh:
        raise ValueError(f"{out} holds another mesh: {record['mesh']}")
    todo = {k: v for k, v in designs.items() if k not in record["designs"]}
    if todo:
        fem = FemLinear(FingerDesign(), FemOptions(**mesh))
        for name, log_e in todo.items():
            t = time.perf_counter()
            _, y = fem.solve(np.asarray(log_e, dtype=float))
            record["designs"][name] = {
                "log_e": [float(v) for v in log_e],
                **_outputs_of(y),
                "solve_s": time.perf_counter() - t,
            }
            path.write_text(json.dumps(record, indent=1), encoding="utf-8")
            if on_progress:
                on_progress(f"{name}: tip {y[0][0] * 1e3:.4f} mm/N")
    return record
