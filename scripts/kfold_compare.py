"""A K-fold surrogate against gradient-boosted trees on every object, each scored by the fold that never saw it.

    python3 scripts/kfold_compare.py FOLDS_DIR DATASET [--seed 0] --out RECORD.json

``FOLDS_DIR`` is ``mjcodesign train --folds K --out FOLDS_DIR`` on ``DATASET``. For each fold this
rebuilds its split (the same objects, seed and validation fraction as the training) and predicts the
fold's held-out rows four ways (:data:`MODELS`): the checkpoint's success head; its calibrated success
score (its outputs through the success rule, Platt-mapped on the fold's validation rows); the trees'
classifier fitted on the fold's training rows; and the trees' regressed outputs through the same rule
and map. It pools the held-out rows of all folds: success ROC AUC and Brier score of each; per object
the Brier and AUC differences (surrogate − trees) with their paired bootstrap intervals over objects;
and the design-ranking Spearman per held-out pose (>= 8 designs, the measured p varying) of each and of
the design-only linear baseline, with the surrogate's paired differences over objects.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

MODELS = ("head", "score", "trees", "trees_score")
"""The success predictions compared: the surrogate's success head and its calibrated success score (the
paper's outputs through the success rule, Platt-mapped on the fold's validation rows), the trees'
classifier on the soft label and the trees' regressed outputs through the same rule and map."""


def compare(folds_dir: Path, dataset: str, seed: int = 0) -> dict:
    """The comparison of the module docstring."""
    from sklearn.metrics import roc_auc_score

    from mjcodesign.evaluation import paired_difference
    from mjcodesign.surrogate import load_surrogate
    from mjcodesign.surrogate.data import fold_splits, load_grasp_data
    from mjcodesign.surrogate.metrics import calibrated_success, tree_baseline, tree_success
    from mjcodesign.surrogate.ranking import linear_design_effect, ranking_fidelity
    from mjcodesign.surrogate.report import predict_rows, predict_success

    manifest = json.loads((folds_dir / "folds.json").read_text(encoding="utf-8"))
    data = load_grasp_data(dataset)
    if data.manifest_sha256 != manifest["dataset"]["manifest_sha256"]:
        raise SystemExit("kfold_compare: the dataset is not the folds' (manifest SHA-256 differs)")
    fold_of = {o: k for k, f in enumerate(manifest["folds"]) for o in f["held_out"]}
    splits = fold_splits(data, fold_of, seed=int(manifest["train"]["seed"]))
    rows, preds, per_fold, ranking = [], {m: [] for m in MODELS}, [], []
    for parts, entry in zip(splits, manifest["folds"], strict=True):
        if sorted(parts.test_objects) != sorted(entry["held_out"]):
            raise SystemExit(f"kfold_compare: {entry['path']}'s split does not rebuild")
        sur = load_surrogate(folds_dir / entry["path"])
        net, net_val = predict_rows(sur, data, parts.test), predict_rows(sur, data, parts.val)
        (t,) = tree_success(data, parts.train, [parts.test], seed=seed)
        tree, tree_val = tree_baseline(data, parts.train, [parts.test, parts.val], seed=seed)
        fold = {
            "head": predict_success(sur, data, parts.test),
            "score": calibrated_success(net, data, parts.test, net_val, parts.val),
            "trees": t,
            "trees_score": calibrated_success(tree, data, parts.test, tree_val, parts.val),
        }
        truth = data.success[parts.test].astype(float)
        val = data.success[parts.val]
        per_fold.append({"fold": entry["path"], "held_out": list(parts.test_objects), "rows": len(parts.test),
                         "platt_fitted": bool(0 < val.sum() < len(val)),
                         **{m: _scores(truth, fold[m], roc_auc_score) for m in MODELS}})  # fmt: skip
        lin = linear_design_effect(data, parts.train, parts.test)
        ranking += ranking_fidelity({**fold, "linear": lin}, data, parts.test)["per_pose"]
        rows.append(parts.test)
        for m in MODELS:
            preds[m].append(fold[m])
    rows = np.concatenate(rows)
    preds = {m: np.concatenate(v) for m, v in preds.items()}
    truth = data.success[rows].astype(float)
    objects = np.array([str(data.objects[p]) for p in data.pose[rows]])
    names = sorted(set(objects))
    brier = {m: np.array([np.mean((p[objects == o] - truth[objects == o]) ** 2) for o in names])
             for m, p in preds.items()}  # fmt: skip
    diffs = {f"brier_{a}_minus_{b}": paired_difference(brier[a], brier[b], names=(a, b), seed=seed).as_dict()
             for a in ("head", "score") for b in ("trees", "trees_score")}  # fmt: skip
    return {
        "folds": per_fold,
        "pooled": {
            "objects": len(names),
            "rows": int(len(rows)),
            **{m: _scores(truth, preds[m], roc_auc_score) for m in MODELS},
            **diffs,
            "auc_per_object": _auc_per_object(truth, preds, objects, names, seed),
        },
        "ranking": _ranking_summary(ranking, seed),
    }


