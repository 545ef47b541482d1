"""A K-fold surrogate against gradient-boosted trees on every object, each scored by the fold that never saw it.

    python3 scripts/kfold_compare.py FOLDS_DIR DATASET [--seed 0] --out RECORD.json

``FOLDS_DIR`` is ``mjcodesign train --folds K --out FOLDS_DIR`` on ``DATASET``. For each fold this
rebuilds its split (the same objects, seed and validation fraction as the training), predicts the fold's
held-out rows with its checkpoint's success head, fits the trees' classifier and the design-only linear
baseline on the fold's training rows, and pools the held-out rows of all folds: success ROC AUC and
Brier score of the head and the trees; per object the Brier difference (head − trees) with its paired
bootstrap interval over objects; and the design-ranking Spearman per held-out pose (>= 8 designs, the
measured p varying) of the head, the trees and the linear baseline, with the head's paired differences
over objects.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def compare(folds_dir: Path, dataset: str, seed: int = 0) -> dict:
    """The comparison of the module docstring."""
    from sklearn.metrics import roc_auc_score

    from mjcodesign.evaluation import paired_difference
    from mjcodesign.surrogate import load_surrogate
    from mjcodesign.surrogate.data import fold_splits, load_grasp_data
    from mjcodesign.surrogate.metrics import tree_success
    from mjcodesign.surrogate.ranking import linear_design_effect, ranking_fidelity
    from mjcodesign.surrogate.report import predict_success

    manifest = json.loads((folds_dir / "folds.json").read_text(encoding="utf-8"))
    data = load_grasp_data(dataset)
    if data.manifest_sha256 != manifest["dataset"]["manifest_sha256"]:
        raise SystemExit("kfold_compare: the dataset is not the folds' (manifest SHA-256 differs)")
    fold_of = {o: k for k, f in enumerate(manifest["folds"]) for o in f["held_out"]}
    splits = fold_splits(data, fold_of, seed=int(manifest["train"]["seed"]))
    rows, head, trees, per_fold, ranking = [], [], [], [], []
    for parts, entry in zip(splits, manifest["folds"], strict=True):
        if sorted(parts.test_objects) != sorted(entry["held_out"]):
            raise SystemExit(f"kfold_compare: {entry['path']}'s split does not rebuild")
        h = predict_success(load_surrogate(folds_dir / entry["path"]), data, parts.test)
        (t,) = tree_success(data, parts.train, [parts.test], seed=seed)
        lin = linear_design_effect(data, parts.train, parts.test)
        truth = data.success[parts.test].astype(float)
        per_fold.append({"fold": entry["path"], "held_out": list(parts.test_objects), "rows": len(parts.test),
                         "head": _scores(truth, h, roc_auc_score), "trees": _scores(truth, t, roc_auc_score)})  # fmt: skip
        r = ranking_fidelity({"head": h, "trees": t, "linear": lin}, data, parts.test)
        ranking += r["per_pose"]
        rows.append(parts.test)
        head.append(h)
        trees.append(t)
    rows, head, trees = np.concatenate(rows), np.concatenate(head), np.concatenate(trees)
    truth = data.success[rows].astype(float)
    objects = np.array([str(data.objects[p]) for p in data.pose[rows]])
    names = sorted(set(objects))
    brier = {m: np.array([np.mean((p[objects == o] - truth[objects == o]) ** 2) for o in names])
             for m, p in (("head", head), ("trees", trees))}  # fmt: skip
    return {
        "folds": per_fold,
        "pooled": {
            "objects": len(names),
            "rows": int(len(rows)),
            "head": _scores(truth, head, roc_auc_score),
            "trees": _scores(truth, trees, roc_auc_score),
            "brier_head_minus_trees": paired_difference(
                brier["head"], brier["trees"], names=("head", "trees"), seed=seed
            ).as_dict(),
        },  # fmt: skip
        "ranking": _ranking_summary(ranking, seed),
    }


def _scores(truth: np.ndarray, p: np.ndarray, auc) -> dict:
    """ROC AUC (None where the rows hold one outcome only) and Brier score of ``p`` against ``truth``."""
    both = 0 < truth.sum() < len(truth)
    return {"roc_auc": float(auc(truth, p)) if both else None, "brier": float(np.mean((p - truth) ** 2))}


def _ranking_summary(per_pose: list[dict], seed: int) -> dict:
    """Medians over the ranked poses; the head's paired differences over objects (per-object means)."""
    from mjcodesign.evaluation import paired_difference

    models = ("head", "trees", "linear")
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
    for other in ("trees", "linear"):
        out[f"head_minus_{other}"] = paired_difference(
            mean["head"], mean[other], names=("head", other), seed=seed
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
    print(f"pooled over {p['objects']} objects: head AUC {p['head']['roc_auc']:.3f} Brier {p['head']['brier']:.3f}; "
          f"trees AUC {p['trees']['roc_auc']:.3f} Brier {p['trees']['brier']:.3f}", file=sys.stderr)  # fmt: skip
    if r["poses"]:
        print(f"ranking over {r['poses']} poses, medians: head {r['head']['median']:.2f}, trees "
              f"{r['trees']['median']:.2f}, linear {r['linear']['median']:.2f}", file=sys.stderr)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
