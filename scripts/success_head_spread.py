"""How firm the success head's loss to the trees is: other training seeds, and a bootstrap over held-out objects.

On a dataset's object split (``train``'s default, split seed 0), the trees' success classifier
(:func:`~mjcodesign.surrogate.metrics.tree_success`) against the success head of checkpoint ``--ckpt``
and of networks trained here with other weight seeds (same split, epochs and settings). Per network:
held-out ROC AUC, Brier score, the design-ranking median, and a paired bootstrap over the held-out
objects (resampled with replacement, ``--draws`` times) of AUC(head) − AUC(trees) and Brier(head) −
Brier(trees), as 95 % percentile intervals. Prints and writes one JSON.

    nice -n 10 python3 scripts/success_head_spread.py --data DS --ckpt CKPT --seeds 1,2 --out spread.json

Not part of the package: the ``spread`` of ``benchmarks/records/*_success_head.json``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

_EPOCHS = 60  # the checkpoint's (real_s2's) epochs


def _bootstrap(p, tree_p, truth, obj, draws: int, rng) -> dict:
    from sklearn.metrics import roc_auc_score

    names = np.unique(obj)
    members = {n: np.flatnonzero(obj == n) for n in names}
    dauc, dbrier = [], []
    for _ in range(draws):
        idx = np.concatenate([members[n] for n in rng.choice(names, size=len(names), replace=True)])
        if 0 < truth[idx].sum() < len(idx):
            dauc.append(roc_auc_score(truth[idx], p[idx]) - roc_auc_score(truth[idx], tree_p[idx]))
            dbrier.append(np.mean((p[idx] - truth[idx]) ** 2) - np.mean((tree_p[idx] - truth[idx]) ** 2))
    return {"auc_minus_trees_95ci": np.percentile(dauc, [2.5, 97.5]).tolist(),
            "brier_minus_trees_95ci": np.percentile(dbrier, [2.5, 97.5]).tolist()}  # fmt: skip


def main() -> None:
    """Parse the flags, train the other seeds, measure, print and write the JSON."""
    import torch

    from mjcodesign.surrogate import (
        ModelConfig,
        Surrogate,
        TrainConfig,
        load_grasp_data,
        load_surrogate,
        split,
        train,
    )
    from mjcodesign.surrogate.metrics import success_head_metrics, tree_success
    from mjcodesign.surrogate.ranking import ranking_fidelity
    from mjcodesign.surrogate.report import predict_success

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument(
        "--ckpt", required=True, help="a checkpoint with a success head, trained on --data (seed 0)"
    )
    ap.add_argument("--seeds", default="1,2", help="other weight seeds to train")
    ap.add_argument("--draws", type=int, default=2000)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    data = load_grasp_data(args.data)
    parts = split(data, "object", seed=0)
    rows = parts.test
    (tree_p,) = tree_success(data, parts.train, [rows], seed=0)
    heads = {"checkpoint": predict_success(load_surrogate(args.ckpt), data, rows)}
    for seed in (int(s) for s in args.seeds.split(",") if s):
        res = train(data, parts, TrainConfig(epochs=_EPOCHS, seed=seed), ModelConfig(success_head=True))
        sur = Surrogate(res.model, res.normalizer, lift=data.lift, lifted_fraction=data.lifted_fraction)
        heads[f"weight seed {seed}"] = predict_success(sur, data, rows)
    truth, obj = data.success[rows], data.objects[data.pose[rows]]
    rng = np.random.default_rng(0)
    out = {"split": parts.as_dict(), "trees_classifier": {}, "heads": {}}
    for name, p in {"trees_classifier": tree_p, **heads}.items():
        m = {k: v for k, v in success_head_metrics(p, data, rows).items() if k != "calibration"}
        m["ranking_median"] = ranking_fidelity({"p": p}, data, rows)["models"]["p"]["median"]
        if name != "trees_classifier":
            m.update(_bootstrap(p, tree_p, truth, obj, args.draws, rng))
            out["heads"][name] = m
        else:
            out[name] = m
        print(name, json.dumps(m), flush=True)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