def _auc_per_object(truth, preds, objects, names, seed) -> dict:
    """Per object with both outcomes, the AUC of each prediction; the surrogate's minus the trees' over them."""
    from sklearn.metrics import roc_auc_score

    from mjcodesign.evaluation import paired_difference

    both = [o for o in names if 0 < truth[objects == o].sum() < np.sum(objects == o)]
    auc = {
        m: np.array([roc_auc_score(truth[objects == o], p[objects == o]) for o in both])
        for m, p in preds.items()
    }
    out = {"objects": len(both), **{m: float(np.mean(v)) for m, v in auc.items()}}
    for a in ("head", "score"):
        for b in ("trees", "trees_score"):
            out[f"{a}_minus_{b}"] = paired_difference(auc[a], auc[b], names=(a, b), seed=seed).as_dict()
    return out


def _scores(truth: np.ndarray, p: np.ndarray, auc) -> dict:
    """ROC AUC (None where the rows hold one outcome only) and Brier score of ``p`` against ``truth``."""
    both = 0 < truth.sum() < len(truth)
    return {"roc_auc": float(auc(truth, p)) if both else None, "brier": float(np.mean((p - truth) ** 2))}


def _ranking_summary(per_pose: list[dict], seed: int) -> dict:
    """Medians over the ranked poses; the head's paired differences over objects (per-object means)."""
    from mjcodesign.evaluation import paired_difference

    models = (*MODELS, "linear")
    out = {"poses": len(per_pose), "objects": len({p["object"] for p in per_pose})}
    if not per_pose:  # no held-out pose with enough designs and a varying measured p
        return out
    for m in models:
        v = np.array([p[m] for p in per_pose])
        out[m] = {"median": float(np.median(v)), "mean": float(v.mean()), "positive": int(np.sum(v > 0))}
    names = sorted({p["object"] for p in per_pose})
    mean = {
        m: np.array([np.mean([p[m] for p in per_pose if p["object"] == o]) for o in names]) for m in models
    }
    for mine in ("head", "score"):
        for other in ("trees", "trees_score", "linear"):
            out[f"{mine}_minus_{other}"] = paired_difference(
                mean[mine], mean[other], names=(mine, other), seed=seed
            ).as_dict()
    return out


def main() -> int:
    """Command line of the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folds", help="a train --folds output folder (folds.json, foldK/)")
    ap.add_argument("dataset", help="the dataset it was trained on")
    ap.add_argument("--seed", type=int, default=0, help="the trees' and the bootstrap's seed")
    ap.add_argument("--out", required=True, help="the record (JSON)")
    a = ap.parse_args()
    from mjcodesign.bench.record import provenance

    rec = {"provenance": provenance("kfold_compare", command=" ".join(["python3", *sys.argv])),
           **compare(Path(a.folds), a.dataset, a.seed)}  # fmt: skip
    Path(a.out).write_text(json.dumps(rec, indent=1) + "\n", encoding="utf-8")
    p, r = rec["pooled"], rec["ranking"]
    print(f"pooled over {p['objects']} objects: " + "; ".join(
        f"{m} AUC {p[m]['roc_auc']:.3f} Brier {p[m]['brier']:.3f}" for m in MODELS), file=sys.stderr)  # fmt: skip
    if r["poses"]:
        print(f"ranking over {r['poses']} poses, medians: " + ", ".join(
            f"{m} {r[m]['median']:.2f}" for m in (*MODELS, "linear")), file=sys.stderr)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
