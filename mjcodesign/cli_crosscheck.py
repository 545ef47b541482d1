"""``mjcodesign crosscheck`` and ``mjcodesign bench fem``: the MuJoCo finger models against the Warp FEM.

Rows (``--json`` prints a list of them): ``scenario``, ``model``, ``design``, ``metric``, ``value``,
``reference``, ``rel_diff``. The cantilever's reference is Euler–Bernoulli; the curl's is the FEM.
The ``press`` scenario of issue 4 is not implemented and is not offered.
"""

from __future__ import annotations

import json
import time

import numpy as np

__all__ = ["add_parser", "add_bench_parser", "crosscheck", "bench_fem", "SCENARIOS"]

SCENARIOS = ("cantilever", "curl")
_MODELS = ("chain", "flex", "flex-quadratic", "fem")
_CURL_TENSION_FRACTIONS = (0.25, 0.5, 1.0)
"""Curl tensions as fractions of the tension that curls the chain model by about 1 rad."""
_CURL_TENSION_SOFT = 0.08
"""Tension [N] that bends the soft (ln E = 13.5) chain finger by about 1 rad; scaled by E for others."""


def _rel(value: float, reference: float | None) -> float | None:
    if reference is None or reference == 0:
        return None
    return float(abs(value - reference) / abs(reference))


def _row(scenario, model, design, metric, value, reference) -> dict:
    return {
        "scenario": scenario,
        "model": model,
        "design": design,
        "metric": metric,
        "value": float(value),
        "reference": None if reference is None else float(reference),
        "rel_diff": _rel(value, reference),
    }


def default_tensions(stiffness) -> list[float]:
    """Curl tensions [N] for finger A: soft-finger tensions scaled by its mean E (same curl range)."""
    scale = float(np.exp(np.mean(stiffness.log_e[0]) - 13.5))
    return [_CURL_TENSION_SOFT * scale * f for f in _CURL_TENSION_FRACTIONS]


def crosscheck(
    scenario: str,
    models: list[str],
    design_name: str,
    *,
    fem_options=None,
    tensions: list[float] | None = None,
) -> tuple[list[dict], dict]:
    """Run ``scenario`` in every backend of ``models``; return (rows, curves for plotting)."""
    from mjcodesign.errors import DesignError
    from mjcodesign.finger import FingerDesign
    from mjcodesign.stiffness import Stiffness

    if scenario not in SCENARIOS:
        raise DesignError(f"unknown scenario {scenario!r}; choose from {SCENARIOS}")
    for m in models:
        if m not in _MODELS:
            raise DesignError(f"unknown model {m!r}; choose from {_MODELS}")
    design = FingerDesign()
    stiffness = Stiffness.parse(design_name)
    rows: list[dict] = []
    curves: dict[str, dict] = {}
    if scenario == "cantilever":
        from mjcodesign.validate import validate_beam

        for m in models:
            if m == "fem":
                from mjcodesign.fem import FemFinger

                r = FemFinger(design, stiffness, options=fem_options).cantilever()
            else:
                r = validate_beam(design, stiffness, m)
            rows.append(
                _row(scenario, m, design_name, "tip_deflection_m", r["tip_deflection_m"], r["analytic_m"])
            )
        return rows, curves

    from mjcodesign.fem import FemFinger
    from mjcodesign.mjcf import TendonMode
    from mjcodesign.validate import curl

    tensions = tensions or default_tensions(stiffness)
    fem = FemFinger(design, stiffness, options=fem_options)
    ref = {}
    for t in tensions:
        r = fem.curl(t)
        ref[t] = (r["bend_angle_rad"], float(np.linalg.norm(r["tip_displacement_m"])))
    curves["fem"] = {"tension": list(tensions), "bend": [ref[t][0] for t in tensions]}
    for m in models:
        bends = []
        for t in tensions:
            if m == "fem":
                bend, tip = ref[t]
            else:
                r = curl(design, stiffness, m, t, tendon_mode=TendonMode.POINT_FORCE)
                bend, tip = r["bend_angle_rad"], float(np.linalg.norm(r["tip_displacement_m"]))
            bends.append(bend)
            rows.append(_row(scenario, m, design_name, f"bend_angle_rad@{t:.4g}N", bend, ref[t][0]))
            rows.append(_row(scenario, m, design_name, f"tip_displacement_m@{t:.4g}N", tip, ref[t][1]))
        curves[m] = {"tension": list(tensions), "bend": bends}
    return rows, curves


