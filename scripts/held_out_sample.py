"""Write the shipped checkpoint's held-out rows (its object split's test objects) as a small .npz.

    python3 scripts/held_out_sample.py DATASET CKPT OUT.npz

The file holds what the network needs to predict each row (the poses' clouds, COM, world vertical and
volume; each row's pose, density and design) and what it is scored against (success, success_p), so a
test can recompute the held-out metrics recorded in the checkpoint without the dataset.
"""

import json
import sys
from pathlib import Path

import numpy as np

from mjcodesign.surrogate.data import load_grasp_data


def main(dataset: str, ckpt: str, out: str) -> None:
    """Write the held-out rows of checkpoint ``ckpt``'s dataset ``dataset`` to ``out``."""
    config = json.loads((Path(ckpt) / "config.json").read_text(encoding="utf-8"))
    held = set(config["split"]["test_objects"])
    data = load_grasp_data(dataset)
    if data.manifest_sha256 != config["dataset"]["manifest_sha256"]:
        raise SystemExit("the dataset is not the checkpoint's (manifest SHA-256 differs)")
    rows = np.flatnonzero([data.objects[p] in held for p in data.pose])
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


if __name__ == "__main__":
    main(*sys.argv[1:])
