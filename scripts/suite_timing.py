"""Time ``run_suite`` on one ad-hoc suite: one warm-up pass, then one timed pass; JSON on stdout.

    python3 scripts/suite_timing.py --objects 013_apple,egad-like:3,025_mug --poses 10 --draws 8 \
        --rows rows.json

Run it at two commits (``scripts/at-commit``), alternating, to compare the evaluation engine's speed on
the same rollouts; ``--rows`` writes the rows so that the two can be checked equal byte for byte. The
suite runs under the ``SuiteRun`` defaults (the paper regime's scenario at the light density).
"""

from __future__ import annotations

import argparse
import json
import time

from mjcodesign.cli.common import user_cache_dir
from mjcodesign.evaluation.config import parse_design_groups
from mjcodesign.evaluation.rollouts import SuiteRun, run_suite
from mjcodesign.evaluation.suite import build_suite


def main() -> None:
    """Build the suite, run it twice, print the second pass's rollouts, wall and CPU seconds."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--objects", default="013_apple,egad-like:3,025_mug")
    p.add_argument("--poses", type=int, default=10)
    p.add_argument("--draws", type=int, default=8)
    p.add_argument("--designs", default="soft,semi-rigid,paper-optimized,random:1")
    p.add_argument("--rows", default=None, help="write the timed pass's rows and objects here (JSON)")
    args = p.parse_args()
    cache = user_cache_dir()
    suite = build_suite(tuple(args.objects.split(",")), poses_per_object=args.poses, seed=0, cache_dir=cache)
    run = SuiteRun(designs=parse_design_groups(args.designs), perturbations=args.draws)
    run_suite(suite, run, cache_dir=cache)
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_suite(suite, run, cache_dir=cache)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if args.rows:
        with open(args.rows, "w") as f:
            json.dump({"rows": result["rows"], "objects": result["objects"]}, f, sort_keys=True)
    print(json.dumps({"rollouts": len(result["rows"]), "wall_s": wall, "cpu_s": cpu}))


if __name__ == "__main__":
    main()
