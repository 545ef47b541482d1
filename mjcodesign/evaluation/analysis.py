"""From a suite's rollouts to success probabilities with intervals and paired comparisons.

Per (object, design): the success probability over the chosen poses × draws, with a Wilson interval,
and the continuous outcomes (hold force, slip, lift margin) as means with Student-t intervals. Per
design and split (in-domain, out-of-domain): the mean over objects with a bootstrap interval (objects are
the unit). Per pair of designs: the mean paired difference over the objects both were measured on, its
interval, a permutation p-value and the smallest difference this many objects detect at 80 % power.
Rollouts the simulator could not use (``DIVERGED``, ``IMPLAUSIBLE``, ``BAD_POSE``) are counted, never
scored.
"""

from __future__ import annotations

from collections import defaultdict
from itertools import combinations

import numpy as np

from mjcodesign.evaluation.stats import bootstrap_mean, mean_interval, paired_difference, wilson

__all__ = ["ALL_POSES", "CONTINUOUS", "SPLITS", "analyse", "object_rates", "per_object_cells", "select_policy"]

ALL_POSES = "all"
"""The pose policy that keeps every pose of the suite."""
SPLITS = ("in-domain", "out-of-domain")
CONTINUOUS = ("hold_force_n", "slip_m", "lift_margin_m")
"""Continuous outcomes summarised per (object, design): mean hold force [N], slip [m], lift margin [m]."""


def _key(r: dict) -> tuple:
    return (r["density"], r["impulse_paper_ns"], r["design"], r["object"])


def select_policy(rows: list[dict], policy: str, surrogate_choice: dict | None = None) -> list[dict]:
    """The rows a pose policy keeps: every pose, the first, the surrogate's or the simulator's best."""
    if policy == ALL_POSES:
        return rows
    if policy == "fixed":
        return [r for r in rows if r["pose"] == 0]
    if policy == "surrogate":
        choice = surrogate_choice or {}
        return [r for r in rows if r["pose"] == choice[r["object"]][r["density"]][r["design"]]["pose"]]
    if policy == "oracle":
        rate: dict[tuple, list[int]] = defaultdict(lambda: [0, 0])
        for r in rows:
            if not r["sample_error"]:
                c = rate[(*_key(r), r["pose"])]
                c[0] += r["success"]
                c[1] += 1
        best: dict[tuple, tuple[float, int]] = {}
        for (*k, pose), (s, n) in rate.items():
            cand = (s / n, -pose)  # highest rate, then the lowest pose index
            if tuple(k) not in best or cand > best[tuple(k)]:
                best[tuple(k)] = cand
        return [r for r in rows if _key(r) in best and r["pose"] == -best[_key(r)][1]]
    raise ValueError(f"unknown pose policy {policy!r}")


def per_object_cells(rows: list[dict]) -> dict[tuple, dict]:
    """Per (density, impulse, design, object): successes, valid rollouts, sample errors, p with Wilson."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        groups[_key(r)].append(r)
    out = {}
    for key, rs in groups.items():
        valid = [r for r in rs if not r["sample_error"]]
        k = sum(r["success"] for r in valid)
        cell = {
            "density": key[0],
            "impulse_paper_ns": key[1],
            "design": key[2],
            "object": key[3],
            "domain": rs[0]["domain"],
            "fold": rs[0]["fold"],
            "successes": int(k),
            "valid": len(valid),
            "sample_errors": len(rs) - len(valid),
            "p": wilson(int(k), len(valid)).as_dict(),
        }
        for name in CONTINUOUS:
            cell[name] = mean_interval([r[name] for r in valid]).as_dict() if valid else None
        out[key] = cell
    return out


def analyse(result: dict, designs: list[str], policies: list[str], *, seed: int = 0) -> dict:
    """The summary of :func:`~mjcodesign.evaluation.rollouts.run_suite`'s result.

    ``{"cells": [...], "regimes": [{"density", "impulse_paper_ns", "policies": {policy: {"designs":
    {label: {split: Interval dict}}, "paired": [...]}}}]}``; ``designs`` fixes the order of the pairs
    (a − b for a listed before b).
    """
    rows = result["rows"]
    regimes = sorted({(r["density"], r["impulse_paper_ns"]) for r in rows}, key=lambda x: (x[0], x[1]))
    all_cells: list[dict] = []
    out_regimes = []
    for dens, imp in regimes:
        regime_rows = [r for r in rows if r["density"] == dens and r["impulse_paper_ns"] == imp]
        entry = {"density": dens, "impulse_paper_ns": imp, "policies": {}}
        for policy in [ALL_POSES, *policies]:
            cells = per_object_cells(select_policy(regime_rows, policy, result.get("surrogate_choice")))
            for c in cells.values():
                all_cells.append({"pose_policy": policy, **c})
            entry["policies"][policy] = _summarise(cells, designs, seed)
        out_regimes.append(entry)
    return {"cells": all_cells, "regimes": out_regimes}


def object_rates(cells) -> dict[str, dict[str, float]]:
    """Per design, each object's share of successful usable rollouts.

    ``cells``: :func:`per_object_cells`' values; an object with no usable rollout is left out.
    """
    rate: dict[str, dict[str, float]] = defaultdict(dict)
    for c in cells:
        if c["valid"]:
            rate[c["design"]][c["object"]] = c["successes"] / c["valid"]
    return rate


def _summarise(cells: dict[tuple, dict], designs: list[str], seed: int) -> dict:
    """Per design and split: the mean over objects; per pair and split: the paired difference."""
    rate: dict[str, dict[str, dict[str, float]]] = defaultdict(lambda: defaultdict(dict))
    for split in SPLITS:
        for d, per in object_rates(c for c in cells.values() if c["domain"] == split).items():
            rate[d][split] = per
    per_design: dict[str, dict] = {}
    for d in designs:
        per_design[d] = {}
        for split in SPLITS:
            values = list(rate[d][split].values())
            per_design[d][split] = bootstrap_mean(values, seed=seed).as_dict() if values else None
    paired = []
    for a, b in combinations(designs, 2):
        for split in SPLITS:
            common = sorted(set(rate[a][split]) & set(rate[b][split]))
            if not common:
                continue
            res = paired_difference(
                np.array([rate[a][split][o] for o in common]),
                np.array([rate[b][split][o] for o in common]),
                names=(a, b),
                seed=seed,
            )
            paired.append({"split": split, **res.as_dict()})
    return {"designs": per_design, "paired": paired}
