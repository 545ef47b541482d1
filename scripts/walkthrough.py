"""Run the workflow of docs/getting-started.md, as written there, and record each step's exit code and time.

    python3 scripts/walkthrough.py --work DIR --out benchmarks/records/DATE_walkthrough.json

The commands are read from the page's workflow ``bash`` block (its ``OBJECTS=`` line and the five
``mjcodesign`` lines) and run in order in one shell under ``nice -n 5``, from ``DIR`` (``work/`` is
made inside it). The record holds the commands, their exit codes and wall times, the dataset's counts,
the evaluation's table, and the provenance of the installed code (:func:`mjcodesign.bench.record.provenance`).
It stops at the first step that fails and records it.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

PAGE = Path(__file__).resolve().parents[1] / "docs" / "getting-started.md"


def page_commands(text: str) -> tuple[str, list[str]]:
    """(the ``OBJECTS=`` assignment, the ``mjcodesign`` command lines) of the page's workflow block.

    The workflow block is the first ``bash`` block that sets ``OBJECTS``.
    """
    blocks = [b for b in re.findall(r"```bash\n(.*?)```", text, re.S) if "OBJECTS=" in b]
    if not blocks:
        raise SystemExit(f"{PAGE}: no bash block sets OBJECTS")
    lines = [ln.strip() for ln in blocks[0].splitlines() if ln.strip() and not ln.startswith("#")]
    objects = next(ln for ln in lines if ln.startswith("OBJECTS="))
    return objects, [ln for ln in lines if ln.startswith("mjcodesign ")]


def main() -> int:
    """Run the page's commands and write the record; exit 1 when a step failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", required=True, help="folder to run in (work/ is made inside it)")
    parser.add_argument("--out", required=True, help="the record (JSON)")
    args = parser.parse_args()
    from mjcodesign.bench.record import provenance

    objects, commands = page_commands(PAGE.read_text(encoding="utf-8"))
    root = Path(args.work)
    root.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, OBJECTS=objects.split("=", 1)[1])
    steps = []
    t_all = time.perf_counter()
    for cmd in commands:
        t0 = time.perf_counter()
        proc = subprocess.run(
            ["nice", "-n", "5", "bash", "-c", cmd], cwd=root, env=env, capture_output=True, text=True
        )
        steps.append(
            {"command": cmd, "exit_code": proc.returncode, "wall_s": round(time.perf_counter() - t0, 1)}
        )
        print(
            f"walkthrough: {cmd.split()[1]} exit {proc.returncode} in {steps[-1]['wall_s']} s",
            file=sys.stderr,
        )
        if proc.returncode != 0:
            steps[-1]["stderr_tail"] = proc.stderr[-2000:]
            break
    record = {
        "provenance": {
            **provenance(
                "walkthrough", command=f"python3 scripts/walkthrough.py --work {args.work} --out {args.out}"
            ),
            "note": "the commands of docs/getting-started.md's first bash block, in one shell, each under nice -n 5",
        },
        "record": {"objects": env["OBJECTS"].split(","), "steps": steps},
    }
    record["record"]["total_wall_s"] = round(time.perf_counter() - t_all, 1)
    info = subprocess.run(
        ["mjcodesign", "data", "info", "work/data", "--json"], cwd=root, capture_output=True, text=True
    )
    if info.returncode == 0:
        summary = json.loads(info.stdout)
        record["record"]["dataset"] = {
            k: summary[k] for k in ("regime", "poses", "samples", "success_rate", "by_design_group")
        }
    table = root / "work" / "evaluation" / "table.md"
    if table.is_file():
        record["record"]["evaluation_table"] = table.read_text(encoding="utf-8").splitlines()
    Path(args.out).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return 0 if all(s["exit_code"] == 0 for s in steps) and len(steps) == len(commands) else 1


if __name__ == "__main__":
    sys.exit(main())
