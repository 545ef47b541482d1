"""Where a dataset's design-ranking signal lives: shared by all poses, by an object's poses, or one pose's own.

    python3 scripts/ranking_sources.py --data DIR --out FILE.json

For every pose of a perturbed dataset whose measured success_p varies over its designs (at least
:data:`~mjcodesign.surrogate.ranking.MIN_DESIGNS`), the Spearman over its designs between success_p and

- one design summary each (mean ln E of all blocks, of the flexures, of the segments, of the base and
  tip halves): a preference shared by every pose, not fitted;
- :func:`~mjcodesign.surrogate.ranking.linear_design_effect` fitted on the poses of the *other*
  objects (what a surrogate must do for an unseen object, with a linear design-only model);
- the same fitted on the *other poses of the same object* (what knowing the object adds).

If the second beats the third, what transfers is a preference shared across objects, and a pose's
ranking beyond it is its own (grasp-specific), so more objects help more than more poses per object.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def _summary(values) -> dict:
    v = np.asarray([x for x in values if np.isfinite(x)])
    q25, med, q75 = np.percentile(v, [25, 50, 75])
    return {"poses": int(len(v)), "median": float(med), "iqr": [float(q25), float(q75)], "mean": float(v.mean()),
            "positive": int(np.sum(v > 0))}  # fmt: skip


def main() -> None:
    """Parse the flags, compute, write the JSON and print it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    from mjcodesign.bench.record import provenance
    from mjcodesign.surrogate.data import load_grasp_data
    from mjcodesign.surrogate.ranking import group_spearman, linear_design_effect, pose_groups

    t0 = time.perf_counter()
    d = load_grasp_data(a.data)
    if d.success_p is None:
        raise SystemExit(
            f"{a.data}: one rollout per cell; this needs a perturbed dataset (datagen --perturbations)"
        )
    rows = np.arange(len(d.pose))
    groups, _ = pose_groups(d, rows)
    obj = np.array([str(d.objects[d.pose[g[0]]]) for g in groups])
    varying = [i for i, g in enumerate(groups) if np.ptp(d.success_p[g]) > 1e-12]
    flex = [1, 3, 5, 7, 9, 12, 14, 16, 18, 20]
    seg = [i for i in range(22) if i not in flex]
    base = [0, 1, 2, 3, 4, 5, 11, 12, 13, 14, 15, 16]
    tip = [i for i in range(22) if i not in base]
    summaries = {
        "mean ln E": list(range(22)),
        "flexures": flex,
        "segments": seg,
        "base half": base,
        "tip half": tip,
    }
    out: dict = {"data": a.data, "poses": len(groups), "varying_poses": len(varying), "fixed_preference": {}}
    for name, cols in summaries.items():
        rho = group_spearman(d.log_e[:, cols].mean(axis=1), d.success_p, [groups[i] for i in varying])
        out["fixed_preference"][f"{name} (stiffer ranks higher)"] = _summary(rho)
    other, same = [], []
    for i in varying:
        g = groups[i]
        for keep, into in ((obj != obj[i], other), ((obj == obj[i]) & (np.arange(len(groups)) != i), same)):
            train = np.concatenate([groups[j] for j in np.flatnonzero(keep)])
            score = linear_design_effect(d, train, g)
            into.append(group_spearman(score, d.success_p[g], [np.arange(len(g))])[0])
    out["linear_design_effect"] = {"fitted_on_other_objects": _summary(other),
                                   "fitted_on_the_same_objects_other_poses": _summary(same)}  # fmt: skip
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    out["provenance"] = provenance(
        "ranking_sources", command=f"python3 scripts/ranking_sources.py --data {a.data} --out {a.out}"
    )
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k != "provenance"}, indent=1))


if __name__ == "__main__":
    main()
