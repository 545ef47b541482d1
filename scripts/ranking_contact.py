"""Does knowing where the object meets each finger make a design ranking learnable? Trees with and without.

    python3 scripts/ranking_contact.py --data DIR --out FILE.json [--folds 5] [--seed 0]

The design signal of a perturbed dataset is grasp-specific (``scripts/ranking_sources.py``): a pose's
ranking of its designs transfers neither from other objects nor from the nearest poses of its own, and
every model ranks about as well as "stiffer ranks higher". A block's stiffness can only matter where
the object loads it, so this script gives a model that information and measures what it buys.

Per pose, from its partial point cloud in the palm frame (finger A on +y, finger B on −y, each finger
hanging along −z from the palm, block b over ``[x0_b, x1_b]`` of its length): for every finger and
block, the share of the cloud's points on that finger's side at the block's height (``presence``) and
how far towards that finger they reach (``reach``, the largest ``σ y`` [m]; 0 where none). Two sets of
gradient-boosted trees with the success head's soft-label loss
(:func:`~mjcodesign.surrogate.metrics.soft_label_trees`) are fitted per object fold:

- ``base``: the tree baseline's inputs (:func:`~mjcodesign.surrogate.metrics.tree_features`);
- ``contact``: those, the 44 contact numbers, the two openings, each block's ln E times its presence,
  and per finger the presence-weighted mean ln E.

Every object is held out once (``--folds`` K, objects assigned by a seeded permutation). On the held-out
poses whose measured success_p varies over at least
:data:`~mjcodesign.surrogate.ranking.MIN_DESIGNS` designs: the per-pose Spearman of each model against
success_p, their paired difference (contact − base) with a 95 % interval from resampling objects; and
on every held-out row the success AUC and Brier score of each.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

DRAWS = 2000
"""Object-bootstrap resamples of the paired difference's interval."""


def _fail(message: str) -> None:
    """Exit 2 with ``message`` as the one line on stderr (bad input)."""
    print(f"ranking_contact: {message}", file=sys.stderr)
    sys.exit(2)


