"""An evaluation's designs on named groups of objects: success over objects and paired differences.

    python3 scripts/object_groups.py EVAL_DIR --group train=FILE --group held-out=FILE \
        --compare A,B [--compare C,D] [--policy all] [--impulse X] [--also EVAL_DIR2] [--out RECORD.json]

``evaluate``'s tables split objects by domain only. This reads its ``results.json`` (every rollout)
and, for each named group of objects (a file of names, commas or lines; ``in-domain`` and
``out-of-domain`` are always there), gives each design's mean success over the group's objects with a
95 % bootstrap interval and each asked pair's paired difference (interval, p-value, detectable
difference), with the evaluation's own statistics (``mjcodesign.evaluation``) and seed.

``--impulse`` picks one disturbance of the evaluation (default: its first). ``--also`` adds the designs
of another evaluation of the same suite, seed, perturbations, regime and scenario: its rollouts share the
first's perturbation draws (they are drawn per object and pose, whatever the designs), so a design
evaluated later pairs with the first's. Designs both evaluated must agree rollout by rollout (the CPU
simulator is deterministic), which checks that the two are pairable; otherwise the script stops.
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


_SAME = (
    "suite",
    "seed",
    "perturbations",
    "regime",
    "scenario",
    "perturbation_model",
    "model",
    "routing",
    "tendon",
)
"""Summary keys two evaluations must share for their rollouts to pair."""


def _rollout_key(r: dict) -> tuple:
    return (r["object"], r["pose"], r["draw"], r["density"], r["impulse_paper_ns"], r["design"])


def merge_evaluations(rows: list[dict], summary: dict, other_rows: list[dict], other: dict) -> list[dict]:
    """``rows`` with ``other_rows``' designs added; raises ValueError when the two cannot pair."""
    for k in _SAME:
        if summary.get(k) != other.get(k):
            raise ValueError(f"the evaluations differ in {k!r}: their rollouts do not pair")
    mine = {_rollout_key(r): r for r in rows}
    designs = {r["design"] for r in rows}
    added = []
    for r in other_rows:
        if r["design"] not in designs:
            added.append(r)
            continue
        twin = mine.get(_rollout_key(r))
        if twin is None or twin["success"] != r["success"] or twin["perturbation"] != r["perturbation"]:
            raise ValueError(
                f"design {r['design']!r} differs between the evaluations at {_rollout_key(r)[:3]}: not pairable"
            )
    return rows + added


def _impulse_rows(folder: Path, impulse: float | None) -> tuple[list[dict], dict]:
    results = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    chosen = summary["impulses_paper_ns"][0] if impulse is None else impulse
    if chosen not in summary["impulses_paper_ns"]:
        raise SystemExit(
            f"object_groups: {folder} has no impulse {chosen} (it has {summary['impulses_paper_ns']})"
        )
    return [r for r in results["rows"] if r["impulse_paper_ns"] == chosen], summary


def main() -> None:
    """Command line of the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("evaluation", help="an evaluate --out folder (results.json, summary.json)")
    ap.add_argument("--group", action="append", default=[], help="NAME=FILE of object names")
    ap.add_argument("--compare", action="append", default=[], help="A,B: design labels, a − b")
    ap.add_argument("--policy", default="all", help="pose policy: all, fixed, oracle")
    ap.add_argument("--impulse", type=float, default=None, help="disturbance [N s] (default: the first)")
    ap.add_argument(
        "--also", action="append", default=[], help="another evaluation whose designs pair (above)"
    )
    ap.add_argument("--out", default=None, help="also write the record here")
    args = ap.parse_args()
    rows, summary = _impulse_rows(Path(args.evaluation), args.impulse)
    commands = [summary["command"]]
    for extra in args.also:
        more, other = _impulse_rows(Path(extra), args.impulse)
        try:
            rows = merge_evaluations(rows, summary, more, other)
        except ValueError as exc:
            raise SystemExit(f"object_groups: {exc}") from None
        commands.append(other["command"])
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
        "also": [{"folder": str(f), "command": c} for f, c in zip(args.also, commands[1:], strict=True)],
        "designs": sorted({r["design"] for r in rows}),
        "impulse_paper_ns": rows[0]["impulse_paper_ns"] if rows else None,
        "policy": args.policy,
        "groups": groups_summary(rows, groups, pairs, args.policy, int(summary["seed"])),
    }
    text = json.dumps(record, indent=1)
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
