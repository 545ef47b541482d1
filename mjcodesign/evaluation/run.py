"""Re-simulate every cell of the table: design group × pose sampling × domain × density × impulse.

Success always comes from the simulator (MuJoCo C through :func:`mjcodesign.jobs.run_jobs`); the
surrogate only chooses poses (``surrogate`` pose sampling) and its prediction is recorded beside the
simulated outcome. Identical rollouts (the fixed and the surrogate's pose agree) run once.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mjcodesign.errors import MjcodesignError
from mjcodesign.evaluation.candidates import CLOUD_POINTS, ObjectCandidates, object_candidates
from mjcodesign.evaluation.config import EvalConfig
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.objects import DENSITY_PRESETS, YCB_IN_DOMAIN
from mjcodesign.scenarios.grasp import GraspScenario, paper_impulse
from mjcodesign.scenarios.outcome import Outcome
from mjcodesign.sim.protocol import get_backend

__all__ = ["EvalObject", "domain_of", "prepare_objects", "record_examples", "run_evaluation"]

Progress = Callable[[str, int, int], None]
"""``progress(stage, done, total)``."""


def domain_of(name: str) -> str:
    """``in-domain`` for the paper's 46 training objects, ``out-of-domain`` for anything else."""
    return "in-domain" if name in YCB_IN_DOMAIN else "out-of-domain"


@dataclass(frozen=True, eq=False)
class EvalObject:
    """An object ready for evaluation, or the reason it is not."""

    name: str
    domain: str
    candidates: ObjectCandidates | None = None
    error: str | None = None


def prepare_objects(
    config: EvalConfig, *, n_points: int = CLOUD_POINTS, progress: Progress | None = None
) -> list[EvalObject]:
    """Load, decompose and pose every object; clouds only when the surrogate chooses poses."""
    names = [(n, "in-domain") for n in config.in_domain] + [
        (n, "out-of-domain") for n in config.out_of_domain
    ]
    out = []
    for i, (name, domain) in enumerate(names):
        try:
            obj = load_grasp_object(name, "light", seed=config.seed, cache_dir=config.cache_dir)
            anygrasp = config.anygrasp if domain == "in-domain" else None
            cands = object_candidates(
                obj, config.candidates, seed=config.seed, anygrasp=anygrasp, cache_dir=config.cache_dir
            )
            if config.needs_surrogate:
                cands = cands.with_clouds(n_points, config.seed)
            out.append(EvalObject(obj.name, domain, cands))
        except MjcodesignError as exc:
            out.append(EvalObject(str(name), domain, error=f"{type(exc).__name__}: {exc}"))
        if progress:
            progress("objects", i + 1, len(names))
    return out


def _predict(surrogate, cands: ObjectCandidates, design, rho: float):
    """The surrogate's (success score, success) for every candidate of one object."""
    from mjcodesign.surrogate import GraspBatch, Poses

    volume = cands.obj.mass / cands.obj.density
    poses = Poses(cands.clouds, cands.com, cands.up, np.full(len(cands), volume))
    p = len(cands)
    pred = surrogate.predict(
        GraspBatch(poses, np.arange(p), np.full(p, rho), np.tile(design.log_e.ravel(), (p, 1)))
    )
    return np.asarray(pred.success_score, dtype=float), np.asarray(pred.success, dtype=bool)


def _job(
    cands: ObjectCandidates,
    k: int,
    design,
    config: EvalConfig,
    scenario,
    rho: float,
    impulse: float,
    label: str,
) -> GraspJob:
    """The grasp of candidate ``k`` with ``design`` at density ``rho`` under ``impulse`` [N s]."""
    return GraspJob(
        obj=cands.obj,
        pose=cands.poses[k],
        design=design,
        finger_model=config.model,
        scenario=dataclasses.replace(scenario, impulse=impulse),
        density=rho,
        seed=config.seed,
        label=label,
    )


def _outcome_row(o: Outcome) -> dict:
    return {
        "success": bool(o.success),
        "body_force": list(o.body_force),
        "displacement": list(o.displacement),
        "ground_contact": bool(o.ground_contact),
        "reason": o.reason,
        "failures": [f.value for f in o.failures],
        "lift_height": float(o.lift_height),
        "wall_time_s": float(o.wall_time_s),
    }


