"""What limits the evaluation's intervals: a variance decomposition of an ``evaluate`` run's rollouts.

Success y of object i, pose j, perturbation draw k is split into nested components (method of moments,
balanced-design estimators on the rollouts the simulator could use):

* ``s2_draw``: the mean within-(object, pose) variance over draws (unbiased, ddof 1);
* ``s2_pose``: the variance of pose means within an object, less ``s2_draw / D``;
* ``s2_object``: the variance of object means, less ``s2_pose / P`` and ``s2_draw / (P D)``.

The variance of a design's mean over n objects is then ``(s2_object + s2_pose / P + s2_draw / (P D)) / n``
(every pose, ``all``) or ``(s2_object + s2_pose + s2_draw / D) / n`` (one pose, ``fixed``), and the 95 %
half-width is 1.96 times its root. From it: the share of each component, the objects needed for a
target half-width at this suite's P and D, the half-width left with infinitely many poses and draws,
and the half-width of the mean over exactly these objects (within-object noise only). Paired
differences between designs (same object, pose and draw) are decomposed the same way.

    python3 scripts/variance_decomposition.py --results DIR/results.json --out record.json

Not part of the package: the record of ``benchmarks/records/*_evaluate_variance.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict

import numpy as np

_Z = 1.96  # two-sided 95 % normal quantile
_TARGET_DESIGN = 0.05  # the evidence issue's target half-width on a design's success
_TARGET_PAIRED = 0.06  # and on a paired difference


def _components(cells: dict) -> dict:
    """Variance components of ``cells``: object -> pose -> list of values over draws."""
    draw_var, pose_var, obj_mean, n_pose, n_draw = [], [], [], [], []
    for poses in cells.values():
        vals = [np.asarray(v, float) for v in poses.values() if len(v) >= 2]
        if not vals:
            continue
        means = np.array([v.mean() for v in vals])
        draw_var.append(np.mean([v.var(ddof=1) for v in vals]))
        if len(vals) >= 2:
            pose_var.append(means.var(ddof=1))
        obj_mean.append(means.mean())
        n_pose.append(len(vals))
        n_draw.append(np.mean([len(v) for v in vals]))
    p, d, n = float(np.mean(n_pose)), float(np.mean(n_draw)), len(obj_mean)
    s2_draw = float(np.mean(draw_var))
    s2_pose = max(float(np.mean(pose_var)) - s2_draw / d, 0.0)
    total = float(np.var(obj_mean, ddof=1))
    s2_object = max(total - s2_pose / p - s2_draw / (p * d), 0.0)
    return {"objects": n, "poses": p, "draws": d, "mean": float(np.mean(obj_mean)), "s2_object": s2_object,
            "s2_pose": s2_pose, "s2_draw": s2_draw, "var_object_means": total}  # fmt: skip


def _needs(c: dict, target: float) -> dict:
    """Half-widths and the objects a target needs, for every pose (``all``) and the first pose (``fixed``)."""
    out = {}
    for policy, per_object in (
        ("all", c["s2_object"] + c["s2_pose"] / c["poses"] + c["s2_draw"] / (c["poses"] * c["draws"])),
        ("fixed", c["s2_object"] + c["s2_pose"] + c["s2_draw"] / c["draws"]),
    ):
        within = per_object - c["s2_object"]
        out[policy] = {
            "halfwidth": _Z * np.sqrt(per_object / c["objects"]),
            "share_object": c["s2_object"] / per_object,
            "objects_for_target": (_Z / target) ** 2 * per_object,
            "halfwidth_infinite_poses_draws": _Z * np.sqrt(c["s2_object"] / c["objects"]),
            "halfwidth_these_objects_only": _Z * np.sqrt(within / c["objects"]),
        }
    return {"target": target, **out}


def decompose(rows: list[dict]) -> dict:
    """Per domain: each design's components and needs, and each pair's (same object, pose and draw)."""
    rows = [r for r in rows if not r["sample_error"]]
    first = (rows[0]["density"], rows[0]["impulse_paper_ns"])
    rows = [r for r in rows if (r["density"], r["impulse_paper_ns"]) == first]
    designs = list(dict.fromkeys(r["design"] for r in rows))
    out: dict = {}
    for domain in sorted({r["domain"] for r in rows}):
        mine = [r for r in rows if r["domain"] == domain]
        by_key: dict = defaultdict(dict)
        for r in mine:
            by_key[(r["object"], r["pose"], r["draw"])][r["design"]] = float(r["success"])
        res: dict = {"designs": {}, "paired": {}}
        for d in designs:
            cells: dict = defaultdict(lambda: defaultdict(list))
            for (o, p, _), v in by_key.items():
                if d in v:
                    cells[o][p].append(v[d])
            c = _components(cells)
            res["designs"][d] = {**c, **_needs(c, _TARGET_DESIGN)}
        for i, a in enumerate(designs):
            for b in designs[i + 1 :]:
                cells = defaultdict(lambda: defaultdict(list))
                for (o, p, _), v in by_key.items():
                    if a in v and b in v:
                        cells[o][p].append(v[a] - v[b])
                c = _components(cells)
                res["paired"][f"{a} - {b}"] = {**c, **_needs(c, _TARGET_PAIRED)}
        out[domain] = res
    return out


def main() -> int:
    """Read the results, decompose, write and print the record."""
    from mjcodesign.bench.record import provenance

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", required=True, help="an evaluate run's results.json")
    p.add_argument("--out", required=True, help="record file (JSON)")
    args = p.parse_args()
    with open(args.results, encoding="utf-8") as f:
        results = json.load(f)
    record = {
        "provenance": provenance("evaluate_variance", command=" ".join(sys.argv)),
        "record": {"suite": results["suite"], "run": results["run"], "rollouts": len(results["rows"]),
                   "decomposition": decompose(results["rows"])},
    }  # fmt: skip
    text = json.dumps(record, indent=1, allow_nan=False, default=float)
    with open(args.out, "w", encoding="utf-8") as f:
        f.write(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
