"""The grasp landscape under the real regime: the paper's objects at their real masses, the hardware's grasp.

``bench landscape --regime real`` runs the in-domain objects of the frozen evaluation suite (the
paper's 46, 10 poses each; an object without a published mass is listed under ``skipped``) at their
published masses, with soft, semi-rigid, paper-optimized and eight random designs, under
:data:`~mjcodesign.scenarios.grasp.REAL_REGIME` (the XL330 servo at 1000 ticks on the 8 mm horn, the
10 cm lift, the paper's disturbance as a Δv of the object, the friction at the top of the tape's range).
One rollout per (object, pose, design): MuJoCo is deterministic and no perturbation is drawn.

It reports:

* success per design group: over rollouts (Wilson interval) and over objects (each object's rate, a
  percentile bootstrap over objects, :mod:`mjcodesign.evaluation.stats`); the same per design;
* (object, pose) pairs where every, some or no design succeeds, and the share where designs disagree
  (``mixed``, with its Wilson interval over pairs);
* objects that favour the soft design (soft's rate above semi-rigid's), the stiff one, or neither; the
  paired difference semi-rigid − soft over objects;
* the same against object mass: success per group in mass bins (:data:`MASS_BINS`) and the rank
  correlation of (semi-rigid − soft) with mass; and against shape: each object's solidity (volume over
  its convex hull's, 1 for a convex object), the rank correlation of (semi-rigid − soft) with it;
* a sensitivity table: the same numbers with the spool radius, the friction and the current limit at
  the ends of their cited ranges (:data:`SENSITIVITY`), one setting changed at a time, on
  ``sensitivity_designs``;
* per object and design, the outcome of every pose (``"1"`` success, ``"."`` failure).
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter

import numpy as np

from mjcodesign.design.servo import CURRENT_LIMIT_RANGE, SPOOL_RADIUS_RANGE
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, MjcodesignError
from mjcodesign.evaluation.stats import bootstrap_mean, paired_difference, wilson
from mjcodesign.evaluation.suite import DEFAULT_SUITE, load_suite
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.models.types import FingerModel
from mjcodesign.objects import published_mass
from mjcodesign.scenarios.grasp import REAL_REGIME, TAPE_FRICTION_RANGE, GraspScenario
from mjcodesign.sim import MujocoBackend

__all__ = ["bench_landscape_real", "SENSITIVITY", "MASS_BINS", "SOFT", "STIFF", "CI_REAL"]

SOFT, STIFF = "soft", "semi-rigid"
"""The two presets whose per-object difference says whether an object favours soft or stiff fingers."""
MASS_BINS = (0.1, 0.3)
"""Mass bin edges [kg]: the paper's hardware soft gripper fails above about 100 g; 300 g splits the rest."""
SENSITIVITY = (
    ("spool_radius", SPOOL_RADIUS_RANGE[0]),
    ("spool_radius", SPOOL_RADIUS_RANGE[1]),
    ("friction", TAPE_FRICTION_RANGE[0]),
    ("current_limit", CURRENT_LIMIT_RANGE[0]),
)
"""One setting moved to an end of its cited range at a time; the other ends are the regime's own values
(friction 1.0, current limit 1.75 A)."""
CI_REAL = {"objects": ("004_sugar_box",), "poses": 2, "designs": ("soft", "semi-rigid")}
"""The short version the tests run."""


def _scenario(setting: str | None, value: float | None) -> GraspScenario:
    """:data:`REAL_REGIME` with one setting moved: the servo's spool radius or current limit, or the friction."""
    if setting is None:
        return REAL_REGIME
    if setting == "friction":
        return dataclasses.replace(REAL_REGIME, friction=value)
    return dataclasses.replace(
        REAL_REGIME, tendon=dataclasses.replace(REAL_REGIME.tendon, **{setting: value})
    )


def _solidity(obj) -> float:
    """Volume over the convex hull's volume [-]: 1 for a convex object, lower for an irregular one."""
    return float(obj.mesh.volume / obj.mesh.convex_hull.volume)


