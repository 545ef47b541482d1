"""``mjcodesign crosscheck`` and ``mjcodesign bench fem``: the MuJoCo finger models against the Warp FEM.

Rows (``--json`` prints a list of them): ``scenario``, ``model``, ``design``, ``metric``, ``value``,
``reference``, ``rel_diff``. The cantilever's reference is Euler–Bernoulli; the curl's and the press's
are the FEM. The press (`mjcodesign.press`) reports, per routing, the contact force's distal-third share
and centroid along the finger; its FEM uses linear tets (contact acts at corner vertices).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

__all__ = ["add_parser", "add_bench_parser", "crosscheck", "bench_fem", "SCENARIOS"]

SCENARIOS = ("cantilever", "curl", "press")
_MODELS = ("chain", "flex", "flex-quadratic", "fem")
_CURL_TENSION_FRACTIONS = (0.25, 0.5, 1.0)
"""Curl tensions as fractions of the tension that curls the chain model by about 1 rad."""
_CURL_TENSION_SOFT = 0.08
"""Tension [N] that bends the soft (ln E = 13.5) chain finger by about 1 rad; scaled by E for others."""
_PRESS_TENSION_FRACTION = 0.5
"""Press tension as a fraction of the 1-rad curl tension: the free tip would rise ~30 mm, far past the
0.5 mm gap, so the whole finger is pressed onto the plate."""
_GRASP_MESH_H = 4e-3
"""Cell size [m] of the grasp benchmark's FEM mesh (2 spine layers, 1,431 vertices)."""
TOL_CROSS = 0.10
"""Cross-simulator tolerance of issue 4 (curl and press against the FEM); rows above it are flagged."""


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
        return float(np.sum(lever / hinge_stiffness(design, np.asarray(young, dtype=float))))

    scale = compliance(np.full(design.n_blocks, np.exp(13.5))) / compliance(stiffness.finger(0))
    return [_CURL_TENSION_SOFT * scale * f for f in _CURL_TENSION_FRACTIONS]


def press_tension(stiffness) -> float:
    """Press (and `bench fem` grasp) tension [N]: half the soft finger's 1-rad curl tension, scaled.

    Scaled by the ratio of mean ln E (paper-optimized: 0.2138 N); the free finger would curl far past
    the plate.
    """
    scale = float(np.exp(np.mean(stiffness.log_e[0]) - 13.5))
    return _PRESS_TENSION_FRACTION * _CURL_TENSION_SOFT * scale


