"""The cross-simulator comparison: one scenario in every finger model, against its reference.

The cantilever's reference is Euler–Bernoulli; the curl's and the press's are the Warp FEM. The press
(`mjcodesign.scenarios.press`) reports, per routing, the contact force's distal-third share and centroid
along the finger; its FEM uses linear tets (contact acts at corner vertices).
"""

from __future__ import annotations

import re
from collections.abc import Callable

import numpy as np

from mjcodesign.crosscheck.press import press_rows
from mjcodesign.crosscheck.rows import BEAM_METRICS, MODELS, SCENARIOS, curl_metrics, pick, row
from mjcodesign.crosscheck.shapes import Shapes
from mjcodesign.crosscheck.tensions import default_tensions

__all__ = ["crosscheck", "model_curl", "parse_sweep", "summary_rows"]

_SWEEP = re.compile(r"^random:(\d+)\.\.(\d+)$")


def parse_sweep(text: str) -> list[str] | None:
    """``random:A..B`` as the design names ``random:A`` … ``random:B``; None for any other text."""
    from mjcodesign.errors import DesignError

    match = _SWEEP.match(text.strip())
    if match is None:
        return None
    a, b = int(match.group(1)), int(match.group(2))
    if b < a:
        raise DesignError(f"design sweep {text!r}: the last seed is below the first")
    return [f"random:{s}" for s in range(a, b + 1)]


def summary_rows(scenario: str, design: str, rows: list[dict]) -> list[dict]:
    """Per model (the FEM reference excluded), the worst and median ``|rel_diff|`` of ``rows``."""
    out = []
    for m in dict.fromkeys(r["model"] for r in rows):
        diffs = [r["rel_diff"] for r in rows if r["model"] == m and r["rel_diff"] is not None]
        if m == "fem" or not diffs:
            continue
        out.append(row(scenario, m, design, "summary:worst_rel_diff", max(diffs), None))
        out.append(row(scenario, m, design, "summary:median_rel_diff", float(np.median(diffs)), None))
    return out


def crosscheck(
    scenario: str,
    models: list[str],
    design_name: str,
    *,
    fem_options=None,
    tensions: list[float] | None = None,
    observer=None,
    on_note: Callable[[str], None] | None = None,
    chain=None,
) -> tuple[list[dict], dict]:
    """Run ``scenario`` in every backend of ``models``; return (rows, curves for plotting).

    ``design_name``: a preset, ``random:SEED`` or 11/22 log E (`mjcodesign.design.stiffness.Stiffness.parse`),
    or ``random:A..B``: every seed from A to B (both included), each design's rows in turn, then per
    MuJoCo model two summary rows (metric ``summary:worst_rel_diff`` and ``summary:median_rel_diff``,
    the value over every row of that model with a reference; curves are not kept).
    ``fem_options`` (`mjcodesign.sim.fem.FemOptions`) mesh the FEM; ``tensions`` [N] are the curl's (the
    press takes the first). ``observer`` (:class:`mjcodesign.sim.observe.Observer`), if given, receives
    every model's rest shape as it is computed (:class:`~mjcodesign.crosscheck.shapes.Shapes` names
    them), so recording costs no extra simulation. ``on_note`` hears one line per model that gave no rest
    state (the CLI prints them on stderr). Curves (curl only) map a model to its ``tension`` [N],
    ``bend`` [rad] and ``tip`` displacements [m]. ``chain``: the chain's `mjcodesign.models.types.SimOptions`
    (its hinges per block and tendon lever; the cantilever and the curl), None for the defaults.
    """
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError

    if scenario not in SCENARIOS:
        raise DesignError(f"unknown scenario {scenario!r}; choose from {SCENARIOS}")
    for m in models:
        if m not in MODELS:
            raise DesignError(f"unknown model {m!r}; choose from {MODELS}")
    sweep = parse_sweep(design_name)
    if sweep is not None:
        rows = []
        for name in sweep:
            rows += crosscheck(
                scenario,
                models,
                name,
                fem_options=fem_options,
                tensions=tensions,
                observer=observer,
                on_note=on_note,
                chain=chain,
            )[0]
        return rows + summary_rows(scenario, design_name, rows), {}
    stiffness = Stiffness.parse(design_name)
    shapes = Shapes(observer, stiffness)
    curves: dict[str, dict] = {}
    if scenario == "cantilever":
        rows = _cantilever_rows(models, design_name, stiffness, fem_options, shapes, chain)
    elif scenario == "press":
        rows = press_rows(models, design_name, stiffness, fem_options, tensions, shapes, on_note)
    else:
        rows, curves = _curl_rows(models, design_name, stiffness, fem_options, tensions, shapes, chain)
    shapes.flush()
    return rows, curves


