"""How repeatable a grasp label is: K perturbed rollouts of one (object, pose, design) cell, and how often they agree.

``bench labels`` runs the frozen evaluation suite's in-domain objects at their published masses under
:data:`~mjcodesign.scenarios.grasp.REAL_REGIME` (the first ``objects`` with a published mass, in suite
order; the others are listed under ``skipped``), the first ``poses`` of each, every design, and
``draws`` perturbed rollouts per cell under the suite's perturbation model, drawn by
:func:`~mjcodesign.evaluation.run_suite` (the draws of an (object, pose) come from their own seeded
stream, shared by every design, so the first 4 of 16 draws are the draws of a 4-draw run).

Each cell's outcomes are a string over its draws: ``"1"`` success, ``"."`` failure, ``"x"`` a rollout
the simulator could not use (a sample error, or a draw given up because every redraw started inside
the object); ``x`` is never scored. From them it reports:

* ``agreement``: the share of cells whose first K usable outcomes all agree, for K in :data:`AGREE_K`
  (up to ``draws``), with a Wilson interval over cells and a bootstrap interval over objects;
* ``p``: the distribution of the per-cell success probability p over all draws, and the draws a cell
  needs for a label with standard error ≤ :data:`SE_TARGET` at its p (``ceil(p(1 − p) / SE²)``, at
  least 1): the median and the share needing more than :data:`HEADLINE_FIRST`;
* ``fixed``: the label from the first K draws alone, its error against all the draws;
* ``adaptive``: the scheme "``first`` draws per cell, extended to all the draws only where they
  disagree", for each ``first`` of :data:`ADAPTIVE_FIRST`: its mean cost in rollouts per cell and its
  error |p_adaptive − p_all| (``headline`` is ``first`` = :data:`HEADLINE_FIRST`);
* the same per design group (the random designs pooled), per design, and per object (objects whose
  every cell agrees over every draw are listed under ``never_vary``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from fractions import Fraction

import numpy as np

from mjcodesign.errors import DesignError, MeshError
from mjcodesign.evaluation.config import parse_design_groups
from mjcodesign.evaluation.rollouts import SuiteRun, run_suite
from mjcodesign.evaluation.stats import bootstrap_mean, wilson
from mjcodesign.evaluation.suite import DEFAULT_SUITE, load_suite
from mjcodesign.models.types import FingerModel
from mjcodesign.objects import published_mass
from mjcodesign.scenarios.grasp import REAL_REGIME

__all__ = [
    "ADAPTIVE_FIRST",
    "AGREE_K",
    "DESIGNS",
    "HEADLINE_FIRST",
    "SE_TARGET",
    "analyse_cells",
    "bench_labels",
    "draws_needed",
]

DESIGNS = ("soft", "semi-rigid", "paper-optimized") + tuple(f"random:{s}" for s in range(5))
"""The presets and five random designs (``Stiffness.random`` seeds 0-4, as the landscape names them)."""
AGREE_K = (2, 4, 8, 16)
"""Draw counts at which agreement is reported (those up to ``draws``, and ``draws`` itself)."""
SE_TARGET = 0.1
"""Standard error asked of a success-probability label: ±0.1 separates p = 0.5 from 0.7 at about 2 SE."""
ADAPTIVE_FIRST = (2, 4, 8)
"""First-stage draw counts of the adaptive scheme (those below ``draws``)."""
HEADLINE_FIRST = 4
"""The adaptive scheme's first stage the issue proposes: 4 draws, all of them only where these disagree."""
SUCCESS, FAILURE, UNUSABLE = "1", ".", "x"


def draws_needed(k: int, n: int, se: float = SE_TARGET) -> int:
    """Draws for a standard error ≤ ``se`` at p = k / n: ``ceil(p(1 − p) / se²)``, at least 1.

    Exact in rationals, so that p = 0.5 at se = 0.1 needs 25, not 26 by rounding.
    """
    if n < 1 or not 0 <= k <= n:
        raise DesignError(f"draws_needed: need 0 <= k <= n and n >= 1, got k={k}, n={n}")
    var = Fraction(k * (n - k), n * n)
    return max(1, math.ceil(var / Fraction(str(se)) ** 2))


def _group(label: str) -> str:
    return "random" if label.startswith("random:") else label


def _usable(outcomes: str) -> str:
    return outcomes.replace(UNUSABLE, "")


def _p(outcomes: str) -> float | None:
    u = _usable(outcomes)
    return u.count(SUCCESS) / len(u) if u else None


def _agrees(outcomes: str) -> bool:
    u = _usable(outcomes)
    return bool(u) and len(set(u)) == 1