def crosscheck(
    scenario: str,
    models: list[str],
    design_name: str,
    *,
    fem_options=None,
    tensions: list[float] | None = None,
    observer=None,
) -> tuple[list[dict], dict]:
    """Run ``scenario`` in every backend of ``models``; return (rows, curves for plotting).

    ``observer`` (:class:`mjcodesign.observe.Observer`), if given, receives every model's rest shape as
    it is computed (:class:`_Shapes` names them), so recording costs no extra simulation.
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError

    if scenario not in SCENARIOS:
        raise DesignError(f"unknown scenario {scenario!r}; choose from {SCENARIOS}")
    for m in models:
        if m not in _MODELS:
            raise DesignError(f"unknown model {m!r}; choose from {_MODELS}")
    design = FingerDesign()
    stiffness = Stiffness.parse(design_name)
    shapes = _Shapes(observer, stiffness)
    rows: list[dict] = []
    curves: dict[str, dict] = {}
    if scenario == "cantilever":
        from mjcodesign.scenarios.static import validate_beam

        for m in models:
            label = f"cantilever/{m}"
            if m == "fem":
                from mjcodesign.sim.fem.finger import FemFinger

                fem = FemFinger(design, stiffness, options=fem_options)
                r = fem.cantilever()
                tip = fem.mesh.tip_face_weight @ r["positions"][fem.mesh.tip_face]
                load = (tip, [0.0, 0.0, r["force_n"]])
                shapes.fem(label, fem, r["positions"], _beam_metrics(r), forces=load)
            else:
                r = validate_beam(design, stiffness, m, observe=shapes.mujoco(label, tip_load=True))
                shapes.set_metrics(label, _beam_metrics(r), tip_force=[0.0, 0.0, r["force_n"]])
            rows.append(
                _row(scenario, m, design_name, "tip_deflection_m", r["tip_deflection_m"], r["analytic_m"])
            )
        shapes.flush()
        return rows, curves
    if scenario == "press":
        rows = _press_rows(models, design_name, stiffness, fem_options, tensions, shapes)
        shapes.flush()
        return rows, curves

    from mjcodesign.sim.fem.finger import FemFinger

    tensions = tensions or default_tensions(stiffness)
    fem = FemFinger(design, stiffness, options=fem_options)  # the reference, with or without "fem"
    ref = {}
    for t in tensions:
        r = fem.curl(t)
        shapes.fem(f"curl/fem/{t:.4g}N", fem, r["positions"], _curl_metrics(r), group="curl/fem")
        ref[t] = (
            r["bend_angle_rad"],
            float(np.linalg.norm(r["tip_displacement_m"])),
            r["tip_displacement_m"],
        )
    for m in models:
        bends, tips = [], []
        for t in tensions:
            if m == "fem":
                bend, tip, tip_xyz = ref[t]
            else:
                label = f"curl/{m}/{t:.4g}N"
                r = _curl(design, stiffness, m, t, observe=shapes.mujoco(label, group=f"curl/{m}"))
                shapes.set_metrics(label, _curl_metrics(r))
                tip_xyz = r["tip_displacement_m"]
                bend, tip = r["bend_angle_rad"], float(np.linalg.norm(tip_xyz))
            bends.append(bend)
            tips.append(tip_xyz)
            rows.append(_row(scenario, m, design_name, f"bend_angle_rad@{t:.4g}N", bend, ref[t][0]))
            rows.append(_row(scenario, m, design_name, f"tip_displacement_m@{t:.4g}N", tip, ref[t][1]))
        curves[m] = {"tension": list(tensions), "bend": bends, "tip": tips}
    shapes.flush()
    return rows, curves


def _curl(design, stiffness, model: str, tension: float, *, observe=None) -> dict:
    """Free curl of finger A at ``tension`` [N].

    Chain and flex: point-force tendon dynamics to rest. Flex-quadratic: its linear static solve
    (`mjcodesign.flex.linear_curl`; its dynamics runs at 3.4 steps/s), valid for bends of a few tenths
    of a radian only. ``observe(built, data)`` as in `mjcodesign.validate.curl`.
    """
    from mjcodesign.models.builder import build_finger
    from mjcodesign.models.types import FingerModel, SimOptions, TendonMode
    from mjcodesign.scenarios.static import curl

    if FingerModel(model) is not FingerModel.FLEX_QUADRATIC:
        return curl(design, stiffness, model, tension, tendon_mode=TendonMode.POINT_FORCE, observe=observe)
    from mjcodesign.models.flex import linear_curl, load_nodes

    opts = SimOptions(gravity=False)
    built = build_finger(design, stiffness, model, tendon_mode=TendonMode.POINT_FORCE, options=opts)
    r = linear_curl(built.model, built.fingers[0], design, tension)
    if observe is not None:
        observe(built, load_nodes(built.model, built.fingers[0], r["node_displacement"]))
    return r


class _Shapes:
    """Hands crosscheck rest shapes to an observer as :class:`~mjcodesign.observe.Snapshot` (finger A).

    Labels: ``{scenario}/{model}``, ``curl/{model}/{tension}N`` (grouped per model: one model's curls are
    drawn over each other), ``press/{routing}/{model}``. A MuJoCo shape is kept until its metrics are
    known (:meth:`set_metrics`) and :meth:`flush` hands everything over. Does nothing without observer.
    """

    def __init__(self, observer, stiffness):
        self.observer = observer
        self.log_e = np.asarray(stiffness.log_e[0])
        self._pending: dict[str, dict] = {}

    def mujoco(self, label: str, *, group=None, tip_load=False, plate=False):
        """An ``observe(built, data)`` callback for a MuJoCo model at rest (None without observer)."""
        if self.observer is None:
            return None

        def keep(built, data, forces=None, obstacle=None) -> None:
            import mujoco

            extra: dict = {"forces": forces, "obstacle": obstacle}
            if tip_load:
                sid = mujoco.mj_name2id(built.model, mujoco.mjtObj.mjOBJ_SITE, built.fingers[0].tip_site)
                extra["forces"] = (data.site_xpos[sid][None].copy(), None)  # force set with the metrics
            if plate:
                from mjcodesign.scenarios.press import plate_box, plate_contacts

                pts, f, _ = plate_contacts(built.model, data)
                extra["forces"] = (pts, f)
                extra["obstacle"] = plate_box(built.model, data)
            d = mujoco.MjData(built.model)  # the caller may go on using its data
            mujoco.mj_copyData(d, built.model, data)
            self._pending[label] = dict(label=label, group=group, built=built, data=d, **extra)

        return keep

    def set_metrics(self, label: str, metrics: dict, *, tip_force=None) -> None:
        """Metrics of a kept MuJoCo shape; ``tip_force`` [N] (3,): the load at its tip point."""
        kept = self._pending.get(label)
        if kept is None:
            return
        kept["metrics"] = metrics
        if tip_force is not None:
            kept["forces"] = (kept["forces"][0], np.asarray(tip_force, dtype=float)[None])

    def fem(self, label: str, fem, x: np.ndarray, metrics: dict, *, group=None, forces=None, obstacle=None):
        if self.observer is None:
            return
        self._pending[label] = dict(
            label=label,
            group=group,
            metrics=metrics,
            positions=x,
            tets=fem.mesh.tets,
            tet_block=fem.mesh.tet_block,
            tendon=fem.mesh.waypoint_weights @ x,
            forces=None if forces is None else tuple(np.atleast_2d(np.asarray(v, float)) for v in forces),
            obstacle=obstacle,
        )

    def flush(self) -> None:
        from mjcodesign.sim.observe import Snapshot

        for kw in self._pending.values():
            self.observer.snapshot(Snapshot(log_e=self.log_e, **kw))
        self._pending.clear()


def _curl_metrics(r: dict) -> dict[str, float]:
    return {
        "tension_n": float(r["tension_n"]),
        "bend_angle_rad": float(r["bend_angle_rad"]),
        "tip_displacement_m": float(np.linalg.norm(r["tip_displacement_m"])),
    }


def _keep_rest(rest: dict, x: np.ndarray, f: np.ndarray) -> None:
    rest.update(x=x, f=f)


def _press_metrics(r: dict) -> dict[str, float]:
    from mjcodesign.scenarios.press import PRESS_METRICS

    return {k: float(r[k]) for k in PRESS_METRICS}


def _beam_metrics(r: dict) -> dict[str, float]:
    return {k: float(r[k]) for k in ("force_n", "tip_deflection_m", "analytic_m")}


def _press_rows(models, design_name, stiffness, fem_options, tensions, shapes) -> list[dict]:
    """Press rows per routing and model; the FEM (linear tets) is the reference."""
    from dataclasses import replace
    from functools import partial

    from mjcodesign.design.finger import FingerDesign, Routing
    from mjcodesign.errors import SimulationDiverged
    from mjcodesign.models.types import FingerModel
    from mjcodesign.scenarios.press import PRESS_METRICS, plate_pose, press_fem, press_linear, press_mujoco
    from mjcodesign.sim.fem.finger import FemFinger, FemOptions

    tension = tensions[0] if tensions else press_tension(stiffness)
    fem_options = replace(fem_options or FemOptions(), order=1)
    rows = []
    for routing in Routing:
        design = FingerDesign(routing=routing)
        res = {}
        if "fem" in models:
            fem = FemFinger(design, stiffness, options=fem_options)
            rest: dict = {}
            res["fem"] = press_fem(fem, tension, observe=partial(_keep_rest, rest))
            on = np.linalg.norm(rest["f"], axis=1) > 0
            shapes.fem(
                f"press/{routing.value}/fem",
                fem,
                rest["x"],
                _press_metrics(res["fem"]),
                forces=(rest["x"][on], rest["f"][on]),
                obstacle=plate_pose(design),
            )
        for m in models:
            if m != "fem":
                label = f"press/{routing.value}/{m}"
                try:
                    if FingerModel(m) is FingerModel.FLEX_QUADRATIC:  # its dynamics: 3.4 steps/s
                        res[m] = press_linear(design, stiffness, m, tension, observe=shapes.mujoco(label))
                    else:
                        res[m] = press_mujoco(
                            design, stiffness, m, tension, observe=shapes.mujoco(label, plate=True)
                        )
                    shapes.set_metrics(label, _press_metrics(res[m]))
                except SimulationDiverged as exc:
                    print(f"note: {m} press ({routing.value}) gave no rest state: {exc}", file=sys.stderr)
        for m in res:
            for metric in PRESS_METRICS:
                ref = res["fem"][metric] if "fem" in res else None
                name = f"{metric}[{routing.value}]@{tension:.4g}N"
                rows.append(_row("press", m, design_name, name, res[m][metric], ref))
    return rows


def plot_curves(curves: dict, path: str) -> None:
    """Curl trajectories per model (PNG, Agg backend).

    Left: the tip path in the bending plane as the tension rises; right: the bend against the tension.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mjcodesign.errors import DesignError, OutputError

    if not curves:
        raise DesignError("--plot needs the curl scenario (no trajectories to plot)")
    fig, (ax_tip, ax_bend) = plt.subplots(1, 2, figsize=(9, 4))
    for name, c in curves.items():
        tip = 1e3 * np.array([[0.0, 0.0, 0.0]] + [list(v) for v in c["tip"]])
        ax_tip.plot(tip[:, 0], tip[:, 2], "o-", label=name)
        ax_bend.plot(c["tension"], np.degrees(c["bend"]), "o-", label=name)
    ax_tip.set_xlabel("tip Δx [mm]")
    ax_tip.set_ylabel("tip Δz [mm]")
    ax_tip.set_title("tip path, tension rising from 0")
    ax_tip.set_aspect("equal", adjustable="datalim")
    ax_bend.set_xlabel("tendon tension [N]")
    ax_bend.set_ylabel("total bend [deg]")
    ax_bend.legend()
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=120)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc}") from exc
    finally:
        plt.close(fig)