def _cantilever_rows(
    models, design_name: str, stiffness, fem_options, shapes: Shapes, chain=None
) -> list[dict]:
    """Tip deflection of every model under a tip load, against the FEM when it runs.

    The FEM itself, and every model when the FEM does not run, against Euler–Bernoulli.
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.scenarios.static import validate_beam

    design = FingerDesign()
    rows = []
    fem_value = None
    for m in sorted(models, key=lambda m: m != "fem"):  # the FEM first: it is the others' reference
        label = f"cantilever/{m}"
        if m == "fem":
            from mjcodesign.sim.fem import FemFinger

            fem = FemFinger(design, stiffness, options=fem_options)
            r = fem.cantilever()
            tip = fem.mesh.tip_face_weight @ r.positions[fem.mesh.tip_face]
            load = (tip, [0.0, 0.0, r.force_n])
            metrics = {k: float(getattr(r, k)) for k in BEAM_METRICS}
            shapes.fem(label, fem, r.positions, metrics, forces=load)
            value, reference = r.tip_deflection_m, r.analytic_m
            fem_value = (r.force_n, r.tip_deflection_m)
        else:
            force = None if fem_value is None else fem_value[0]
            res = validate_beam(
                design, stiffness, m, force=force, options=chain if m == "chain" else None,
                observe=shapes.mujoco(label, tip_load=True),
            )  # fmt: skip
            shapes.set_metrics(label, pick(res, BEAM_METRICS), tip_force=[0.0, 0.0, res["force_n"]])
            value = res["tip_deflection_m"]
            reference = res["analytic_m"] if fem_value is None else fem_value[1]
        rows.append(row("cantilever", m, design_name, "tip_deflection_m", value, reference))
    order = {m: i for i, m in enumerate(models)}
    return sorted(rows, key=lambda r: order[r["model"]])


def _curl_rows(models, design_name: str, stiffness, fem_options, tensions, shapes: Shapes, chain=None):
    """Bend and tip displacement of every model at each tension, against the FEM; (rows, curves)."""
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.sim.fem import FemFinger

    design = FingerDesign()
    tensions = tensions or default_tensions(stiffness)
    fem = FemFinger(design, stiffness, options=fem_options)  # the reference, with or without "fem"
    ref = {}
    for t in tensions:
        r = fem.curl(t)
        metrics = curl_metrics(r.tension_n, r.bend_angle_rad, r.tip_displacement_m)
        shapes.fem(f"curl/fem/{t:.4g}N", fem, r.positions, metrics, group="curl/fem")
        tip_xyz = list(r.tip_displacement_m)
        ref[t] = (r.bend_angle_rad, float(np.linalg.norm(tip_xyz)), tip_xyz)
    rows, curves = [], {}
    for m in models:
        bends, tips = [], []
        for t in tensions:
            if m == "fem":
                bend, tip, tip_xyz = ref[t]
            else:
                label = f"curl/{m}/{t:.4g}N"
                r = model_curl(
                    design, stiffness, m, t, observe=shapes.mujoco(label, group=f"curl/{m}"), chain=chain,
                )  # fmt: skip
                shapes.set_metrics(
                    label, curl_metrics(r["tension_n"], r["bend_angle_rad"], r["tip_displacement_m"])
                )
                tip_xyz = r["tip_displacement_m"]
                bend, tip = r["bend_angle_rad"], float(np.linalg.norm(tip_xyz))
            bends.append(bend)
            tips.append(tip_xyz)
            rows.append(row("curl", m, design_name, f"bend_angle_rad@{t:.4g}N", bend, ref[t][0]))
            rows.append(row("curl", m, design_name, f"tip_displacement_m@{t:.4g}N", tip, ref[t][1]))
        curves[m] = {"tension": list(tensions), "bend": bends, "tip": tips}
    return rows, curves


def model_curl(design, stiffness, model: str, tension: float, *, observe=None, chain=None) -> dict:
    """Free curl of finger A of a MuJoCo model at ``tension`` [N], as the curl comparison runs it.

    Chain: its native tendon, dynamics to rest (`mjcodesign.scenarios.static.curl`) under ``chain``
    (`mjcodesign.models.types.SimOptions`, None for the defaults: the tendon lever held at the straight
    finger's, as the grasps run it). Flex: point-force tendon dynamics to rest (its native tendon rides
    on the nearest nodes).
    Flex-quadratic: its linear static solve (`mjcodesign.models.flex.linear_curl`; its dynamics runs at
    3.4 steps/s), valid for bends of a few tenths of a radian only. ``observe(built, data)`` as in
    `mjcodesign.scenarios.static.curl`.
    """
    from mjcodesign.models.builder import build_finger
    from mjcodesign.models.types import FingerModel, SimOptions, TendonMode
    from mjcodesign.scenarios.static import curl

    if FingerModel(model) is FingerModel.CHAIN:
        return curl(design, stiffness, model, tension, options=chain, observe=observe)
    if FingerModel(model) is not FingerModel.FLEX_QUADRATIC:
        return curl(design, stiffness, model, tension, tendon_mode=TendonMode.POINT_FORCE, observe=observe)
    from mjcodesign.models.flex import linear_curl, load_nodes

    opts = SimOptions(gravity=False)
    built = build_finger(design, stiffness, model, tendon_mode=TendonMode.POINT_FORCE, options=opts)
    r = linear_curl(built.model, built.fingers[0], design, tension)
    if observe is not None:
        observe(built, load_nodes(built.model, built.fingers[0], r["node_displacement"]))
    return r