def _share(flags: list[bool], objects: list[str]) -> dict:
    """The share of True: Wilson over cells, and a bootstrap over the objects' own shares."""
    out = {"cells": wilson(int(sum(flags)), len(flags)).as_dict()}
    per_obj: dict[str, list[bool]] = {}
    for f, o in zip(flags, objects, strict=True):
        per_obj.setdefault(o, []).append(f)
    out["objects"] = bootstrap_mean([np.mean(v) for v in per_obj.values()]).as_dict()
    return out


def _errors(err: list[float]) -> dict:
    e = np.asarray(err, dtype=float)
    return {
        "max": float(e.max()),
        "mean": float(e.mean()),
        "share_over_se": float(np.mean(e > SE_TARGET)),
    }


def analyse_cells(cells: list[dict], draws: int) -> dict:
    """Agreement, p, draws needed and the fixed and adaptive labels of ``cells`` (module docstring).

    Each cell is ``{"object", "pose", "design", "outcomes"}`` with ``draws`` outcome characters.
    Cells without a usable outcome are counted under ``unusable_cells`` and left out of the rest.
    """
    used = [c for c in cells if _usable(c["outcomes"])]
    if not used:
        raise DesignError("no cell has a usable rollout")
    objs = [c["object"] for c in used]
    ks = sorted({k for k in AGREE_K if k <= draws} | {draws})
    p_all = [_p(c["outcomes"]) for c in used]
    n_all = [len(_usable(c["outcomes"])) for c in used]
    need = [draws_needed(_usable(c["outcomes"]).count(SUCCESS), n) for c, n in zip(used, n_all, strict=True)]
    agreement = {}
    for k in ks:
        flags = [_agrees(c["outcomes"][:k]) for c in used]
        agreement[str(k)] = {
            **_share(flags, objs),
            "all_success": sum(f and _p(c["outcomes"][:k]) == 1.0 for f, c in zip(flags, used, strict=True)),
            "all_failure": sum(f and _p(c["outcomes"][:k]) == 0.0 for f, c in zip(flags, used, strict=True)),
        }
    counts = np.bincount(
        [_usable(c["outcomes"]).count(SUCCESS) for c, n in zip(used, n_all, strict=True) if n == draws],
        minlength=draws + 1,
    )
    fixed = {}
    for k in ks:
        err = [
            abs(_p(c["outcomes"][:k]) - p)
            for c, p in zip(used, p_all, strict=True)
            if _usable(c["outcomes"][:k])
        ]
        fixed[str(k)] = {"rollouts_per_cell": k, "cells": len(err), "error": _errors(err)}
    adaptive = {}
    for first in (f for f in ADAPTIVE_FIRST if f < draws):
        cost, err, extended = [], [], 0
        for c, p in zip(used, p_all, strict=True):
            head = c["outcomes"][:first]
            if _agrees(head):
                cost.append(first)
                err.append(abs(_p(head) - p))
            else:
                cost.append(draws)
                err.append(0.0)
                extended += 1
        adaptive[str(first)] = {
            "first": first,
            "full": draws,
            "rollouts_per_cell": float(np.mean(cost)),
            "extended_share": extended / len(used),
            "error": _errors(err),
        }
    return {
        "cells": len(used),
        "unusable_cells": len(cells) - len(used),
        "unusable_rollouts": sum(c["outcomes"].count(UNUSABLE) for c in cells),
        "agreement": agreement,
        "p": {
            "mean": float(np.mean(p_all)),
            "quantiles": {
                q: float(np.quantile(p_all, float(q))) for q in ("0.1", "0.25", "0.5", "0.75", "0.9")
            },
            "share_between": float(np.mean([0 < p < 1 for p in p_all])),
            "successes_of_draws": {str(i): int(v) for i, v in enumerate(counts)},
        },
        "draws_needed": {
            "se_target": SE_TARGET,
            "median": float(np.median(need)),
            "max": int(max(need)),
            "share_over_first": float(np.mean([n > HEADLINE_FIRST for n in need])),
            "histogram": {str(v): need.count(v) for v in sorted(set(need))},
        },
        "fixed": fixed,
        "adaptive": adaptive,
        "headline": adaptive.get(str(HEADLINE_FIRST)),
    }


def _brief(cells: list[dict], draws: int) -> dict:
    """The few numbers of a subset: cells, all-agree share at each K, mean p, need and adaptive cost."""
    a = analyse_cells(cells, draws)
    return {
        "cells": a["cells"],
        "agree": {k: v["cells"]["value"] for k, v in a["agreement"].items()},
        "mean_p": a["p"]["mean"],
        "share_between": a["p"]["share_between"],
        "median_draws_needed": a["draws_needed"]["median"],
        "adaptive_rollouts_per_cell": a["headline"]["rollouts_per_cell"] if a["headline"] else None,
    }


