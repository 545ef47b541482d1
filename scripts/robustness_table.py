"""Does a design's lead survive the model's uncertainty? Evaluations of the same designs under model variants.

    python3 scripts/robustness_table.py --run default=EV1 --run "friction 0.6=EV2" --run printed=EV3
        --presets soft,semi-rigid,paper-optimized --out benchmarks/records/DATE_NAME.json

Each ``--run NAME=DIR`` is an ``evaluate`` output folder (its ``results.json``: every rollout) of the same
designs on the same suite, poses and draws under one model variant (``--routing``, ``--friction``); the
first is the nominal model. Per pose policy (every pose, the first, each design's best), per split
(in-domain, out-of-domain) and per variant, the record gives:

- each design's success (mean over objects, bootstrap interval) and its share of rollouts the simulator
  could not use (diverged, implausible: counted, never scored);
- each design's change from the nominal run, paired over objects (the same objects, poses and draws);
- the designs' ranking, and whether it is the nominal one;
- for each design that is not a preset: its lead over the best preset *of that variant*, paired over
  objects, and whether the lead keeps the nominal lead's sign under every variant (``robust``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _rows(folder: Path) -> list[dict]:
    return json.loads((folder / "results.json").read_text(encoding="utf-8"))["rows"]


def table(runs: dict[str, list[dict]], presets: list[str], seed: int = 0) -> dict:
    """The record's body (module docstring) from each variant's evaluation rows, the nominal first.

    The fixed and oracle policies are the evaluation's (first pose; each design's best pose per object).
    """
    from mjcodesign.evaluation.analysis import (
        ALL_POSES,
        SPLITS,
        object_rates,
        per_object_cells,
        select_policy,
    )
    from mjcodesign.evaluation.stats import bootstrap_mean, paired_difference

    names = list(runs)
    designs = list(dict.fromkeys(r["design"] for r in runs[names[0]]))
    for n in names[1:]:
        if set(dict.fromkeys(r["design"] for r in runs[n])) != set(designs):
            raise SystemExit(f"run {n!r} has other designs than {names[0]!r}")
    candidates = [d for d in designs if d not in presets]
    out: dict = {"variants": names, "designs": designs, "presets": presets, "policies": {}}
    for policy in [ALL_POSES, "fixed", "oracle"]:
        per_policy: dict = {}
        for split in SPLITS:
            rates, errors = {}, {}
            for n, rows in runs.items():
                kept = [r for r in select_policy(rows, policy) if r["domain"] == split]
                cells = per_object_cells(kept).values()
                rates[n] = object_rates(cells)
                errors[n] = {
                    d: sum(c["sample_errors"] for c in cells if c["design"] == d)
                    / max(1, sum(c["sample_errors"] + c["valid"] for c in cells if c["design"] == d))
                    for d in designs
                }
            # a design without rows in this split (one design per training object) is left out of it
            present = [d for d in designs if all(rates[n].get(d) for n in names)]
            entry: dict = {"success": {}, "change": {}, "unusable_share": errors, "ranking": {}, "lead": {},
                           "absent": [d for d in designs if d not in present]}  # fmt: skip
            for n in names:
                entry["success"][n] = {
                    d: bootstrap_mean(list(rates[n][d].values()), seed=seed).as_dict() for d in present
                }
                order = sorted(present, key=lambda d: -entry["success"][n][d]["value"])
                entry["ranking"][n] = order
                if n != names[0]:
                    entry["change"][n] = {}
                    for d in present:
                        common = sorted(set(rates[n][d]) & set(rates[names[0]][d]))
                        diff = paired_difference(
                            [rates[n][d][o] for o in common],
                            [rates[names[0]][d][o] for o in common],
                            names=(n, names[0]),
                            seed=seed,
                        )
                        entry["change"][n][d] = diff.as_dict()
            entry["same_ranking_as_nominal"] = {
                n: entry["ranking"][n] == entry["ranking"][names[0]] for n in names
            }
            for d in (c for c in candidates if c in present):
                leads = {}
                for n in names:
                    best = max(presets, key=lambda p: entry["success"][n][p]["value"])
                    common = sorted(set(rates[n][d]) & set(rates[n][best]))
                    diff = paired_difference(
                        [rates[n][d][o] for o in common],
                        [rates[n][best][o] for o in common],
                        names=(d, best),
                        seed=seed,
                    )
                    leads[n] = {"best_preset": best, **diff.as_dict()}
                signs = {n: _sign(leads[n]) for n in names}
                entry["lead"][d] = {"per_variant": leads, "robust": len(set(signs.values())) == 1}
            per_policy[split] = entry
        out["policies"][policy] = per_policy
    return out


def _sign(lead: dict) -> int:
    value = lead["difference"]["value"]
    return (value > 0) - (value < 0)


def main() -> int:
    """Read the runs, write the record."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--run", action="append", required=True, help="NAME=DIR of an evaluate run; nominal first"
    )
    parser.add_argument(
        "--presets", default="soft,semi-rigid,paper-optimized", help="the designs compared against"
    )
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    parser.add_argument("--out", required=True, help="the record (JSON)")
    args = parser.parse_args()
    from mjcodesign.bench.record import provenance

    runs = {}
    for item in args.run:
        name, _, folder = item.partition("=")
        if not name or not folder:
            parser.error(f"--run {item}: write NAME=DIR")
        runs[name] = _rows(Path(folder))
    presets = [p.strip() for p in args.presets.split(",") if p.strip()]
    record = {
        "provenance": provenance("robustness_table", command=" ".join(["python3", *sys.argv])),
        "runs": {item.partition("=")[0]: item.partition("=")[2] for item in args.run},
        **table(runs, presets, args.seed),
    }
    Path(args.out).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    for split, e in record["policies"]["all"].items():
        for d, lead in e["lead"].items():
            parts = [
                f"{n}: {v['difference']['value']:+.3f} vs {v['best_preset']}"
                for n, v in lead["per_variant"].items()
            ]
            print(f"{split} {d}: robust={lead['robust']} ({'; '.join(parts)})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
