"""Where a dataset's design-ranking signal lives: shared by all poses, by an object's poses, or one pose's own.

    python3 scripts/ranking_sources.py --data DIR --out FILE.json

For every pose of a perturbed dataset whose measured success_p varies over its designs (at least
:data:`~mjcodesign.surrogate.ranking.MIN_DESIGNS`), the Spearman over its designs between success_p and

- one design summary each (mean ln E of all blocks, of the flexures, of the segments, of the base and
  tip halves): a preference shared by every pose, not fitted;
- :func:`~mjcodesign.surrogate.ranking.linear_design_effect` fitted on the poses of the *other*
  objects (what a surrogate must do for an unseen object, with a linear design-only model);
- the same fitted on the *other poses of the same object* (what knowing the object adds);
- the same fitted on the ``--nearest`` K poses of the same object closest to the pose (palm position
  in metres plus :data:`ANGLE_SCALE` times the palm's rotation angle in radians), and on the K farthest
  as the control: whether a ranking is shared by neighbouring grasps at the dataset's pose spacing.

If the second beats the third, what transfers is a preference shared across objects, and a pose's
ranking beyond it is its own (grasp-specific), so more objects help more than more poses per object.
If the nearest poses transfer no more than the farthest, the ranking is not a smooth function of the
grasp at the dataset's pose spacing: no model of (cloud, pose) can learn it from these neighbours.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ANGLE_SCALE = 0.05
"""[m/rad] Weight of the palm's rotation in the pose distance: 1 rad counts as 5 cm, a little under half
the finger's 13.6 cm, so a rotation about the palm counts as the distance it moves the finger's middle."""


def _summary(values) -> dict:
    v = np.asarray([x for x in values if np.isfinite(x)])
    if not len(v):
        return {"poses": 0, "median": None, "iqr": None, "mean": None, "positive": 0}
    q25, med, q75 = np.percentile(v, [25, 50, 75])
    return {"poses": int(len(v)), "median": float(med), "iqr": [float(q25), float(q75)], "mean": float(v.mean()),
            "positive": int(np.sum(v > 0))}  # fmt: skip


def _fail(message: str) -> None:
    """Exit 2 with ``message`` as the one line on stderr (bad input)."""
    print(f"ranking_sources: {message}", file=sys.stderr)
    sys.exit(2)


def pose_distances(palms: np.ndarray, i: int, others: np.ndarray) -> np.ndarray:
    """Distance [m] of the palm poses ``palms[others]`` (4x4) from ``palms[i]``: position + ANGLE_SCALE * angle."""
    dp = np.linalg.norm(palms[others, :3, 3] - palms[i, :3, 3], axis=1)
    rel = np.einsum("nji,jk->nik", palms[others, :3, :3], palms[i, :3, :3])
    cos = (np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0
    return dp + ANGLE_SCALE * np.arccos(np.clip(cos, -1.0, 1.0))


def neighbouring_poses(
    d, groups: list[np.ndarray], varying: list[int], obj: np.ndarray, ks: list[int]
) -> dict:
    """Per varying pose, the linear design effect fitted on its K nearest and K farthest poses of its object.

    ``d``: the dataset (``palm``, ``pose``, ``log_e``, ``success_p``); ``groups``: each pose's sample rows;
    ``obj``: each group's object. Returns the nearest distance's median and IQR [m] and per K the
    Spearman summaries ``nearest_K`` and ``farthest_K``.
    """
    from mjcodesign.surrogate.ranking import group_spearman, linear_design_effect

    palms = d.palm[[d.pose[g[0]] for g in groups]]
    index = np.arange(len(groups))
    nearest_m: list[float] = []
    near: dict[int, list[float]] = {k: [] for k in ks}
    far: dict[int, list[float]] = {k: [] for k in ks}
    for i in varying:
        same = np.flatnonzero((obj == obj[i]) & (index != i))
        if not len(same):
            continue
        dist = pose_distances(palms, i, same)
        order = same[np.argsort(dist, kind="stable")]
        nearest_m.append(float(dist.min()))
        for k in ks:
            for sel, into in ((order[:k], near[k]), (order[::-1][:k], far[k])):
                score = linear_design_effect(d, np.concatenate([groups[j] for j in sel]), groups[i])
                into.append(group_spearman(score, d.success_p[groups[i]], [np.arange(len(groups[i]))])[0])
    q25, med, q75 = np.percentile(nearest_m, [25, 50, 75]) if nearest_m else (np.nan,) * 3
    return {
        "angle_scale_m_per_rad": ANGLE_SCALE,
        "nearest_distance_m": {"median": float(med), "iqr": [float(q25), float(q75)]},
        **{f"nearest_{k}": _summary(near[k]) for k in ks},
        **{f"farthest_{k}": _summary(far[k]) for k in ks},
    }


def main() -> None:
    """Parse the flags, compute, write the JSON and print it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--nearest", default="1,3,8", help="K of the nearest/farthest-pose fits (comma list)")
    a = ap.parse_args()
    try:
        ks = [int(k) for k in a.nearest.split(",")]
    except ValueError:
        ks = []
    if not ks or min(ks) < 1:
        _fail(f"--nearest {a.nearest!r}: give positive integers, e.g. 1,3,8")
    from mjcodesign.bench.record import provenance
    from mjcodesign.errors import MjcodesignError
    from mjcodesign.surrogate.data import load_grasp_data
    from mjcodesign.surrogate.ranking import group_spearman, linear_design_effect, pose_groups

    t0 = time.perf_counter()
    try:
        d = load_grasp_data(a.data, perturbed=True)
    except (MjcodesignError, OSError) as exc:
        _fail(str(exc))  # the error names the path
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
    out["neighbouring_poses"] = neighbouring_poses(d, groups, varying, obj, ks)
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    out["provenance"] = provenance(
        "ranking_sources",
        command=f"python3 scripts/ranking_sources.py --data {a.data} --out {a.out} --nearest {a.nearest}",
    )
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k != "provenance"}, indent=1))


if __name__ == "__main__":
    main()