def bench_labels(
    *,
    suite: str = DEFAULT_SUITE,
    objects: int = 12,
    poses: int = 3,
    designs: tuple[str, ...] = DESIGNS,
    draws: int = 16,
    seed: int = 0,
    model: str = "chain",
    cache_dir=None,
    progress: Callable[[str, int, int], None] | None = None,
    warn: Callable[[str], None] | None = None,
) -> dict:
    """Run the label-repeatability bench (module docstring); returns a JSON-ready dict.

    ``objects``: how many of the suite's in-domain objects with a published mass (in suite order);
    ``poses``: the first poses of each; ``designs``: presets, ``random:SEED`` or ``joint:FILE``;
    ``draws``: perturbed rollouts per cell; ``seed``: the perturbation draws' seed. ``progress(stage,
    done, total)`` hears each finished object; ``warn(line)`` each object that could not be loaded.
    """
    for name, value in (("objects", objects), ("poses", poses), ("draws", draws)):
        if isinstance(value, bool) or int(value) < 1:
            raise DesignError(f"--{name} must be >= 1, got {value}")
    if not designs:
        raise DesignError("the bench needs at least one design")
    groups = parse_design_groups(",".join(designs))
    FingerModel(model)
    the_suite = load_suite(suite)
    in_domain = [o for o in the_suite.objects if o.domain == "in-domain"]
    skipped = {}
    for o in in_domain:
        try:
            published_mass(o.source)
        except MeshError as exc:
            skipped[o.name] = f"{type(exc).__name__}: {exc}"
    chosen = [o for o in in_domain if o.name not in skipped][:objects]
    if not chosen:
        raise DesignError(f"suite {the_suite.name} has no in-domain object with a published mass")
    sub = dataclasses.replace(
        the_suite,
        objects=tuple(
            dataclasses.replace(o, poses=o.poses[:poses], source_index=o.source_index[:poses]) for o in chosen
        ),
    )
    run = SuiteRun(
        designs=groups, perturbations=draws, mass="real", model=model, seed=seed, scenario=REAL_REGIME
    )
    cpu0, wall0 = time.process_time(), time.perf_counter()
    result = run_suite(sub, run, cache_dir=cache_dir, progress=progress, warn=warn)
    cpu_s, wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
    per_object: dict[str, dict] = {}
    for o in result["objects"]:
        if o["error"]:
            skipped[o["name"]] = o["error"]
        else:
            per_object[o["name"]] = {
                "mass_kg": published_mass(o["name"]).mass,
                "poses": o["poses"],
                "redrawn": o["redrawn"],
                "draws_given_up": o["draws_given_up"],
            }
    if not per_object:
        raise DesignError(f"no object could be loaded: {skipped}")
    grid: dict[tuple, list[str]] = {
        (so.name, k, g.label): [UNUSABLE] * draws
        for so in sub.objects
        if so.name in per_object
        for k in range(len(so.poses))
        for g in groups
    }
    for r in result["rows"]:
        grid[(r["object"], r["pose"], r["design"])][r["draw"]] = (
            UNUSABLE if r["sample_error"] else SUCCESS if r["success"] else FAILURE
        )
    cells = [
        {"object": o, "pose": k, "design": d, "group": _group(d), "outcomes": "".join(v)}
        for (o, k, d), v in grid.items()
    ]
    labels = [g.label for g in groups]
    by_group = {
        g: _brief([c for c in cells if c["group"] == g], draws) for g in dict.fromkeys(map(_group, labels))
    }
    for name in per_object:
        mine = [c for c in cells if c["object"] == name]
        per_object[name].update(_brief(mine, draws))
        per_object[name]["never_vary"] = all(_agrees(c["outcomes"]) for c in mine)
    n_rollouts = len(result["rows"])
    return {
        "regime": "real",
        "scenario": {**dataclasses.asdict(REAL_REGIME), "tendon_drive": type(REAL_REGIME.tendon).__name__},
        "suite": {"name": the_suite.name, "digest": the_suite.digest},
        "perturbation": the_suite.perturbation.as_dict(),
        "model": model,
        "designs": labels,
        "draws": draws,
        "seed": seed,
        "objects": per_object,
        "skipped": skipped,
        "rollouts": n_rollouts,
        **analyse_cells(cells, draws),
        "overall": _brief(cells, draws),
        "by_group": by_group,
        "by_design": {d: _brief([c for c in cells if c["design"] == d], draws) for d in labels},
        "never_vary": sorted(o for o, v in per_object.items() if v["never_vary"]),
        "cell_outcomes": cells,
        "cpu_s_per_rollout": cpu_s / max(n_rollouts, 1),
        "wall_s": wall_s,
    }
