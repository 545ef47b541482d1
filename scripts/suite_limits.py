"""What limits every design of an evaluation: the objects none of them ever holds, and their failures.

    python3 scripts/suite_limits.py RESULTS.json [--impulse X] --out benchmarks/records/DATE_NAME.json

Reads an ``evaluate`` run's ``results.json`` (every rollout) and writes, per split: the objects that no
design holds at any pose or draw, the failure kinds of their rollouts, the objects whose best design
holds under half of its rollouts, the ceiling those never-held objects put on any design's success
over objects, and each object's success difference between two designs (``--compare A,B``).
``--impulse`` keeps one disturbance of an evaluation that swept several (default: every rollout).
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path


def limits(rows: list[dict], compare: tuple[str, str] | None) -> dict:
    """The summary of the module docstring from an evaluation's rows."""
    by: dict[str, dict[str, list[dict]]] = collections.defaultdict(lambda: collections.defaultdict(list))
    domain = {}
    for r in rows:
        by[r["object"]][r["design"]].append(r)
        domain[r["object"]] = r["domain"]
    rate = {o: {d: sum(x["success"] for x in v) / len(v) for d, v in ds.items()} for o, ds in by.items()}
    out: dict = {
        "designs": sorted({r["design"] for r in rows}),
        "regimes": sorted(
            {r["density"] for r in rows}
        ),  # the evaluation's regime labels (``real``, or densities)
        "splits": {},
    }
    for split in sorted(set(domain.values())):
        objs = sorted(o for o in by if domain[o] == split)
        never = [o for o in objs if max(rate[o].values()) == 0.0]
        kinds = collections.Counter(
            k for o in never for v in by[o].values() for x in v for k in x["failures"]
        )
        out["splits"][split] = {
            "objects": len(objs),
            "never_held": never,
            "never_held_failures": dict(kinds),
            "ceiling": 1.0 - len(never) / len(objs),
            "best_design_below_half": {o: max(rate[o].values()) for o in objs if max(rate[o].values()) < 0.5},
        }
    if compare is not None:
        a, b = compare
        out["difference"] = {"a": a, "b": b, "per_object": {o: rate[o][a] - rate[o][b] for o in sorted(by)}}
    return out


def main() -> int:
    """Read the rows, write the summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", help="an evaluate run's results.json")
    parser.add_argument("--compare", default=None, help="two designs A,B: per-object success of A − B")
    parser.add_argument("--impulse", type=float, default=None, help="keep this disturbance [N s] only")
    parser.add_argument("--out", required=True, help="the record (JSON)")
    args = parser.parse_args()
    from mjcodesign.bench.record import provenance

    rows = json.loads(Path(args.results).read_text(encoding="utf-8"))["rows"]
    if args.impulse is not None:
        rows = [r for r in rows if r["impulse_paper_ns"] == args.impulse]
        if not rows:
            raise SystemExit(f"suite_limits: no rollout at impulse {args.impulse}")
    compare = tuple(args.compare.split(",", 1)) if args.compare else None
    record = {
        "provenance": provenance("suite_limits", command=" ".join(["python3", *sys.argv])),
        **limits(rows, compare),
    }
    Path(args.out).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    for split, s in record["splits"].items():
        print(
            f"{split}: {len(s['never_held'])} of {s['objects']} never held; ceiling {s['ceiling']:.3f}",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