def plot_curves(curves: dict, path: str) -> None:
    """Bend angle against tension per model (PNG, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mjcodesign.errors import OutputError

    fig, ax = plt.subplots(figsize=(5, 4))
    for name, c in curves.items():
        ax.plot(c["tension"], np.degrees(c["bend"]), "o-", label=name)
    ax.set_xlabel("tendon tension [N]")
    ax.set_ylabel("total bend [deg]")
    ax.legend()
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=120)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc}") from exc
    finally:
        plt.close(fig)


def bench_fem(*, h: float = 3e-3, spine_layers: int = 4, dyn_steps: int = 2000) -> dict:
    """FEM speed on this machine: explicit steps/s, and one static curl solve plus its gradient [s].

    The explicit step is the smaller of the paper's 2.5 µs and the mesh's CFL estimate.
    """
    from mjcodesign.fem import FemDynamics, FemFinger, FemOptions
    from mjcodesign.finger import FingerDesign
    from mjcodesign.stiffness import Stiffness

    design = FingerDesign()
    fem = FemFinger(
        design, Stiffness.preset("paper-optimized"), options=FemOptions(h=h, spine_layers=spine_layers)
    )
    dyn = FemDynamics(dt=min(FemDynamics().dt, fem.stable_dt()))
    fem.rollout(10 * dyn.dt, dynamics=dyn, position=(0, 0, 0.05), frames=1)  # compile and warm up
    t0 = time.perf_counter()
    fem.rollout(dyn_steps * dyn.dt, dynamics=dyn, position=(0, 0, 0.05), frames=1)
    steps_per_s = dyn_steps / (time.perf_counter() - t0)
    load = fem.tendon_load(0.5)
    t0 = time.perf_counter()
    x, _ = fem.solve_static(load, steps=2)
    t1 = time.perf_counter()
    g = np.zeros((fem.mesh.n_vertices, 3))
    g[fem.mesh.tip, 2] = 1.0
    fem.static_gradient(x, load, g)
    t2 = time.perf_counter()
    return {
        "device": fem.options.device,
        "n_tets": fem.mesh.n_tets,
        "n_vertices": fem.mesh.n_vertices,
        "dt_s": dyn.dt,
        "steps_per_s": steps_per_s,
        "grasp_0.2s_forward_s_estimate": 0.2 / dyn.dt / steps_per_s,
        "static_curl_s": t1 - t0,
        "static_gradient_s": t2 - t1,
    }


def _fem_options(args):
    from mjcodesign.fem import FemOptions

    return FemOptions(h=args.fem_h, spine_layers=args.fem_layers, order=args.fem_order)


def _cmd_crosscheck(args) -> int:
    from mjcodesign import cli_viz
    from mjcodesign.cli import _emit

    tensions = [float(v) for v in args.tensions.split(",")] if args.tensions else None
    cli_viz.record_crosscheck(args, tensions)
    rows, curves = crosscheck(
        args.scenario, args.models.split(","), args.design, fem_options=_fem_options(args), tensions=tensions
    )
    if args.plot:
        plot_curves(curves, args.plot)
    _emit(rows, args.json)
    return 0


def _cmd_bench_fem(args) -> int:
    if args.fem_order != 1:
        from mjcodesign.errors import DesignError

        raise DesignError("bench fem times explicit dynamics, which needs --fem-order 1")
    res = bench_fem(h=args.fem_h, spine_layers=args.fem_layers, dyn_steps=args.steps)
    if args.out:
        from pathlib import Path

        Path(args.out).write_text(json.dumps(res))
    if args.json:
        print(json.dumps(res))
    else:
        from mjcodesign.cli import _emit

        _emit(res, False)
    return 0


def _fem_flags(p, *, h: float, layers: int, order: int) -> None:
    p.add_argument("--fem-h", type=float, default=h, help="FEM cell size in the segments [m]")
    p.add_argument("--fem-layers", type=int, default=layers, help="FEM layers through the 2 mm spine (even)")
    p.add_argument("--fem-order", type=int, choices=(1, 2), default=order, help="FEM tet order")


def add_parser(subparsers) -> None:
    """Register ``crosscheck`` on the top-level sub-parsers."""
    p = subparsers.add_parser("crosscheck", help="run one case in every backend (MuJoCo models, Warp FEM)")
    p.add_argument("--scenario", choices=SCENARIOS, required=True)
    p.add_argument("--models", default="chain,flex,fem", help=f"comma-separated, from {_MODELS}")
    p.add_argument("--design", default="paper-optimized", help="preset name or 11/22 comma-separated log E")
    p.add_argument("--tensions", default=None, help="curl tensions [N], comma-separated")
    p.add_argument("--plot", default=None, help="curl: write bend against tension per model to this PNG")
    # Quadratic tets, 2 spine layers: within 4% of Euler–Bernoulli on the cantilever (mjcodesign.fem).
    _fem_flags(p, h=4e-3, layers=2, order=2)
    p.add_argument("--rrd", default=None, help="curl: record every model's rest shape (Rerun .rrd)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_crosscheck, decimation=None)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench fem`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "fem", help="Warp FEM steps/s on the CPU and static solve + gradient time"
    )
    _fem_flags(p, h=3e-3, layers=4, order=1)
    p.add_argument("--steps", type=int, default=2000, help="explicit substeps to time")
    p.add_argument("--out", default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_fem)
