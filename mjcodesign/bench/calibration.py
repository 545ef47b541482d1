"""The stiffness calibration checked against FEM numbers it was not fitted to.

For every design recorded in ``calibration_fem.json`` (package data beside this module: converged
quadratic-tet solves of designs outside the training set: the alternating extremes, the presets and
random seeds; written by
:func:`mjcodesign.crosscheck.calibration.record_fem`), each MuJoCo model's cantilever (tip load giving
δ = 1% of L, as ``validate beam``) against the FEM's, and beam theory's for comparison. Curl rows come
from ``curl`` entries of the same file (nonlinear FEM curls) when present. Also times the calibration
itself per design (the reduced FEM solve), which data generation pays for every sampled design.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from mjcodesign.design.beam import cantilever_tip_deflection
from mjcodesign.design.calibration import block_compliance
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, Stiffness
from mjcodesign.errors import DesignError, MjcodesignError, OutputError
from mjcodesign.scenarios.static import AUTO_DEFLECTION, validate_beam

__all__ = ["bench_calibration", "REFERENCE", "CONVERGED", "TOL_CANTILEVER", "TOL_CURL"]

REFERENCE = Path(__file__).resolve().parent / "calibration_fem.json"
"""The recorded FEM numbers on the shipped reduced model's mesh (package data, with its provenance)."""
CONVERGED = Path(__file__).resolve().parent / "calibration_fem_converged.json"
"""The recorded FEM numbers on the converged mesh (8 spine layers)."""
TOL_CANTILEVER = 0.05
"""The target: a model within 5% of the converged FEM on the cantilever, every design."""
TOL_CURL = 0.10
"""The target: within 10% on curl bend and tip up to about 1.3 rad."""
_TIMING_DESIGNS = 1000


def bench_calibration(
    *,
    references: tuple[str | Path, ...] = (REFERENCE, CONVERGED),
    models: tuple[str, ...] = ("chain", "flex", "flex-quadratic"),
    designs: tuple[str, ...] | None = None,
    on_progress=None,
) -> dict:
    """Cantilever (and recorded curl) rows of every model against each recorded FEM file, and a summary.

    ``designs``: names to take from the files (default all of each). Returns ``rows`` (design, model,
    metric, value, reference, rel_diff, fem_mesh), ``summary`` (per FEM mesh, model and metric: worst
    and median |rel_diff|, the worst design, how many designs miss the tolerance) and
    ``calibration_s_per_design`` (CPU seconds of one finger's calibration). Raises
    :class:`DesignError` for an unknown model and :class:`OutputError` for a reference file that does
    not read, before any work.
    """
    unknown = [m for m in models if m not in _MODELS]
    if unknown:
        raise DesignError(f"unknown model(s) {unknown}: choose from {', '.join(_MODELS)}")
    design = FingerDesign()
    refs = [(path, _read_reference(path)) for path in references]  # every file checked before any work
    rows, meshes = [], {}
    for path, ref in refs:
        mesh = f"h {1e3 * ref['mesh']['h']:g} mm, {ref['mesh']['spine_layers']} spine layers"
        meshes[mesh] = {"file": str(path), **ref["mesh"], "designs": len(ref["designs"])}
        names = [n for n in ref["designs"] if designs is None or n in designs]
        for name in names:
            for r in _design_rows(design, name, ref["designs"][name], models):
                rows.append({**r, "fem_mesh": mesh})
            if on_progress:
                on_progress(f"{mesh}: {name}")
    if designs is not None and not rows:
        raise DesignError(f"none of {designs} is in the reference files")
    return {
        "references": meshes,
        "rows": rows,
        "summary": {m: _summary([r for r in rows if r["fem_mesh"] == m]) for m in meshes},
        "calibration_s_per_design": _time_calibration(design),
    }


_MODELS = ("chain", "flex", "flex-quadratic")  # the MuJoCo finger models ``validate_beam`` builds


