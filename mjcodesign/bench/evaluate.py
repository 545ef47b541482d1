"""Benchmark of a suite evaluation: raw ``mujoco.rollout`` against :func:`run_suite`, on the same scenes.

* ``raw_rollouts_per_s``: ``mujoco.rollout`` alone, one call per object over all its perturbed scenes ×
  designs on all cores (models, controls and initial states prepared beforehand, not timed);
* ``pipeline_rollouts_per_s``: :func:`mjcodesign.evaluation.run_suite` on the same suite and draws
  (object loading from the cache, the start-overlap checks of the draws, scene copies, the rollout,
  divergence checks and outcomes);
* ``pipeline_vs_raw``: their ratio, each repeat's pair measured back to back (the machine is shared).
"""

from __future__ import annotations

import os
import time

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjcodesign.evaluation.config import parse_design_groups
from mjcodesign.evaluation.rollouts import SuiteRun, run_suite
from mjcodesign.evaluation.suite import build_suite
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object
from mjcodesign.models.simulate import reset_warnings
from mjcodesign.scenarios import get_regime
from mjcodesign.scenarios.grasp import at_paper_disturbance, control_spec, phase_controls
from mjcodesign.scenarios.perturb import Perturbation, perturbed_scene
from mjcodesign.sim import initial_state
from mjcodesign.sim.mujoco_c import scene_with_design

__all__ = ["bench_evaluate"]


def bench_evaluate(
    objects: tuple[str, ...] = ("013_apple", "025_mug", "egad-like:3"),
    poses_per_object: int = 10,
    perturbations: int = 8,
    designs: str = "soft,semi-rigid,paper-optimized,random:1",
    *,
    regime: str = "real",
    repeats: int = 2,
    cache_dir=None,
) -> dict:
    """Time the pipeline and the raw rollouts of the same suite, ``repeats`` pairs.

    The defaults are the default suite's rollouts per object (10 poses × 8 draws × 4 designs) under the
    ``regime`` that ``evaluate`` runs by default, so that the per-object work weighs as it does there.
    """
    reg = get_regime(regime)
    density, mass = reg.masses(None, None)
    suite = build_suite(objects, poses_per_object=poses_per_object, seed=0, cache_dir=cache_dir)
    run = SuiteRun(
        designs=parse_design_groups(designs),
        perturbations=perturbations,
        scenario=reg.scenario,
        mass=mass,
        densities=(density,),
    )
    result = run_suite(suite, run, cache_dir=cache_dir)  # warm-up; its rows name the draws used
    prepared = _raw_batches(suite, run, result["rows"], cache_dir)
    n = sum(len(m) for m, _, _ in prepared)
    raw_s, pipe_s = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run_suite(suite, run, cache_dir=cache_dir)
        pipe_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        for models, x0, ctrl in prepared:
            datas = [mujoco.MjData(models[0]) for _ in range(len(os.sched_getaffinity(0)))]
            for d in datas:
                reset_warnings(d)
            mj_rollout.rollout(models, datas, x0, ctrl, control_spec=control_spec())
        raw_s.append(time.perf_counter() - t0)
    rows = len(result["rows"])
    ratios = [(rows / p) / (n / r) for p, r in zip(pipe_s, raw_s, strict=True)]
    return {
        "objects": list(objects),
        "regime": regime,
        "poses_per_object": poses_per_object,
        "perturbations": perturbations,
        "designs": designs.split(","),
        "rollouts": rows,
        "raw_rollouts": n,
        "raw_wall_s": raw_s,
        "pipeline_wall_s": pipe_s,
        "raw_rollouts_per_s": n / float(np.median(raw_s)),
        "pipeline_rollouts_per_s": rows / float(np.median(pipe_s)),
        "pipeline_vs_raw": ratios,
        "default_suite_estimate_s": _DEFAULT_SUITE_ROLLOUTS * float(np.median(pipe_s)) / rows,
        "default_suite_raw_estimate_s": _DEFAULT_SUITE_ROLLOUTS * float(np.median(raw_s)) / n,
    }


_DEFAULT_SUITE_ROLLOUTS = 27840  # (46 + 41) objects x 10 poses x 8 draws x 4 designs, less given-up draws


def _raw_batches(suite, run, rows, cache_dir):
    """Per object: the models, initial states and controls of the rollouts ``rows`` name.

    Same masses, tendon drive and disturbance as the pipeline's rows.
    """
    out = []
    by_name = {o.name: o for o in suite.objects}
    for name in dict.fromkeys(r["object"] for r in rows):
        so = by_name[name]
        obj = load_grasp_object(so.source, "light", seed=suite.seed, cache_dir=cache_dir)
        mine = [r for r in rows if r["object"] == name]
        first = run.designs[0].design
        scenario = at_paper_disturbance(run.scenario, mine[0]["impulse_paper_ns"])
        base = SceneCache().scene(
            GraspJob(
                obj=obj, pose=so.poses[0], design=first, scenario=scenario, density=mine[0]["density_kg_m3"]
            )
        )
        designs = {g.label: g.design for g in run.designs}
        scenes = []
        for r in mine:
            p = Perturbation(**r["perturbation"])
            scenes.append(
                scene_with_design(
                    perturbed_scene(base, scenario, p, pose=so.poses[r["pose"]]), designs[r["design"]]
                )
            )
        plans = [phase_controls(sc, scenario) for sc in scenes]
        ctrl = np.stack([c for c, _ in plans])
        x0 = np.stack([initial_state(sc) for sc in scenes])
        out.append(([sc.model for sc in scenes], x0, ctrl))
    return out
