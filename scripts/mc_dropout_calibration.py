"""Is a checkpoint's Monte Carlo dropout spread an uncertainty? Measured on its held-out rows.

    python3 scripts/mc_dropout_calibration.py --ckpt DIR --data DIR [--samples 16] --out FILE.json

Reads the success head K times with dropout on (:func:`mjcodesign.surrogate.inference.dropout_draws`)
on the rows of the checkpoint's held-out objects, and reports: the held-out ROC AUC and Brier score of
the deterministic head and of the draws' mean; the Spearman of the draws' standard deviation against
the mean's absolute error on ``success_p``, beside that of the Bernoulli spread sqrt(p (1 − p)) of the
mean itself (what any probability "knows" of its error); and the same Spearman within bins of the mean
(0–0.2, …, 0.8–1), where p alone cannot explain it. An uncertainty worth penalising ranks the errors
within a bin. And the design ranking (:func:`~mjcodesign.surrogate.ranking.ranking_fidelity`) of the
mean and of mean ∓ std.

With ``--member CKPT`` (repeatable; checkpoints of the same dataset and held-out objects, e.g. ``train
--split-seed 0 --seed 1``) the draws are the deterministic heads of ``--ckpt`` and the members instead:
an ensemble's mean and spread, measured the same way.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

BINS = (0.2, 0.4, 0.6, 0.8)
MIN_BIN = 30  # rows a bin needs for its Spearman to be reported


def main() -> None:
    """Parse the flags, measure, write the JSON and print it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ckpt", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--member", action="append", default=[], help="ensemble member checkpoint (repeat)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    import torch
    from scipy.stats import spearmanr
    from sklearn.metrics import roc_auc_score

    from mjcodesign.bench.record import provenance
    from mjcodesign.surrogate import load_surrogate
    from mjcodesign.surrogate.data import load_grasp_data
    from mjcodesign.surrogate.inference import dropout_draws
    from mjcodesign.surrogate.ranking import ranking_fidelity
    from mjcodesign.surrogate.report import predict_success

    torch.set_num_threads(1)
    d = load_grasp_data(a.data)
    held = set(json.loads((Path(a.ckpt) / "metrics.json").read_text())["split"]["test_objects"])
    rows = np.array([i for i in range(len(d.pose)) if str(d.objects[d.pose[i]]) in held])
    sur = load_surrogate(a.ckpt)
    p0 = predict_success(sur, d, rows)
    if a.member:
        for m in a.member:
            theirs = json.loads((Path(m) / "metrics.json").read_text())["split"]["test_objects"]
            if set(theirs) != held:
                raise SystemExit(f"{m} holds out other objects than {a.ckpt}")
        draws = np.array([p0, *(predict_success(load_surrogate(m), d, rows) for m in a.member)])
    else:
        with dropout_draws(sur.model, a.seed):
            draws = np.array([predict_success(sur, d, rows) for _ in range(a.samples)])
    mean, std = draws.mean(axis=0), draws.std(axis=0)
    y, label = d.success[rows], d.success_p[rows]
    err = np.abs(mean - label)
    bins = np.digitize(mean, BINS)
    within = []
    for b in range(len(BINS) + 1):
        s = bins == b
        if s.sum() >= MIN_BIN:
            within.append(
                {
                    "bin": b,
                    "rows": int(s.sum()),
                    "spearman_std_err": float(spearmanr(std[s], err[s]).correlation),
                    "spearman_bernoulli_err": float(
                        spearmanr(np.sqrt(mean[s] * (1 - mean[s])), err[s]).correlation
                    ),
                }
            )
    rank = ranking_fidelity(
        {"deterministic": p0, "mean": mean, "mean - std": mean - std, "mean + std": mean + std}, d, rows
    )
    out = {
        "ckpt": a.ckpt, "data": a.data, "rows": len(rows), "samples": len(draws), "members": a.member,
        "deterministic": {"roc_auc": float(roc_auc_score(y, p0)), "brier": float(np.mean((p0 - y) ** 2))},
        "mc_mean": {"roc_auc": float(roc_auc_score(y, mean)), "brier": float(np.mean((mean - y) ** 2))},
        "std_median": float(np.median(std)),
        "spearman_std_err": float(spearmanr(std, err).correlation),
        "spearman_bernoulli_err": float(spearmanr(np.sqrt(mean * (1 - mean)), err).correlation),
        "within_mean_bins": within,
        "ranking_median": {k: v["median"] for k, v in rank["models"].items()},
        "provenance": provenance("mc_dropout_calibration", command=" ".join(["python3", "scripts/mc_dropout_calibration.py", *sys.argv[1:]])),
    }  # fmt: skip
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k != "provenance"}, indent=1))


if __name__ == "__main__":
    main()
