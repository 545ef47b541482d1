"""The surrogate's learning curve over poses per object: ``mjcodesign train --poses-per-object N`` per N.

For a dataset and a list of N, runs one after another (a subprocess each)

    mjcodesign train --data D --poses-per-object N --out OUT_ROOT/nN --epochs E --seed S --threads T --json

and gathers from each run's ``metrics.json`` the held-out success measures: the success head's ROC
AUC and Brier score beside those of the gradient-boosted trees' classifier (trained on the same rows),
the median design-ranking Spearman of both, the training rows and the wall time. Every N holds out
the same objects and scores all their poses (``train --poses-per-object``), so the points compare;
the record checks that they do. Writes one JSON with provenance to ``--out`` after every run.

    nice -n 10 python3 scripts/learning_curve.py --data DS --poses 6,12,20 --out-root RUNS/curve --out curve.json

``--train-args='--efficiency 0 --smoothness-poses 0'`` adds flags to every ``train`` (here: no 25 %
run, no smoothness lines). Exits 1 when a run failed (its line is in the record), 2 on bad flags.

Not part of the package: the record of a learning curve (``benchmarks/records/*_learning_curve.json``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

from mjcodesign.bench.record import provenance
from mjcodesign.cli.common import int_at_least
from mjcodesign.outputs import write_atomic

_HEAD = "surrogate (head)"  # the ranking's names of the two success probabilities (surrogate.report)
_TREES = "gradient-boosted trees (classifier)"


def _poses(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not values or min(values) < 1 or len(set(values)) < len(values):
        raise argparse.ArgumentTypeError(f"must be distinct comma-separated integers >= 1, got {text!r}")
    return values


def _parse() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="dataset folder (mjcodesign datagen)")
    p.add_argument("--poses", required=True, type=_poses, help="poses per object, comma-separated: 6,12,20")
    p.add_argument("--out-root", required=True, help="folder of the runs' checkpoints (OUT_ROOT/nN)")
    p.add_argument("--out", required=True, help="record file (JSON), rewritten after every run")
    p.add_argument("--epochs", type=int_at_least(1), default=60)
    p.add_argument(
        "--seed", type=int_at_least(0), default=0, help="train's --seed (split, weights, shuffles)"
    )
    p.add_argument("--threads", type=int_at_least(1), default=1)
    p.add_argument(
        "--train-args", default="", help="more flags for every train, one string (--train-args='...')"
    )
    return p.parse_args()


def _train_argv(args: argparse.Namespace, n: int) -> list[str]:
    """The ``mjcodesign train`` flags of the run with ``n`` poses per object."""
    return ["train", "--data", args.data, "--poses-per-object", str(n), "--out", str(Path(args.out_root) / f"n{n}"),
            "--epochs", str(args.epochs), "--seed", str(args.seed), "--threads", str(args.threads), "--json",
            *shlex.split(args.train_args)]  # fmt: skip


def _run(argv: list[str]) -> tuple[int, str, float]:
    """Run this interpreter's ``mjcodesign`` with ``argv``, its stderr passed through: (rc, last stderr line, s).

    Its stdout (the ``--json`` summary) is dropped: the record reads the run's ``metrics.json``.
    """
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "mjcodesign.cli", *argv]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    last = ""
    for line in proc.stderr:
        sys.stderr.write(line)
        sys.stderr.flush()
        last = line.strip() or last
    return proc.wait(), last, time.perf_counter() - t0


def _get(d: dict, *keys):
    """``d[k0][k1]...``, or None where a key is missing (a network without a success head)."""
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def _point(n: int, m: dict) -> dict:
    """One point of the curve: what the run trained on and its held-out success measures."""
    test, ranks = m["test"], m["ranking"]["models"]
    return {
        "poses_per_object": n,
        "train_rows": m["training"]["train_rows"],
        "val_rows": m["split"]["val"],
        "test_rows": m["split"]["test"],
        "epochs": m["training"]["epochs"],
        "best_epoch": m["training"]["best_epoch"],
        "stopped": m["training"]["stopped"],
        "train_wall_s": m["training"]["wall_s"],
        "surrogate_head": {k: _get(test, "surrogate", "success_head", k) for k in ("roc_auc", "brier")},
        "trees_classifier": {k: _get(test, "gradient-boosted trees", "success_head", k) for k in ("roc_auc", "brier")},
        "ranking_median": {"surrogate_head": _get(ranks, _HEAD, "median"), "trees_classifier": _get(ranks, _TREES, "median"),
                           "poses": m["ranking"]["poses"]},
        "verdict": {k: m["verdict"].get(k) for k in ("head_auc", "head_brier", "ranking_beats_trees")},
    }  # fmt: skip


def _held_out(metrics: list[dict]) -> dict:
    """The held-out objects and rows of the runs, and whether every run had the same."""
    first = metrics[0]["split"]
    same = all(
        m["split"]["test_objects"] == first["test_objects"] and m["split"]["test"] == first["test"]
        for m in metrics
    )
    return {"test_objects": first["test_objects"], "test_rows": first["test"], "same_for_every_n": same}


def main() -> int:
    """Run the trainings, write and print the record."""
    args = _parse()
    record = {
        "provenance": provenance("learning_curve", command=shlex.join(["python3", *sys.argv])),
        "settings": {"data": args.data, "poses_per_object": args.poses, "epochs": args.epochs, "seed": args.seed,
                     "threads": args.threads, "train_args": shlex.split(args.train_args), "out_root": args.out_root,
                     "held_out": "the same objects and all their poses for every N; training and validation rows "
                                 "are the first N poses of each training object"},
        "runs": [],
    }  # fmt: skip
    metrics, failed = [], 0
    for n in args.poses:
        argv = _train_argv(args, n)
        load = list(os.getloadavg())
        rc, last, wall = _run(argv)
        run = {"poses_per_object": n, "command": shlex.join(["mjcodesign", *argv]), "returncode": rc,
               "run_wall_s": wall, "load_average_start": load, "load_average_end": list(os.getloadavg()),
               "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds")}  # fmt: skip
        if rc == 0:
            m = json.loads((Path(args.out_root) / f"n{n}" / "metrics.json").read_text(encoding="utf-8"))
            metrics.append(m)
            run.update(_point(n, m))
            record["dataset"] = {k: m["dataset"][k] for k in ("path", "manifest_sha256", "samples", "poses")}
            record["held_out"] = _held_out(metrics)
        else:
            failed += 1
            run["error"] = last
        record["runs"].append(run)
        write_atomic(args.out, json.dumps(record, indent=1, allow_nan=False) + "\n")
    print(json.dumps(record, indent=1, allow_nan=False))
    if metrics and not record["held_out"]["same_for_every_n"]:
        print("learning_curve: the runs held out different rows: the points do not compare", file=sys.stderr)
        return 1
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