def bench_fem(
    *, h: float = 3e-3, spine_layers: int = 4, dyn_steps: int = 2000, grasp_horizon: float = 0.2
) -> dict:
    """FEM speed on this machine: explicit steps/s, a static curl and its gradient, a dynamic grasp.

    Times [s] of one static curl solve plus its gradient, and of the forward and forward-plus-gradient
    of a dynamic grasp of ``grasp_horizon`` [s].

    The explicit step of ``steps_per_s`` is the smaller of the paper's 2.5 µs and the mesh's CFL estimate.
    The grasp (`mjcodesign.fem_grasp.grasp_scene`) runs the paper's 2.5 µs on a 4 mm mesh without
    waypoint layers, with selective mass scaling; its loss is the time-averaged normal force on the box
    and the gradient is with respect to the 22 ln E (checkpointed ``wp.Tape``).
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.sim.fem.finger import FemDynamics, FemFinger, FemOptions

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
    x = fem.solve_static(load, steps=2)
    t1 = time.perf_counter()
    g = np.zeros((fem.mesh.n_vertices, 3))
    g[fem.mesh.tip, 2] = 1.0
    fem.static_gradient(x, load, g)
    t2 = time.perf_counter()
    grasp = _bench_grasp(design, grasp_horizon)
    return {
        "device": fem.options.device,
        "n_tets": fem.mesh.n_tets,
        "n_vertices": fem.mesh.n_vertices,
        "dt_s": dyn.dt,
        "steps_per_s": steps_per_s,
        "grasp_0.2s_forward_s_estimate": 0.2 / dyn.dt / steps_per_s,
        "static_curl_s": t1 - t0,
        "static_gradient_s": t2 - t1,
        **grasp,
    }


def _bench_grasp(design, horizon: float) -> dict:
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.sim.fem.finger import FemFinger, FemOptions
    from mjcodesign.sim.fem.grasp import grasp_scene

    stiffness = Stiffness.preset("paper-optimized")
    fem = FemFinger(
        design, stiffness, options=FemOptions(h=_GRASP_MESH_H, spine_layers=2, waypoint_layers=False)
    )
    tension = press_tension(stiffness)
    sim = grasp_scene(fem, tension)
    sim.run(10 * sim.dyn.dt, frames=1)  # compile and warm up
    t0 = time.perf_counter()
    fwd = sim.run(horizon, frames=1)
    t1 = time.perf_counter()
    value, grad = sim.mean_force_gradient(horizon)
    t2 = time.perf_counter()
    return {
        "grasp_horizon_s": horizon,
        "grasp_dt_s": sim.dyn.dt,
        "substeps": fwd["steps"],
        "grasp_n_vertices": fem.mesh.n_vertices,
        "grasp_added_mass_fraction": sim.added_mass_fraction,
        "grasp_tension_n": tension,
        "grasp_mean_force_n": value,
        "grasp_max_penetration_m": fwd["max_penetration"],
        "grasp_forward_s": t1 - t0,
        "grasp_forward_backward_s": t2 - t1,
        "grasp_gradient_norm": float(np.linalg.norm(grad)),
    }


def _fem_options(args):
    from mjcodesign.sim.fem.finger import FemOptions

    return FemOptions(h=args.fem_h, spine_layers=args.fem_layers, order=args.fem_order)


def _cmd_crosscheck(args) -> int:
    from mjcodesign.cli import viz as cli_viz
    from mjcodesign.cli.main import _emit

    tensions = [float(v) for v in args.tensions.split(",")] if args.tensions else None
    rec = cli_viz.open_recorder(args)
    try:
        rows, curves = crosscheck(
            args.scenario,
            args.models.split(","),
            args.design,
            fem_options=_fem_options(args),
            tensions=tensions,
            observer=rec,
        )
    finally:
        if rec is not None:
            rec.close()
    if args.plot:
        plot_curves(curves, args.plot)
    _emit(rows, args.json)
    for r in rows:
        if r["model"] != "fem" and r["rel_diff"] is not None and r["rel_diff"] > TOL_CROSS:
            print(
                f"note: {r['model']} misses the FEM by {r['rel_diff']:.0%} (> {TOL_CROSS:.0%}) on {r['metric']}",
                file=sys.stderr,
            )
    return 0


def _cmd_bench_fem(args) -> int:
    if args.fem_order != 1:
        from mjcodesign.errors import DesignError

        raise DesignError("bench fem times explicit dynamics, which needs --fem-order 1")
    res = bench_fem(
        h=args.fem_h, spine_layers=args.fem_layers, dyn_steps=args.steps, grasp_horizon=args.grasp_horizon
    )
    if args.out:
        from pathlib import Path

        Path(args.out).write_text(json.dumps(res))
    if args.json:
        print(json.dumps(res))
    else:
        from mjcodesign.cli.main import _emit

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
    p.add_argument(
        "--design", default="paper-optimized", help="preset name, random:SEED or 11/22 comma-separated log E"
    )
    p.add_argument("--tensions", default=None, help="curl tensions [N], comma-separated (press: the first)")
    p.add_argument("--plot", default=None, help="curl: write tip paths and bend against tension to this PNG")
    # Quadratic tets, 2 spine layers: within 4% of Euler–Bernoulli on the cantilever (mjcodesign.fem).
    _fem_flags(p, h=4e-3, layers=2, order=2)
    from mjcodesign.cli.viz import add_recording_flags

    add_recording_flags(p, decimation=False)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_crosscheck)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``bench fem`` on the ``bench`` sub-parsers."""
    p = bench_subparsers.add_parser(
        "fem", help="Warp FEM steps/s on the CPU and static solve + gradient time"
    )
    _fem_flags(p, h=3e-3, layers=4, order=1)
    p.add_argument("--steps", type=int, default=2000, help="explicit substeps to time")
    p.add_argument("--grasp-horizon", type=float, default=0.2, help="dynamic grasp to time [s]")
    p.add_argument("--out", default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_fem)
