"""``mjcodesign design``: from objects to a verified, printable gripper in one run.

:func:`~mjcodesign.pipeline.run_design` checks the output folder, loads the surrogate and every object (an unknown object
or an unreadable mesh is refused before any long work), then:

1. samples each object's grasp candidates (:func:`~mjcodesign.evaluation.object_candidates`) and
   their partial clouds;
2. co-designs the 22 block stiffnesses and a pose per object through the surrogate (Algorithm 1,
   :func:`~mjcodesign.codesign.optimize`), jointly or one design per object;
   With ``adapt`` (``--adapt N``), first fine-tunes the surrogate on N simulated grasps of each object
   at these poses (:func:`~mjcodesign.pipeline.adapt.adapt_surrogate`) and co-designs through it;
3. verifies by re-simulation: the optimised design and the soft, semi-rigid and paper-optimized
   presets, each at the pose the surrogate picks for it, under the evaluation's perturbation model
   (:func:`~mjcodesign.evaluation.run_suite`) at every disturbance of :data:`SWEEP_IMPULSES`; per
   object and design the success probability with its Wilson interval;
4. writes into the folder (staged: a failure leaves nothing): ``design.txt`` (or
   ``designs/OBJECT.txt``), ``poses/OBJECT.json``, the adapted network under ``surrogate/`` (``--adapt``), the print files under ``print/``
   (:func:`~mjcodesign.fabrication.write_print_files`), ``report.md``, ``report.html``, their figures
   under ``figures/``, ``result.json`` and, with a recorder, ``run.rrd``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mjcodesign.codesign import Mode, OptimizeConfig, PoseSet, optimize
from mjcodesign.codesign.report import design_text, write_design, write_json, write_pose
from mjcodesign.codesign.run import dataset_masses
from mjcodesign.codesign.verify import pick_poses, predicted_success
from mjcodesign.design.stiffness import PRESETS, Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.evaluation import (
    DesignGroup,
    PerturbationModel,
    Suite,
    SuiteObject,
    SuiteRun,
    object_candidates,
    run_suite,
    wilson,
)
from mjcodesign.evaluation.candidates import CLOUD_POINTS
from mjcodesign.fabrication import Calibration, plan_print, write_print_files
from mjcodesign.jobs import GraspJob, load_grasp_object, run_jobs
from mjcodesign.models.types import FingerModel
from mjcodesign.objects import YCB_IN_DOMAIN, published_mass_or_none
from mjcodesign.outputs import OutputKind, check_output, staged
from mjcodesign.pipeline.adapt import adapt_surrogate, summary_line
from mjcodesign.pipeline.report import GraspImages, write_report
from mjcodesign.pipeline.specs import DEFAULT_DENSITY, ObjectSpec
from mjcodesign.scenarios import TendonForce, TendonPosition
from mjcodesign.scenarios.grasp import GraspScenario, at_paper_disturbance
from mjcodesign.sim.mujoco_c import MujocoBackend

__all__ = ["ADAPTED_DIR", "BASELINES", "OPTIMISED", "SWEEP_IMPULSES", "DesignOptions", "run_design"]

OPTIMISED = "optimised"
"""The label of the co-designed design in the report."""
BASELINES = ("soft", "semi-rigid", "paper-optimized")
"""The presets the optimised design is verified against."""
SWEEP_IMPULSES = (0.1, 0.2, 0.4)
"""Disturbances of the verification [N s, the paper's units]: its 0.1 (the table's, first), 0.2, 0.4."""
ADAPTED_DIR = "surrogate"
"""The folder of the adapted network (``--adapt``) in the output, a checkpoint folder."""
_DENSITY_LABEL = "design"  # the one regime of the verification: each object at its own density

Progress = Callable[[str, int, int], None]


@dataclasses.dataclass(frozen=True, kw_only=True)
class DesignOptions:
    """How ``mjcodesign design`` runs (its flags)."""

    mode: Mode = Mode.JOINT
    tendon: TendonForce | TendonPosition | None = None
    """The tendon drive (:func:`mjcodesign.data.parse_tendon`); None: the checkpoint dataset's."""
    poses_per_object: int = 10
    """Grasp candidates sampled per object (the co-design's pose set)."""
    budget: int = 720
    """Re-simulation rollouts of the verification (objects × designs × disturbances × draws)."""
    seed: int = 0
    max_iterations: int = 2000
    """N of Algorithm 1."""
    adapt: int = 0
    """Rollouts per object to fine-tune the surrogate on before the co-design
    (:func:`~mjcodesign.pipeline.adapt.adapt_surrogate`); 0: the checkpoint as it is."""

    def __post_init__(self) -> None:
        for name in ("poses_per_object", "budget", "max_iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise DesignError(f"{name} must be an integer >= 1, got {v!r}")
        if isinstance(self.adapt, bool) or not isinstance(self.adapt, int) or self.adapt < 0:
            raise DesignError(f"--adapt must be an integer >= 0, got {self.adapt!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise DesignError(f"seed must be an integer >= 0, got {self.seed!r}")


def _scenario(surrogate, tendon) -> tuple[GraspScenario, FingerModel]:
    """The checkpoint dataset's scenario and finger model (as the co-design's verification), ``tendon``'s drive."""
    from mjcodesign.surrogate import dataset_config

    config = dataset_config(surrogate)
    if config is None:
        scenario = GraspScenario(lift=surrogate.lift, lifted_fraction=surrogate.lifted_fraction)
        model = FingerModel.CHAIN
    else:
        scenario, model = config.scenario, config.model
    if tendon is not None:
        scenario = dataclasses.replace(scenario, tendon=tendon)
    return scenario, model


def _object_density(spec: ObjectSpec, volume: float, base: float, rule: str) -> float:
    """An object's density [kg/m³] in the checkpoint dataset's regime.

    Its given mass over its volume; else, where the dataset's rule takes published masses (``real``,
    ``auto``), its published mass; else the dataset's density ``base``.
    """
    if spec.mass_kg is not None:
        return float(spec.mass_kg) / volume
    found = published_mass_or_none(str(spec.source)) if rule in ("real", "auto") else None
    return base if found is None else found.mass / volume


def _pose_set(cands: list, volumes: list[float], names: list[str], sources: list[str]) -> PoseSet:
    """The candidates of every object as one :class:`~mjcodesign.codesign.PoseSet` (object order, candidate order)."""
    object_of = np.repeat(np.arange(len(cands)), [len(c) for c in cands])
    return PoseSet(
        tuple(names),
        object_of,
        np.concatenate([c.clouds for c in cands]).astype(np.float32),
        np.concatenate([c.com for c in cands]),
        np.concatenate([c.matrices for c in cands]),
        np.array([p.openings for c in cands for p in c.poses], dtype=float),
        np.repeat(np.asarray(volumes), [len(c) for c in cands]),
        source="sampled",
        sources=tuple(sources),
    )


def run_design(
    specs: tuple[ObjectSpec, ...],
    *,
    checkpoint: str | Path,
    out: str | Path,
    options: DesignOptions,
    overwrite: bool = False,
    cache_dir: str | Path | None = None,
    command: str = "",
    recorder: Callable[[Path], object] | None = None,
    progress: Progress | None = None,
    warn: Callable[[str], None] | None = None,
    gl: str | None = None,
) -> dict:
    """Run the whole design (module docstring) and return the JSON record (``result.json``).

    ``recorder``: makes the Rerun observer for a file path (``run.rrd`` in the folder); None writes
    none. ``progress(stage, done, total)`` follows objects and stages; ``warn`` gets one line each.
    ``gl``: the OpenGL backend of the grasp images (:class:`GraspImages`; None: MuJoCo's own choice).
    Raises the library's errors (:class:`~mjcodesign.errors.MjcodesignError`) with nothing written.
    """
    from mjcodesign.surrogate import load_surrogate

    say = progress or (lambda _s, _d, _t: None)
    tell = warn or (lambda _m: None)
    t0 = time.perf_counter()
    folder = check_output(out, OutputKind.DESIGN, overwrite=overwrite, inputs={"--ckpt": checkpoint})
    if not specs:
        raise DesignError("no object given")
    per_draw = len(specs) * (1 + len(BASELINES)) * len(SWEEP_IMPULSES)
    if options.budget < per_draw:
        raise DesignError(
            f"--budget {options.budget} is below one draw of every rollout: {len(specs)} objects × "
            f"{1 + len(BASELINES)} designs × {len(SWEEP_IMPULSES)} disturbances = {per_draw}"
        )
    surrogate = load_surrogate(checkpoint)
    n_points = int((surrogate.meta.get("dataset") or {}).get("cloud_points", CLOUD_POINTS))
    scenario, model = _scenario(surrogate, options.tendon)
    timings: dict[str, float] = {}

    # 1. objects and their candidates
    t = time.perf_counter()
    objs, rho, cands, volumes, notes = {}, {}, [], [], {}
    base_density, mass_rule = dataset_masses(surrogate, None, None)
    for i, spec in enumerate(specs):
        obj = load_grasp_object(spec.source, DEFAULT_DENSITY, seed=options.seed, cache_dir=cache_dir)
        volume = obj.mass / obj.density  # [m³]
        rho[spec.name] = _object_density(spec, volume, base_density, mass_rule)
        c = object_candidates(obj, options.poses_per_object, seed=options.seed, cache_dir=cache_dir)
        c = c.with_clouds(n_points, options.seed)
        if len(c) < options.poses_per_object:
            notes[spec.name] = (
                f"{len(c)} of {options.poses_per_object} poses: the sampler accepted no more "
                "(or a pose's box held too few surface points for its cloud)"
            )
            tell(f"{spec.name}: {notes[spec.name]}")
        objs[spec.name], volumes = obj, [*volumes, volume]
        cands.append(c)
        say("posing objects", i + 1, len(specs))
    names = [s.name for s in specs]
    poses = _pose_set(cands, volumes, names, [s.source for s in specs])
    timings["poses_s"] = time.perf_counter() - t
    adapt = None
    if options.adapt:
        t = time.perf_counter()
        surrogate, adapt = adapt_surrogate(
            surrogate, poses, objs, rho, scenario, model, options.adapt, seed=options.seed, progress=say
        )
        adapt["summary"] = summary_line(adapt)
        if not adapt["adapted"]:
            tell(adapt["reason"])
        timings["adapt_s"] = time.perf_counter() - t

    # 2. co-design through the surrogate
    t = time.perf_counter()
    cfg = OptimizeConfig(mode=options.mode, max_iterations=options.max_iterations)
    result = optimize(
        surrogate,
        poses,
        rho,
        cfg,
        on_step=lambda s: say("co-design iterations", s.iteration, cfg.max_iterations),
    )
    timings["codesign_s"] = time.perf_counter() - t
    designs = {OPTIMISED: [result.design_of(k) for k in range(len(names))]}
    rows = {OPTIMISED: np.asarray(result.chosen)}
    for b in BASELINES:
        log_e = np.asarray(PRESETS[b], dtype=float).ravel()
        designs[b] = [log_e] * len(names)
        rows[b] = pick_poses(surrogate, poses, log_e, rho)
    predicted = {  # (success, head's p) per design label
        label: predicted_success(surrogate, poses, rows[label], np.array(designs[label]), rho)[::2]
        for label in designs
    }

    # 3. verification by re-simulation
    t = time.perf_counter()
    draws = options.budget // per_draw
    verify_rows = _verify(
        specs, objs, poses, designs, rows, rho, scenario, model, draws, options, cache_dir, say, tell
    )
    timings["verify_s"] = time.perf_counter() - t
    verification = _summary(verify_rows, names, designs, rows, poses, predicted)
    verification.update(draws=draws, rollouts=len(verify_rows), budget=options.budget)

    # 4. files
    t = time.perf_counter()
    root = Path(out)
    record = {
        "objects": [
            {
                "name": s.name,
                "source": s.source,
                "mass_kg": rho[s.name] * v,
                "mass_given": s.mass_kg is not None,
                "density_kg_m3": rho[s.name],
                "domain": "in-domain" if s.source in YCB_IN_DOMAIN else "out-of-domain",
                "candidates": len(c),
                "note": notes.get(s.name, ""),
                "pose_file": str(root / "poses" / f"{s.name}.json"),
            }
            for s, v, c in zip(specs, volumes, cands, strict=True)
        ],
        "mode": options.mode.value,
        "design": design_text(result.designs[0]) if options.mode is Mode.JOINT else None,
        "designs": {n: result.design_of(k).tolist() for k, n in enumerate(names)},
        "design_file": str(root / ("design.txt" if options.mode is Mode.JOINT else "designs")),
        "codesign": {"iterations": result.iterations, "stopped": result.stopped, "phases": result.phases},
        "verification": verification,
        "simulation": {
            "model": model.value,
            "tendon": scenario.tendon.text(),
            "scenario": dataclasses.asdict(scenario),
            "perturbation": PerturbationModel().as_dict(),
        },
        "checkpoint": str(checkpoint),
        "adapt": adapt,
        "seed": options.seed,
        "poses_per_object": options.poses_per_object,
        "command": command,
    }
    with staged(folder) as tmp:
        _write_designs(tmp, result, names, poses)
        if adapt is not None and adapt["adapted"]:
            _save_adapted(tmp, root, surrogate, adapt)
        record["print"] = _write_print(tmp, root, result, names, options.mode)
        images = GraspImages(gl=gl)
        observers = [images]
        rrd = None
        if recorder is not None:
            rrd = recorder(tmp / "run.rrd")
            observers.append(rrd)
        try:
            _replay_chosen(
                specs, objs, poses, designs, rows, rho, scenario, model, options.seed, _FanOut(observers)
            )
        finally:
            if rrd is not None:
                rrd.close()
        record["rrd"] = str(root / "run.rrd") if rrd is not None else None
        timings["files_s"] = time.perf_counter() - t
        record["timings"] = timings
        record["wall_s"] = time.perf_counter() - t0
        record["files"] = write_report(tmp, root, record, images.images)
        write_json(tmp / "result.json", record)
    return record


def _verify(specs, objs, poses, designs, rows, rho, scenario, model, draws, options, cache_dir, say, tell):
    """Every verification rollout: per object and chosen pose, the designs that chose it, all draws."""
    out: list[dict] = []
    for k, spec in enumerate(specs):
        by_row: dict[int, list[str]] = {}
        for label in designs:
            by_row.setdefault(int(rows[label][k]), []).append(label)
        for row, labels in by_row.items():
            so = SuiteObject(
                name=spec.name,
                source=spec.source,
                domain="in-domain" if spec.source in YCB_IN_DOMAIN else "out-of-domain",
                fold=None,
                poses=(poses.gripper_pose(row),),
                source_index=(row - int(poses.rows(k)[0]),),
            )
            suite = Suite(name="design", objects=(so,), seed=options.seed, poses_per_object=1)
            run = SuiteRun(
                designs=tuple(DesignGroup(lb, lb, Stiffness(designs[lb][k])) for lb in labels),
                perturbations=draws,
                densities=(repr(float(rho[spec.name])),),
                impulses=SWEEP_IMPULSES,
                model=model.value,
                seed=options.seed,
                scenario=scenario,
            )
            res = run_suite(suite, run, cache_dir=cache_dir, warn=tell)
            for r in res["rows"]:
                out.append(dict(r, density=_DENSITY_LABEL, pose=so.source_index[0]))
        say("verifying objects", k + 1, len(specs))
    return out


def _head_p(p, k: int) -> dict:
    """``{"predicted_success_p": p[k]}`` from a success head's probabilities, ``{}`` without a head."""
    return {} if p is None else {"predicted_success_p": float(p[k])}


def _summary(rows: list[dict], names, designs, chosen, poses: PoseSet, predicted) -> dict:
    """Per (object, design, disturbance) and per (design, disturbance): success with its Wilson interval."""
    cells = []
    for k, name in enumerate(names):
        for label in designs:
            for imp in SWEEP_IMPULSES:
                sel = [
                    r for r in rows if (r["object"], r["design"], r["impulse_paper_ns"]) == (name, label, imp)
                ]
                valid = [r for r in sel if not r["sample_error"]]
                ok = sum(r["success"] for r in valid)
                cells.append(
                    {
                        "object": name,
                        "design": label,
                        "impulse_paper_ns": imp,
                        "pose": int(chosen[label][k] - poses.rows(k)[0]),
                        "successes": int(ok),
                        "valid": len(valid),
                        "sample_errors": len(sel) - len(valid),
                        "p": wilson(int(ok), len(valid)).as_dict(),
                        "predicted_success": bool(predicted[label][0][k]),
                        **_head_p(predicted[label][1], k),
                    }
                )
    sweep = []
    for label in designs:
        for imp in SWEEP_IMPULSES:
            sel = [c for c in cells if (c["design"], c["impulse_paper_ns"]) == (label, imp)]
            ok, n = sum(c["successes"] for c in sel), sum(c["valid"] for c in sel)
            sweep.append(
                {
                    "design": label,
                    "impulse_paper_ns": imp,
                    "successes": ok,
                    "valid": n,
                    "p": wilson(ok, n).as_dict(),
                }
            )
    return {
        "designs": list(designs),
        "impulses_paper_ns": list(SWEEP_IMPULSES),
        "table_impulse_paper_ns": SWEEP_IMPULSES[0],
        "cells": cells,
        "sweep": sweep,
    }


def _write_designs(tmp: Path, result, names, poses: PoseSet) -> None:
    if result.mode is Mode.JOINT:
        write_design(tmp / "design.txt", result.designs[0])
    else:
        (tmp / "designs").mkdir()
        for k, n in enumerate(names):
            write_design(tmp / "designs" / f"{n}.txt", result.design_of(k))
    (tmp / "poses").mkdir()
    for k, n in enumerate(names):
        write_pose(tmp / "poses" / f"{n}.json", poses, int(result.chosen[k]))


def _save_adapted(tmp: Path, root: Path, surrogate, adapt: dict) -> None:
    """The adapted network as the checkpoint folder ``surrogate/`` (for any command's ``--ckpt``)."""
    from mjcodesign.surrogate import save_checkpoint

    save_checkpoint(tmp / ADAPTED_DIR, surrogate)
    adapt["checkpoint"] = str(root / ADAPTED_DIR)


def _write_print(tmp: Path, root: Path, result, names, mode: Mode) -> dict:
    """The print files of the design (joint) or of each object's design (``print/OBJECT/``)."""
    cal = Calibration.default()
    groups = (
        {"": result.designs[0]}
        if mode is Mode.JOINT
        else {n: result.design_of(k) for k, n in enumerate(names)}
    )
    out = {}
    for sub, log_e in groups.items():
        where = tmp / "print" / sub if sub else tmp / "print"
        where.mkdir(parents=True)
        report = write_print_files(
            plan_print(Stiffness(log_e), cal),
            where,
            root / "print" / sub if sub else root / "print",
            design_text(log_e),
        )
        out[sub or "joint"] = report["files"]
    return out


def _replay_chosen(specs, objs, poses, designs, rows, rho, scenario, model, seed, observer) -> None:
    """Each design's grasp of each object at its chosen pose, unperturbed, at the table's disturbance."""
    at_table = at_paper_disturbance(scenario, SWEEP_IMPULSES[0])
    jobs = [
        GraspJob(
            obj=objs[spec.name],
            pose=poses.gripper_pose(int(rows[label][k])),
            design=Stiffness(designs[label][k]),
            finger_model=model,
            scenario=at_table,
            density=rho[spec.name],
            seed=seed,
            label=f"{label}/{spec.name}",
        )
        for k, spec in enumerate(specs)
        for label in designs
    ]
    run_jobs(jobs, MujocoBackend(), observer)


class _FanOut:
    """One observer that hands every rollout to several."""

    def __init__(self, observers: list):
        self.observers = observers

    def rollout(self, rollout) -> None:
        for o in self.observers:
            o.rollout(rollout)

    def snapshot(self, snapshot) -> None:
        for o in self.observers:
            o.snapshot(snapshot)

    def close(self) -> None:
        """Nothing: each observer is closed by its owner."""