def bench_landscape_real(
    *,
    suite: str = DEFAULT_SUITE,
    objects: tuple[str, ...] | None = None,
    poses: int | None = None,
    designs: tuple[str, ...],
    sensitivity: bool = True,
    sensitivity_designs: tuple[str, ...] | None = None,
    model: str = "chain",
    nthread: int | None = None,
    seed: int = 0,
    on_progress=None,
) -> dict:
    """Run the real-regime landscape (module docstring); returns a JSON-ready dict.

    ``objects``: a subset of the suite's in-domain objects (default: all); ``poses``: the first poses
    of each (default: all); ``sensitivity_designs``: the designs of the sensitivity rows (default:
    ``designs``). ``on_progress(text)`` hears one line per object.
    """
    if not designs:
        raise DesignError("the landscape needs at least one design")
    if poses is not None and poses < 1:
        raise DesignError("the landscape needs at least one pose per object")
    the_suite = load_suite(suite)
    in_domain = [o for o in the_suite.objects if o.domain == "in-domain"]
    if objects is not None:
        unknown = sorted(set(objects) - {o.name for o in in_domain})
        if unknown:
            raise DesignError(f"not in-domain objects of suite {the_suite.name}: {', '.join(unknown)}")
        in_domain = [o for o in in_domain if o.name in objects]
    sens_designs = tuple(sensitivity_designs or designs)
    stiffness = {name: Stiffness.parse(name) for name in dict.fromkeys(designs + sens_designs)}
    settings = [(None, None)] + (list(SENSITIVITY) if sensitivity else [])
    backend = MujocoBackend(nthread)
    outcome: dict[tuple, dict[str, dict[str, str]]] = {s: {} for s in settings}
    per_object, skipped = {}, {}
    cpu0, wall0 = time.process_time(), time.perf_counter()
    n_rollouts = 0
    for so in in_domain:
        try:
            mass = published_mass(so.name).mass
            obj = load_grasp_object(so.source, "light", mass="real", seed=the_suite.seed)
        except MjcodesignError as exc:
            skipped[so.name] = f"{type(exc).__name__}: {exc}"
            continue
        the_poses = so.poses[:poses] if poses else so.poses
        per_object[so.name] = {"mass_kg": mass, "solidity": _solidity(obj), "poses": len(the_poses)}
        scenes = SceneCache(size=4)
        jobs = []
        for setting in settings:
            names = designs if setting[0] is None else sens_designs
            scenario = _scenario(*setting)
            for k, pose in enumerate(the_poses):
                for name in names:
                    jobs.append(
                        GraspJob(
                            obj=obj,
                            pose=pose,
                            design=stiffness[name],
                            finger_model=FingerModel(model),
                            scenario=scenario,
                            seed=seed,
                            label=f"{so.name}/{k}/{name}",
                        )
                    )
        outs = run_jobs(jobs, backend, scenes=scenes)
        n_rollouts += len(outs)
        i = 0
        for setting in settings:
            names = designs if setting[0] is None else sens_designs
            res = {name: [] for name in names}
            failures = Counter()
            for _ in the_poses:
                for name in names:
                    res[name].append("1" if outs[i].success else ".")
                    failures.update(f.value for f in outs[i].failures)
                    i += 1
            outcome[setting][so.name] = {name: "".join(v) for name, v in res.items()}
            if setting[0] is None:
                per_object[so.name]["failures"] = dict(failures)
        if on_progress:
            on_progress(f"{so.name}: {mass * 1000:.0f} g, {len(outs)} rollouts")
    if not per_object:
        raise DesignError(f"no object could be loaded: {skipped}")
    base = _analyse(outcome[(None, None)], per_object, designs)
    rows = []
    for setting in settings[1:]:
        row = _analyse(outcome[setting], per_object, sens_designs, detail=False)
        ref = _analyse(outcome[(None, None)], per_object, sens_designs, detail=False)
        rows.append(
            {
                "setting": setting[0],
                "value": setting[1],
                **row,
                "change": {
                    "success_all": row["success_all"] - ref["success_all"],
                    "mixed_share": row["pairs"]["mixed_share"]["value"]
                    - ref["pairs"]["mixed_share"]["value"],
                },
            }
        )
    return {
        "regime": "real",
        "scenario": _scenario_dict(REAL_REGIME),
        "suite": {"name": the_suite.name, "digest": the_suite.digest},
        "model": model,
        "designs": list(designs),
        "mean_log_e": {name: float(np.mean(stiffness[name].as_list())) for name in stiffness},
        "objects": per_object,
        "skipped": skipped,
        "rollouts": n_rollouts,
        **base,
        "sensitivity_designs": list(sens_designs) if sensitivity else [],
        "sensitivity_reference": _analyse(outcome[(None, None)], per_object, sens_designs, detail=False)
        if sensitivity
        else None,
        "sensitivity": rows,
        "outcomes": {name: outcome[(None, None)][name] for name in per_object},
        "sensitivity_outcomes": {
            f"{s[0]}={s[1]:g}": {name: outcome[s][name] for name in per_object} for s in settings[1:]
        },
        "cpu_s_per_rollout": (time.process_time() - cpu0) / max(n_rollouts, 1),
        "wall_s": time.perf_counter() - wall0,
    }


