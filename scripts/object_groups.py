"""An evaluation's designs on named groups of objects: success over objects and paired differences.

    python3 scripts/object_groups.py EVAL_DIR --group train=FILE --group held-out=FILE \
        --compare A,B [--compare C,D] [--policy all] [--out RECORD.json]

``evaluate``'s tables split objects by domain only. This reads its ``results.json`` (every rollout)
and, for each named group of objects (a file of names, commas or lines; ``in-domain`` and
``out-of-domain`` are always there), gives each design's mean success over the group's objects with a
95 % bootstrap interval and each asked pair's paired difference (interval, p-value, detectable
difference), with the evaluation's own statistics (``mjcodesign.evaluation``) and seed.
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path

import numpy as np

from mjcodesign.evaluation import bootstrap_mean, paired_difference, per_object_cells, select_policy
from mjcodesign.evaluation.analysis import object_rates


def _names(path: str) -> set[str]:
    text = Path(path).read_text(encoding="utf-8")
    return {s.strip() for s in text.replace(",", "\n").splitlines() if s.strip()}


def groups_summary(rows: list[dict], groups: dict[str, set[str]], pairs, policy: str, seed: int) -> dict:
    """Per group: objects, each design's interval, each pair's paired difference (module docstring)."""
    rate = object_rates(per_object_cells(select_policy(rows, policy)).values())
    out = {}
    for name, objs in groups.items():
        entry = {"objects": sorted(objs), "designs": {}, "paired": []}
        for d, per in rate.items():
            v = [per[o] for o in sorted(objs) if o in per]
            entry["designs"][d] = bootstrap_mean(v, seed=seed).as_dict() if v else None
        for a, b in pairs:
            common = sorted(objs & set(rate[a]) & set(rate[b]))
            if common:
                res = paired_difference(
                    np.array([rate[a][o] for o in common]),
                    np.array([rate[b][o] for o in common]),
                    names=(a, b),
                    seed=seed,
                )
                entry["paired"].append(res.as_dict())
        out[name] = entry
    return out


def main() -> None:
    """Command line of the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("evaluation", help="an evaluate --out folder (results.json, summary.json)")
    ap.add_argument("--group", action="append", default=[], help="NAME=FILE of object names")
    ap.add_argument("--compare", action="append", default=[], help="A,B: design labels, a − b")
    ap.add_argument("--policy", default="all", help="pose policy: all, fixed, oracle")
    ap.add_argument("--out", default=None, help="also write the record here")
    args = ap.parse_args()
    folder = Path(args.evaluation)
    results = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    rows = [r for r in results["rows"] if r["impulse_paper_ns"] == summary["impulses_paper_ns"][0]]
    domains: dict[str, set[str]] = collections.defaultdict(set)
    for r in rows:
        domains[r["domain"]].add(r["object"])
    groups = dict(domains)
    for g in args.group:
        name, _, path = g.partition("=")
        groups[name] = _names(path)
    pairs = [tuple(c.split(",", 1)) for c in args.compare]
    record = {
        "evaluation": {k: summary[k] for k in ("command", "suite", "regime", "perturbations", "designs")},
        "policy": args.policy,
        "groups": groups_summary(rows, groups, pairs, args.policy, int(summary["seed"])),
    }
    text = json.dumps(record, indent=1)
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