def run_evaluation(
    config: EvalConfig,
    objects: list[EvalObject],
    surrogate=None,
    *,
    scenario: GraspScenario | None = None,
    progress: Progress | None = None,
) -> list[dict]:
    """One row per rollout (every cell's every object), JSON-ready, in a fixed order.

    ``surrogate`` (:class:`mjcodesign.surrogate.Surrogate`) is needed for ``surrogate`` pose sampling
    and adds its prediction to every row; without it rows carry ``predicted_success`` None.
    """
    if config.needs_surrogate and surrogate is None:
        raise MjcodesignError("surrogate pose sampling needs a checkpoint")
    scenario = scenario or GraspScenario()
    rows: list[dict] = []
    jobs: list[GraspJob] = []
    job_of: dict[tuple, int] = {}
    for ev in objects:
        if ev.candidates is None:
            continue
        cands = ev.candidates
        for g in config.designs:
            design = g.for_object(ev.name)
            if design is None or (g.group == "individual" and ev.domain != "in-domain"):
                continue
            for dens in config.densities:
                rho = DENSITY_PRESETS[dens]
                scores = ok = None
                if surrogate is not None:
                    scores, ok = _predict(surrogate, cands, design, rho)
                for sampling in config.pose_sampling:
                    k = int(np.argmax(scores)) if sampling == "surrogate" else 0
                    for imp in config.impulses:
                        key = (ev.name, g.label, dens, k, imp)
                        if key not in job_of:
                            job_of[key] = len(jobs)
                            label = f"{g.label}/{ev.name}/{dens}/{k}/{imp}"
                            jobs.append(
                                _job(cands, k, design, config, scenario, rho, paper_impulse(imp), label)
                            )
                        rows.append(
                            {
                                "group": g.group,
                                "design_label": g.label,
                                "design": design.as_list(),
                                "object": ev.name,
                                "domain": ev.domain,
                                "density": dens,
                                "density_kg_m3": rho,
                                "pose_sampling": sampling,
                                "candidate": k,
                                "pose_source": cands.source,
                                "pose_source_index": int(cands.source_index[k]),
                                "pose": cands.matrices[k].tolist(),
                                "openings": list(cands.poses[k].openings),
                                "impulse_paper_ns": float(imp),
                                "impulse_ns": paper_impulse(imp),
                                "predicted_score": None if scores is None else float(scores[k]),
                                "predicted_success": None if ok is None else bool(ok[k]),
                                "_job": job_of[key],
                            }
                        )
    outcomes = _run(jobs, progress)
    for r in rows:
        o = outcomes[r.pop("_job")]
        r.update(_outcome_row(o))
    return rows


def _run(jobs: list[GraspJob], progress: Progress | None) -> list[Outcome]:
    """Run the jobs object by object (one scene cache), reporting progress."""
    backend = get_backend("mujoco")
    scenes = SceneCache()
    out: list[Outcome | None] = [None] * len(jobs)
    by_obj: dict[int, list[int]] = {}
    for i, j in enumerate(jobs):
        by_obj.setdefault(id(j.obj), []).append(i)
    done = 0
    for idx in by_obj.values():
        res = run_jobs([jobs[i] for i in idx], backend, scenes=scenes)
        for i, o in zip(idx, res, strict=True):
            out[i] = o
        done += len(idx)
        if progress:
            progress("rollouts", done, len(jobs))
    return out  # type: ignore[return-value]


def record_examples(
    rows: list[dict], objects: list[EvalObject], config: EvalConfig, observer, *, per_group: int = 2
) -> list[str]:
    """Re-run the best and worst rollouts of every design group into ``observer``; their labels.

    ``per_group`` best (held, highest lift) and worst (failed, lowest lift), at the first impulse; the
    observer is e.g. a Rerun recorder.
    """
    from mjcodesign.design.stiffness import Stiffness

    cands = {o.name: o.candidates for o in objects if o.candidates is not None}
    imp = float(config.impulses[0])
    picked: list[dict] = []
    for g in config.designs:
        mine = [r for r in rows if r["design_label"] == g.label and r["impulse_paper_ns"] == imp]
        seen, unique = set(), []
        for r in mine:
            key = (r["object"], r["density"], r["candidate"])
            if key not in seen:
                seen.add(key)
                unique.append(r)
        best = sorted((r for r in unique if r["success"]), key=lambda r: -r["lift_height"])[:per_group]
        worst = sorted((r for r in unique if not r["success"]), key=lambda r: r["lift_height"])[:per_group]
        picked += [dict(r, _tag="best") for r in best] + [dict(r, _tag="worst") for r in worst]
    jobs = []
    for r in picked:
        c = cands[r["object"]]
        label = f"{r['design_label']}/{r['_tag']}/{r['object']}/{r['density']}"
        design = Stiffness(r["design"])
        jobs.append(
            _job(
                c, r["candidate"], design, config, GraspScenario(), r["density_kg_m3"], r["impulse_ns"], label
            )
        )
    if jobs:
        run_jobs(jobs, get_backend("mujoco"), observer)
    return [j.label for j in jobs]
