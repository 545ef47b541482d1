"""Whether fine-tuning a surrogate on a user's small dataset (``train --init``) helps on the user's objects.

A base surrogate is trained on a base dataset (``train``'s default object split). The user's dataset
holds other objects, none in the base. Two questions, each measured on rows no network trained on:

* **new poses of the user's objects** (what ``design --adapt`` relies on): per user object, its even
  poses are the adaptation set (a fifth of them, at least one pose, the validation), its odd poses the
  test;
* **other new objects**: the user's objects in two halves; fine-tuned on one half (all its poses), tested
  on the other half.

Against the base network as it is (zero-shot) and a network of the same architecture trained from
scratch on the adaptation rows alone, over ``--seeds``. Metrics on the test rows: success ROC AUC and
accuracy (score > 0), MAE of the vertical force [N] and the displacement norm [mm], and the loss on the
base network's normaliser (one scale for all). Prints and writes one JSON record with provenance.

    nice -n 10 python3 scripts/finetune_experiment.py --base BASE_DS --user USER_DS --out record.json

Not part of the package: the record of ``benchmarks/records/*_finetune.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def _parse() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", required=True, help="base dataset folder")
    p.add_argument("--user", required=True, help="the user's dataset folder (other objects)")
    p.add_argument("--out", required=True, help="record file (JSON)")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--epochs", type=int, default=100)
    p.add_argument("--patience", type=int, default=20)
    p.add_argument("--lr", default="1e-3,1e-4", help="fine-tuning learning rates (comma-separated)")
    p.add_argument("--threads", type=int, default=1)
    return p.parse_args()


def _parts(data, train_poses, val_poses, test_poses, mode):
    from mjcodesign.surrogate import Split

    def rows(poses):
        return np.flatnonzero(np.isin(data.pose, np.asarray(sorted(poses), dtype=int)))

    return Split(mode, rows(train_poses), rows(val_poses), rows(test_poses))


def _pose_halves(data, objects):
    """Per object: even poses (adaptation: a fifth of them, >= 1, validation) and odd poses (test)."""
    tr, va, te = [], [], []
    for name in objects:
        poses = sorted(np.flatnonzero(data.objects == name))
        adapt, test = poses[0::2], poses[1::2]
        n_val = max(1, round(0.2 * len(adapt)))
        va += adapt[:n_val]
        tr += adapt[n_val:]
        te += test
    return tr, va, te


def _object_halves(data, train_objects, test_objects):
    """All poses of ``train_objects`` (a fifth of each object's poses the validation); ``test_objects``' poses."""
    tr, va = [], []
    for name in train_objects:
        poses = sorted(np.flatnonzero(data.objects == name))
        n_val = max(1, round(0.2 * len(poses)))
        va += poses[:n_val]
        tr += poses[n_val:]
    te = [int(p) for name in test_objects for p in np.flatnonzero(data.objects == name)]
    return tr, va, te


def _score(sur, data, parts, base_norm) -> dict:
    from mjcodesign.surrogate.metrics import score_outputs
    from mjcodesign.surrogate.report import predict_rows, standard_loss

    pred, val = predict_rows(sur, data, parts.test), predict_rows(sur, data, parts.val)
    s = score_outputs(pred, data, parts.test, val, parts.val)
    y = data.outputs[parts.test]
    return {
        "success_roc_auc": s["success"]["roc_auc"],
        "success_accuracy": s["success"]["accuracy"],
        "mae_force_z_n": float(np.mean(np.abs(pred[:, 5] - y[:, 5]))),
        "mae_displacement_mm": 1e3 * float(np.mean(np.linalg.norm(pred[:, 6:9] - y[:, 6:9], axis=1))),
        "loss_base_scale": standard_loss(pred, data, parts.test, base_norm)["loss"],
    }


def main() -> int:
    """Run the experiment; write and print the record."""
    import torch

    from mjcodesign.bench.record import provenance
    from mjcodesign.surrogate import OptimizerConfig, Surrogate, TrainConfig, load_grasp_data, split, train

    args = _parse()
    torch.set_num_threads(args.threads)
    seeds = [int(s) for s in args.seeds.split(",")]
    lrs = [float(v) for v in args.lr.split(",")]
    base_data, user = load_grasp_data(args.base), load_grasp_data(args.user)
    overlap = set(base_data.objects) & set(user.objects)
    if overlap:
        sys.exit(f"the user's dataset shares objects with the base: {sorted(overlap)}")

    def cfg(seed, lr=1e-3):
        return TrainConfig(epochs=args.epochs, early_stop_patience=args.patience, seed=seed,
                           optimizer=OptimizerConfig(lr=lr))  # fmt: skip

    def wrap(res, data):
        return Surrogate(res.model, res.normalizer, lift=data.lift, lifted_fraction=data.lifted_fraction)

    t0 = time.perf_counter()
    base_res = train(base_data, split(base_data, "object", seed=0), cfg(0))
    base = wrap(base_res, base_data)
    norm = base_res.normalizer
    objects = sorted(set(user.objects))
    half = len(objects) // 2
    setups = {"new_poses": [_parts(user, *_pose_halves(user, objects), "new_poses")]}
    setups["new_objects"] = [
        _parts(user, *_object_halves(user, objects[:half], objects[half:]), "new_objects_a"),
        _parts(user, *_object_halves(user, objects[half:], objects[:half]), "new_objects_b"),
    ]
    results: dict = {}
    for name, parts_list in setups.items():
        runs = []
        for parts in parts_list:
            entry = {"split": parts.mode, "adapt_rows": len(parts.train), "val_rows": len(parts.val),
                     "test_rows": len(parts.test), "zero_shot": _score(base, user, parts, norm)}  # fmt: skip
            for seed in seeds:
                for lr in lrs:
                    ft = train(user, parts, cfg(seed, lr), init=(base.model, base.normalizer))
                    entry.setdefault(f"fine_tuned_lr{lr:g}", []).append(
                        {"seed": seed, "epochs": len(ft.history), **_score(wrap(ft, user), user, parts, norm)}
                    )
                sc = train(user, parts, cfg(seed), base.config)
                entry.setdefault("scratch", []).append(
                    {"seed": seed, "epochs": len(sc.history), **_score(wrap(sc, user), user, parts, norm)}
                )
            runs.append(entry)
            print(json.dumps(entry), file=sys.stderr, flush=True)
        results[name] = runs
    record = {
        "provenance": provenance("finetune", command=" ".join(sys.argv)),
        "record": {
            "base": {"dataset": str(base_data.root), "samples": len(base_data), "objects": sorted(set(base_data.objects)),
                     "epochs": len(base_res.history), "model": base.config.as_dict()},
            "user": {"dataset": str(user.root), "samples": len(user), "objects": objects,
                     "success_rate": float(np.mean(user.success))},
            "seeds": seeds, "fine_tune_lr": lrs, "epochs": args.epochs, "patience": args.patience,
            "normalizer": "fine-tuning keeps the base checkpoint's normaliser; scratch fits its own",
            "results": results, "wall_s": time.perf_counter() - t0,
        },
    }  # fmt: skip
    text = json.dumps(record, indent=1, allow_nan=False)
    with open(args.out, "w", encoding="utf-8") as f:
        f.write(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