def _read_reference(path: str | Path) -> dict:
    """A recorded FEM file; :class:`OutputError` for one that is missing, unreadable or of another shape."""
    try:
        ref = json.loads(Path(path).read_text(encoding="utf-8"))
        mesh, designs = ref["mesh"], ref["designs"]
        float(mesh["h"]), int(mesh["spine_layers"])
        for rec in designs.values():
            Stiffness(rec["log_e"]), float(rec["tip"]["tip_face_z"])
    except OSError as exc:
        raise OutputError(f"--reference {path}: cannot read it ({exc.strerror or exc})") from None
    except (ValueError, KeyError, TypeError, AttributeError, MjcodesignError) as exc:
        raise OutputError(
            f"--reference {path}: not a recorded FEM file ({type(exc).__name__}: {str(exc)[:120]})"
        ) from None
    return ref


def _design_rows(design: FingerDesign, name: str, rec: dict, models) -> list[dict]:
    stiffness = Stiffness(rec["log_e"])
    young = stiffness.finger(0)
    fem = rec["tip"]["tip_face_z"]  # [m/N]: linear, so any small load
    force = AUTO_DEFLECTION * design.length / fem
    rows = [_row(name, "beam", "cantilever", cantilever_tip_deflection(design, young, 1.0), fem)]
    for model in models:
        r = validate_beam(design, stiffness, model, force=force)
        rows.append(_row(name, model, "cantilever", r["tip_deflection_m"] / force, fem))
    for curl in rec.get("curl", []):
        rows += _curl_rows(name, design, stiffness, curl, models)
    return rows


def _row(design: str, model: str, metric: str, value: float, reference: float) -> dict:
    return {
        "design": design,
        "model": model,
        "metric": metric,
        "value": float(value),
        "reference": float(reference),
        "rel_diff": float(abs(value - reference) / abs(reference)),
    }


def _curl_rows(name, design, stiffness, curl: dict, models) -> list[dict]:
    from mjcodesign.crosscheck.run import model_curl

    rows = []
    for model in models:
        if model == "flex-quadratic":  # its curl is a linear solve: not valid at large bends
            continue
        r = model_curl(design, stiffness, model, curl["tension_n"])
        tag = f"@{curl['tension_n']:.4g}N"
        rows.append(_row(name, model, "curl_bend" + tag, r["bend_angle_rad"], curl["bend_angle_rad"]))
        tip = float(np.linalg.norm(r["tip_displacement_m"]))
        rows.append(
            _row(name, model, "curl_tip" + tag, tip, float(np.linalg.norm(curl["tip_displacement_m"])))
        )
    return rows


def _summary(rows: list[dict]) -> dict:
    out: dict = {}
    for r in rows:
        kind = r["metric"].split("@")[0]
        out.setdefault(r["model"], {}).setdefault(kind, []).append(r)
    tol = {"cantilever": TOL_CANTILEVER}
    return {
        model: {
            kind: {
                "worst": max(x["rel_diff"] for x in rs),
                "median": float(np.median([x["rel_diff"] for x in rs])),
                "worst_design": max(rs, key=lambda x: x["rel_diff"])["design"],
                "misses": sum(x["rel_diff"] > tol.get(kind, TOL_CURL) for x in rs),
                "n": len(rs),
            }
            for kind, rs in kinds.items()
        }
        for model, kinds in out.items()
    }


def _time_calibration(design: FingerDesign) -> float:
    """CPU seconds of :func:`block_compliance` (one finger's calibration) per design, random designs."""
    rng = np.random.default_rng(0)
    young = np.exp(rng.uniform(LOG_E_MIN, LOG_E_MAX, (_TIMING_DESIGNS, design.n_blocks)))
    block_compliance(design, young[0])  # load the file
    t0 = time.process_time()
    for e in young:
        block_compliance(design, e)
    return (time.process_time() - t0) / _TIMING_DESIGNS
