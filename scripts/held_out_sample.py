"""Write the shipped checkpoint's held-out rows (its object split's test objects) as a small .npz.

    python3 scripts/held_out_sample.py DATASET CKPT OUT.npz [--poses-per-object N]

The file holds what the network needs to predict each row (the poses' clouds, COM, world vertical and
volume; each row's pose, density and design) and what it is scored against (success, success_p), so a
test can recompute the held-out metrics without the dataset. With ``--poses-per-object N`` it keeps the
first N poses of each held-out object (a sample small enough to ship as a test fixture) and prints the
metrics the checkpoint gives on that sample, for the weights' card.
"""

import argparse
import json
from pathlib import Path

import numpy as np

from mjcodesign.surrogate.data import load_grasp_data


def _first_poses(data, held: set, n: int | None) -> np.ndarray:
    """Rows of the held-out objects, restricted to each object's first ``n`` poses when ``n`` is given."""
    keep = set()
    for name in sorted(held):
        poses = np.flatnonzero(data.objects == name)
        keep.update(int(p) for p in (poses if n is None else poses[:n]))
    return np.flatnonzero(np.isin(data.pose, sorted(keep)))


def sample_metrics(ckpt: str, sample: str) -> dict:
    """The checkpoint's success AUC and Brier score on the rows of ``sample`` (a file this script wrote)."""
    from sklearn.metrics import roc_auc_score

    from mjcodesign.surrogate import load_surrogate
    from mjcodesign.surrogate.inference import GraspBatch, Poses

    with np.load(sample, allow_pickle=False) as z:
        s = {k: z[k] for k in z.files}
    pred = load_surrogate(ckpt).predict(
        GraspBatch(Poses(s["clouds"], s["com"], s["up"], s["volume"]), s["pose"], s["density"], s["log_e"])
    )
    truth = s["success"].astype(float)
    return {
        "rows": len(truth),
        "head_auc": float(roc_auc_score(truth, pred.success_p)),
        "head_brier": float(np.mean((pred.success_p - truth) ** 2)),
        "score_auc": float(roc_auc_score(truth, pred.success_score)),
    }


def main(dataset: str, ckpt: str, out: str, poses_per_object: int | None = None) -> None:
    """Write the held-out rows of checkpoint ``ckpt``'s dataset ``dataset`` to ``out``."""
    config = json.loads((Path(ckpt) / "config.json").read_text(encoding="utf-8"))
    held = set(config["split"]["test_objects"])
    data = load_grasp_data(dataset)
    if data.manifest_sha256 != config["dataset"]["manifest_sha256"]:
        raise SystemExit("the dataset is not the checkpoint's (manifest SHA-256 differs)")
    rows = _first_poses(data, held, poses_per_object)
    poses, pose = np.unique(data.pose[rows], return_inverse=True)
    np.savez_compressed(
        out,
        clouds=data.clouds[poses].astype(np.float32),
        com=data.com[poses],
        up=data.up[poses],
        volume=data.poses.volume[poses],
        objects=np.array([str(n) for n in data.objects[poses]]),
        pose=pose.astype(np.int64),
        density=data.density[rows],
        log_e=data.log_e[rows],
        success=data.success[rows],
        success_p=data.success_p[rows],
        manifest_sha256=np.array(data.manifest_sha256),
    )
    print(f"{len(rows)} rows over {len(poses)} poses of {len(held)} objects -> {out}")
    m = sample_metrics(ckpt, out)
    print(
        f"on these rows: head AUC {m['head_auc']:.4f}, Brier {m['head_brier']:.4f}; score AUC {m['score_auc']:.4f}"
    )


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("ckpt")
    ap.add_argument("out")
    ap.add_argument(
        "--poses-per-object", type=int, default=None, help="keep each held-out object's first N poses"
    )
    a = ap.parse_args()
    main(a.dataset, a.ckpt, a.out, a.poses_per_object)