def contact_features(clouds: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """Per pose, (presence, reach) of each finger's blocks, shape (P, 4 n_blocks).

    ``clouds`` (P, N, 3) in the palm frame; ``spans`` (n_blocks, 2): each block's [x0, x1] along the
    finger [m]. Columns: presence of finger A's blocks, of finger B's, then reach of A's, of B's
    (the 22-design order: finger A first, base to tip).
    """
    c = np.asarray(clouds, dtype=float)
    along = -c[:, :, 2]  # (P, N): distance from the palm along the fingers
    presence, reach = [], []
    for sigma in (1.0, -1.0):
        toward = sigma * c[:, :, 1]
        side = toward > 0
        for x0, x1 in spans:
            at = side & (along >= x0) & (along < x1)
            presence.append(at.mean(axis=1))
            reach.append(np.where(at, toward, -np.inf).max(axis=1))
    reach_a = np.stack(reach, axis=1)
    return np.concatenate([np.stack(presence, axis=1), np.where(np.isfinite(reach_a), reach_a, 0.0)], axis=1)


def contact_inputs(
    base: np.ndarray, log_e: np.ndarray, contact: np.ndarray, openings: np.ndarray
) -> np.ndarray:
    """The ``contact`` model's inputs: ``base``, the contact numbers, openings, ln E x presence, weighted means."""
    n = log_e.shape[1]
    presence = contact[:, :n]
    weighted = [
        (log_e[:, f] * presence[:, f]).sum(axis=1) / np.maximum(presence[:, f].sum(axis=1), 1e-12)
        for f in (slice(0, n // 2), slice(n // 2, n))
    ]
    return np.concatenate([base, contact, openings, log_e * presence, np.stack(weighted, axis=1)], axis=1)


def object_folds(objects: list[str], k: int, seed: int) -> dict[str, int]:
    """Each object's fold, 0..k-1, from a seeded permutation (sizes differ by at most one)."""
    order = np.random.default_rng(seed).permutation(sorted(objects))
    return {str(o): i % k for i, o in enumerate(order)}


def paired(a: np.ndarray, b: np.ndarray, objects: np.ndarray, seed: int) -> dict:
    """Mean and median of a − b over poses, with a 95 % interval of the mean from resampling objects."""
    from mjcodesign.evaluation.stats import cluster_bootstrap_mean

    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    iv = cluster_bootstrap_mean(d, objects, np.random.default_rng(seed), n_boot=DRAWS)
    return {"poses": int(len(d)), "objects": int(len(np.unique(objects))), "mean": iv.value,
            "median": float(np.median(d)), "low": iv.low, "high": iv.high, "positive": int(np.sum(d > 0))}  # fmt: skip


def _summary(v: np.ndarray) -> dict:
    q25, med, q75 = np.percentile(v, [25, 50, 75])
    return {"median": float(med), "iqr": [float(q25), float(q75)], "mean": float(v.mean())}


def evaluate(data, folds: dict[str, int], seed: int) -> dict:
    """Both models on every object fold held out (module docstring); the per-pose and per-row figures."""
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.surrogate.metrics import (
        cloud_statistics,
        soft_label_trees,
        success_head_metrics,
        tree_features,
    )
    from mjcodesign.surrogate.ranking import group_spearman, pose_groups
    from mjcodesign.surrogate.train import success_labels

    spans = np.array([(b.x0, b.x1) for b in FingerDesign().blocks()])
    stats = cloud_statistics(data.clouds)
    contact = contact_features(data.clouds, spans)
    obj_of_row = data.objects[data.pose]
    pred = {"base": np.full(len(data.pose), np.nan), "contact": np.full(len(data.pose), np.nan)}
    for k in sorted(set(folds.values())):
        held = np.isin(obj_of_row, [o for o, f in folds.items() if f == k])
        train, test = np.flatnonzero(~held), np.flatnonzero(held)
        if not len(test) or not len(train):
            continue
        p = success_labels(data, train)
        xb = [tree_features(data, r, stats) for r in (train, test)]
        xc = [contact_inputs(x, data.log_e[r], contact[data.pose[r]], data.openings[data.pose[r]])
              for x, r in zip(xb, (train, test), strict=True)]  # fmt: skip
        pred["base"][test] = soft_label_trees(xb[0], p, [xb[1]], seed)[0]
        pred["contact"][test] = soft_label_trees(xc[0], p, [xc[1]], seed)[0]
    rows = np.flatnonzero(np.isfinite(pred["base"]))
    label = success_labels(data, rows)
    groups, _ = pose_groups(data, rows)
    groups = [g for g in groups if np.ptp(label[g]) > 1e-12]
    rho = {name: group_spearman(v[rows], label, groups) for name, v in pred.items()}
    objects = np.array([str(obj_of_row[rows[g[0]]]) for g in groups])
    return {
        "poses_ranked": len(groups),
        "rows": int(len(rows)),
        "spearman": {name: _summary(v) for name, v in rho.items()},
        "contact_minus_base": paired(rho["contact"], rho["base"], objects, seed),
        "success": {
            name: {k: m[k] for k in ("roc_auc", "brier", "brier_p")}
            for name, v in pred.items()
            for m in [success_head_metrics(v[rows], data, rows)]
        },  # fmt: skip
    }


def main() -> None:
    """Parse the flags, compute, write the JSON and print it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--folds", default="5", help="object folds, each held out once (>= 2)")
    ap.add_argument("--seed", default="0")
    a = ap.parse_args()
    try:
        k, seed = int(a.folds), int(a.seed)
    except ValueError:
        k = seed = -1
    if k < 2 or seed < 0:
        _fail(f"--folds {a.folds!r} / --seed {a.seed!r}: give an integer >= 2 and one >= 0")
    from mjcodesign.bench.record import provenance
    from mjcodesign.errors import MjcodesignError
    from mjcodesign.surrogate.data import load_grasp_data

    t0 = time.perf_counter()
    try:
        d = load_grasp_data(a.data, perturbed=True)
    except (MjcodesignError, OSError) as exc:
        _fail(str(exc))  # the error names the path
    names = sorted({str(o) for o in d.objects[d.pose]})
    if len(names) < k:
        _fail(f"{a.data}: {len(names)} object(s), fewer than --folds {k}")
    folds = object_folds(names, k, seed)
    out = {"data": a.data, "folds": k, "seed": seed, "fold_of": folds, **evaluate(d, folds, seed)}
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    out["provenance"] = provenance(
        "ranking_contact",
        command=f"python3 scripts/ranking_contact.py --data {a.data} --out {a.out} --folds {k} --seed {seed}",
    )
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k not in ("provenance", "fold_of")}, indent=1))


if __name__ == "__main__":
    main()
