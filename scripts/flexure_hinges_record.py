"""Records the printed chain with n hinges per flexure against the FEM with the same routing.

``SimOptions(routing="printed", hinges_per_block=n)``: each flexure as n hinges of n k at the middles of
its n equal parts, the segments keeping one. For every n of ``--hinges``:

* the straight finger's buckling tension of uniform fingers, ln E 13.5-17.0 (`mjcodesign.models.stability`,
  MuJoCo's forces differenced), against the converged FEM's over its global modes (recorded at ln E 15 in
  ``tests/data/fem_routing_refinement.json``; ∝ E for a uniform finger), against the first flexure's
  closed form with the same n hinges (`string_buckling_tension`) and against that flexure as an
  Euler–Bernoulli beam (the form at ``EULER_BERNOULLI_HINGES``); and the block its mode turns most;
* the free curl (gravity off) of the designs of each recorded FEM curl file (``--fem-curls``) at the
  file's tensions: bend and |tip| against the FEM's.

    python3 scripts/flexure_hinges_record.py --out benchmarks/records/2026-12-05_flexure_hinges.json

Seconds on one core; the FEM is read, never rerun. Not part of the package: a record of how the numbers
in the models and cross-simulator pages were made.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import numpy as np

from mjcodesign.bench.record import provenance
from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models import build_finger
from mjcodesign.models.chain import hinge_stiffness
from mjcodesign.models.channels import channel_points
from mjcodesign.models.stability import buckling_tension, string_buckling_tension
from mjcodesign.models.types import FingerModel, SimOptions
from mjcodesign.scenarios.static import curl

LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)
"""ln E of the uniform fingers (those of tests/test_routing.py)."""
EULER_BERNOULLI_HINGES = 400
"""Hinges of the closed form that stand for the continuous flexure (4e-6 short of its limit, as 1/n²)."""
_DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def _options(n: int) -> SimOptions:
    return SimOptions(routing="printed", gravity=False, hinges_per_block=n)


def _buckling(n: int, fem_global: dict) -> list[dict]:
    design = FingerDesign()
    flexure = next(b for b in design.blocks() if b.kind is BlockKind.FLEXURE)
    pts = channel_points(design)
    x_a, x_b = pts[0, 2, 0], pts[1, 0, 0]
    rows = []
    for log_e in LOG_E:
        built = build_finger(design, Stiffness([log_e] * 11), FingerModel.CHAIN, options=_options(n))
        t_crit, mode = buckling_tension(built)
        k = hinge_stiffness(design, np.full(design.n_blocks, np.exp(log_e)))[flexure.index]
        fem = fem_global["fem_global_n"] * np.exp(log_e - fem_global["log_e"])
        form = string_buckling_tension(k, flexure.x0, flexure.x1, x_a, x_b, n)
        beam = string_buckling_tension(k, flexure.x0, flexure.x1, x_a, x_b, EULER_BERNOULLI_HINGES)
        block_mode = np.bincount(built.fingers[0].joint_blocks, weights=mode, minlength=design.n_blocks)
        rows.append(
            {
                "hinges_per_flexure": n,
                "log_e": log_e,
                "chain_n": t_crit,
                "fem_global_n": fem,
                "chain_over_fem": t_crit / fem,
                "first_flexure_form_n": form,
                "chain_over_form": t_crit / form,
                "first_flexure_beam_n": beam,
                "chain_over_beam": t_crit / beam,
                "mode_block": int(np.argmax(np.abs(block_mode))),
            }
        )
    return rows


def _curls(n: int, path: Path) -> list[dict]:
    rows = []
    for row in json.loads(path.read_text())["record"]["curl"]:
        r = curl(
            FingerDesign(), Stiffness.parse(row["design"]), "chain", row["tension_n"], options=_options(n)
        )
        fem_tip = float(np.linalg.norm(row["fem_tip_displacement_m"]))
        tip = float(np.linalg.norm(r["tip_displacement_m"]))
        rows.append(
            {
                "hinges_per_flexure": n,
                "design": row["design"],
                "tension_n": row["tension_n"],
                "chain_bend_angle_rad": r["bend_angle_rad"],
                "fem_bend_angle_rad": row["fem_bend_angle_rad"],
                "bend_rel_error": r["bend_angle_rad"] / row["fem_bend_angle_rad"] - 1.0,
                "chain_tip_m": tip,
                "fem_tip_m": fem_tip,
                "tip_rel_error": tip / fem_tip - 1.0,
            }
        )
    return rows


def main(argv=None) -> None:
    """Measure the chain for every n and write the record (provenance, then the numbers)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True, help="JSON record to write")
    p.add_argument("--hinges", default="1,2,3,4,6,8,16", help="hinges per flexure, comma-separated")
    p.add_argument(
        "--fem-curls",
        default="fem_routing_curl.json,fem_routing_curl13_seeds0-2.json,fem_routing_curl13_seeds3-9.json",
        help="recorded FEM curl files in tests/data, comma-separated (a missing one is skipped)",
    )
    args = p.parse_args(argv)
    hinges = [int(v) for v in args.hinges.split(",")]
    command = shlex.join(
        ["python3", "scripts/flexure_hinges_record.py", *(sys.argv[1:] if argv is None else argv)]
    )
    fem_global = json.loads((_DATA / "fem_routing_refinement.json").read_text())["record"]["refinement"][-1]
    record: dict = {
        "hinges_per_flexure": hinges,
        "log_e": list(LOG_E),
        "fem_global": {
            "file": "tests/data/fem_routing_refinement.json",
            "mesh": fem_global["mesh"],
            "log_e": fem_global["log_e"],
            "fem_global_n": fem_global["fem_global_n"],
        },
        "buckling": [row for n in hinges for row in _buckling(n, fem_global)],
        "curls": [],
    }
    for name in args.fem_curls.split(","):
        path = _DATA / name
        if not path.exists():
            continue
        fem = json.loads(path.read_text())["record"]
        record["curls"].append(
            {
                "file": f"tests/data/{name}",
                "curl_mesh": fem["curl_mesh"],
                "bend_target_rad": fem["bend_target_rad"],
                "rows": [row for n in hinges for row in _curls(n, path)],
            }
        )
    out = {"provenance": provenance("flexure_hinges_record", command=command), "record": record}
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