def _scenario_dict(s: GraspScenario) -> dict:
    t = s.tendon
    return {
        "tendon": {
            "mode": t.mode,
            "ticks": t.ticks,
            "spool_radius_m": t.spool_radius,
            "current_limit_a": t.current_limit,
            "max_tension_n": t.max_tension,
            "pull_m": t.pull,
        },
        "lift_m": s.lift,
        "lift_s": s.lift_s,
        "delta_v_m_s": s.delta_v,
        "friction": s.friction,
        "mass": "real (published, uniform density)",
    }


def _group(name: str) -> str:
    return "random" if name.startswith("random:") else name


def _analyse(outcome: dict[str, dict[str, str]], per_object: dict, designs, *, detail: bool = True) -> dict:
    """Success per group and design, disagreeing pairs, soft vs stiff per object and against mass/shape."""
    objs = [o for o in per_object if o in outcome]
    groups = list(dict.fromkeys(_group(d) for d in designs))

    def rate(obj: str, names) -> float:
        s = "".join(outcome[obj][n] for n in names)
        return s.count("1") / len(s)

    def group_stats(names, objects=objs) -> dict:
        k = sum(outcome[o][n].count("1") for o in objects for n in names)
        n = sum(len(outcome[o][n]) for o in objects for n in names)
        out = {"rollouts": wilson(k, n).as_dict()}
        if objects:
            out["objects"] = bootstrap_mean([rate(o, names) for o in objects]).as_dict()
        return out

    by_group = {g: [d for d in designs if _group(d) == g] for g in groups}
    cats = Counter()
    for o in objs:
        for k in range(per_object[o]["poses"]):
            ok = [outcome[o][d][k] == "1" for d in designs]
            cats["all" if all(ok) else "none" if not any(ok) else "mixed"] += 1
    n_pairs = sum(cats.values())
    out = {
        "success_all": float(np.mean([c == "1" for o in objs for d in designs for c in outcome[o][d]])),
        "success": {g: group_stats(names) for g, names in by_group.items()},
        "pairs": {
            **{k: cats.get(k, 0) for k in ("all", "mixed", "none")},
            "mixed_share": wilson(cats.get("mixed", 0), n_pairs).as_dict(),
        },
    }
    if SOFT in designs and STIFF in designs:
        diff = {o: rate(o, [STIFF]) - rate(o, [SOFT]) for o in objs}
        out["soft_vs_stiff"] = {
            "favour_soft": sorted(o for o, d in diff.items() if d < 0),
            "favour_stiff": sorted(o for o, d in diff.items() if d > 0),
            "neither": sorted(o for o, d in diff.items() if d == 0),
            "stiff_minus_soft": paired_difference(
                [rate(o, [STIFF]) for o in objs], [rate(o, [SOFT]) for o in objs], names=(STIFF, SOFT)
            ).as_dict(),
            "rank_correlation_with_mass": _spearman(
                [per_object[o]["mass_kg"] for o in objs], list(diff.values())
            ),
            "rank_correlation_with_solidity": _spearman(
                [per_object[o]["solidity"] for o in objs], list(diff.values())
            ),
        }
    if detail:
        edges = (0.0, *MASS_BINS, np.inf)
        bins = {}
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            members = [o for o in objs if lo <= per_object[o]["mass_kg"] < hi]
            label = f"{lo * 1000:g}-{hi * 1000:g} g" if np.isfinite(hi) else f">= {lo * 1000:g} g"
            bins[label] = {
                "objects": len(members),
                **{g: group_stats(names, members)["rollouts"] for g, names in by_group.items()},
            }
        out["by_mass"] = bins
        out["per_design"] = {d: group_stats([d]) for d in designs}
    return out


def _spearman(x, y) -> dict:
    """Spearman's rank correlation of ``x`` and ``y`` with its two-sided p-value (None when constant)."""
    from scipy.stats import spearmanr

    if len(set(x)) < 2 or len(set(y)) < 2:
        return {"rho": None, "p_value": None, "n": len(x)}
    r = spearmanr(x, y)
    return {"rho": float(r.statistic), "p_value": float(r.pvalue), "n": len(x)}
