"""Compare checkpoints' design-ranking fidelity on the same held-out poses, paired, with object-bootstrap intervals.

Reads each checkpoint's report (``metrics.json`` of ``mjcodesign train``): its per-pose Spearman of the
success head (else the score) and of the design-only linear baseline, on the poses its split held out.
Checkpoints of one split share their poses; the script pairs them pose by pose against the first
(the reference) and against the linear baseline, and resamples the held-out objects (2,000 draws) for a
95 % interval of the mean paired difference. Also the held-out success AUC and Brier of each head.

    python3 scripts/ranking_compare.py --ref real_lc/n20 --ckpt rank/r1 --ckpt rank/r4 --out cmp.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

LINEAR = "linear design effect (training rows)"
DRAWS = 2000


def _per_pose(metrics: dict) -> tuple[dict, dict]:
    """(pose_row -> (object, head rho), pose_row -> linear rho or absent)."""
    rows = metrics["ranking"]["per_pose"]
    key = "surrogate (head)" if rows and "surrogate (head)" in rows[0] else "surrogate (score)"
    head = {q["pose_row"]: (q["object"], q[key]) for q in rows}
    lin = {q["pose_row"]: q[LINEAR] for q in rows if LINEAR in q}
    return head, lin


def _paired(a: dict, b: dict, objects: dict, rng) -> dict:
    """Mean and median of a - b over their shared poses, with an object-bootstrap 95 % interval of the mean."""
    from mjcodesign.evaluation.stats import cluster_bootstrap_mean

    poses = sorted(set(a) & set(b))
    d = np.array([a[p] - b[p] for p in poses])
    iv = cluster_bootstrap_mean(d, np.array([objects[p] for p in poses]), rng, n_boot=DRAWS)
    return {
        "poses": len(poses),
        "mean": iv.value,
        "median": float(np.median(d)),
        "mean_95ci": [iv.low, iv.high],
    }


def _head_metrics(m: dict) -> dict:
    s = m["test"]["surrogate"]
    h = s.get("success_head") or s["success"]
    return {"head_auc": h["roc_auc"], "head_brier": h["brier"], "score_auc": s["success"]["roc_auc"],
            "train_config": {k: m["train_config"].get(k) for k in ("seed", "rank_weight", "success_weight")}}  # fmt: skip


def main() -> None:
    """Parse the flags, compute, write the JSON and print it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref", required=True, help="reference checkpoint folder")
    ap.add_argument("--ckpt", action="append", default=[], help="checkpoint folder to compare (repeat)")
    ap.add_argument(
        "--linear-from",
        default=None,
        help="checkpoint whose report holds the linear baseline of the reference's split (default: the first --ckpt that has it)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    ms = {p: json.loads((Path(p) / "metrics.json").read_text()) for p in [a.ref, *a.ckpt]}
    heads = {p: _per_pose(m)[0] for p, m in ms.items()}
    lins = {p: _per_pose(m)[1] for p, m in ms.items()}
    src = a.linear_from or next((p for p in [a.ref, *a.ckpt] if lins[p]), None)
    lin = lins[src] if src else {}
    objects = {r: o for h in heads.values() for r, (o, _) in h.items()}
    val = {p: {r: v for r, (_, v) in h.items()} for p, h in heads.items()}
    out = {"reference": a.ref, "linear_from": src, "draws": DRAWS, "checkpoints": {}}
    for p in [a.ref, *a.ckpt]:
        e = {**_head_metrics(ms[p]), "median": float(np.median(list(val[p].values()))), "poses": len(val[p])}
        if p != a.ref:
            e["minus_reference"] = _paired(val[p], val[a.ref], objects, rng)
        if lin:
            e["minus_linear"] = _paired(val[p], lin, objects, rng)
        out["checkpoints"][p] = e
    if lin:
        out["linear_median"] = float(np.median([lin[r] for r in val[a.ref] if r in lin]))
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
