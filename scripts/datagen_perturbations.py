"""Cost and label spread of ``datagen --perturbations``: the same objects, poses and designs at each setting.

    python scripts/datagen_perturbations.py --out benchmarks/records/DATE_datagen_perturbations.json

Runs ``mjcodesign datagen`` (the default regime) once per ``--settings`` value into a temporary folder,
reads ``data info --json`` of each, and writes one record: per setting the wall time, rollouts, cells,
rollouts per cell (against K = 1's cells), the share of cells with 0 < p < 1 and of cells extended, and
the success rate of the binary label. Run it with ``scripts/at-commit`` so that the record names a clean
commit.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mjcodesign.bench import write_json
from mjcodesign.bench.record import provenance

_OBJECTS = "002_master_chef_can,005_tomato_soup_can,006_mustard_bottle,013_apple"


def _run(argv: list[str]) -> str:
    res = subprocess.run([sys.executable, "-m", "mjcodesign.cli.main", *argv], capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(argv)}: exit {res.returncode}: {res.stderr.strip()[-500:]}")
    return res.stdout


def main() -> int:
    """Run every setting and write the record."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--objects", default=_OBJECTS)
    p.add_argument("--poses-per-object", type=int, default=3)
    p.add_argument("--designs-per-pose", type=int, default=8)
    p.add_argument("--settings", default="1,4,4:16", help="comma-separated --perturbations values")
    p.add_argument("--out", required=True)
    args = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for setting in args.settings.split(","):
            out = Path(tmp) / setting.replace(":", "-")
            t0 = time.perf_counter()
            summary = json.loads(
                _run(
                    [
                        "datagen",
                        "--objects",
                        args.objects,
                        "--poses-per-object",
                        str(args.poses_per_object),
                        "--designs-per-pose",
                        str(args.designs_per_pose),
                        "--perturbations",
                        setting,
                        "--out",
                        str(out),
                    ]
                )
            )
            wall = time.perf_counter() - t0
            info = json.loads(_run(["data", "info", str(out), "--json"]))
            cells = summary["samples"] + summary["rejected"]
            rollouts = summary.get("rollouts", cells)
            rows.append(
                {
                    "perturbations": setting,
                    "wall_s": wall,
                    "poses": summary["poses"],
                    "cells": cells,
                    "rollouts": rollouts,
                    "rollouts_per_cell": rollouts / cells if cells else 0.0,
                    "success_rate": info["success_rate"],
                    "labels": info.get("labels"),
                    "by_object": {k: v["success_rate"] for k, v in info["by_object"].items()},
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    base = rows[0]["wall_s"]
    for r in rows:
        r["wall_vs_first"] = r["wall_s"] / base if base else None
    record = {
        "objects": args.objects.split(","),
        "poses_per_object": args.poses_per_object,
        "designs_per_pose": args.designs_per_pose,
        "settings": rows,
        "provenance": provenance("datagen_perturbations", command=" ".join(["python", *sys.argv])),
    }
    write_json(record, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
