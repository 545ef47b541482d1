"""Records the Warp FEM with the printed tendon routing: the reference the chain's printed routing is tested on.

The FEM (`FemOptions(routing="printed")`: the tendon through the 18 channel points of
`mjcodesign.models.channels.channel_points`, frictionless) on the converged mesh the chain is calibrated to
(`mjcodesign.crosscheck.calibration.CONVERGED_MESH`):

* the unloaded finger's buckling tension of uniform fingers, ln E 13.5-17.0
  (`FemStability.buckling_tension`: follower only and linearised with the prestress);
* the free curl of random designs (`Stiffness.random`, finger A, seeds outside the calibration's) at the
  tension at which the printed chain bends ``--bend`` rad (found on the chain by bisection; all far
  below the chain's buckling tension), bend and tip displacement.

and (``--parts refinement``, one uniform finger, ``--refinement-log-e``) the buckling tension as the mesh is
refined, `REFINEMENT_MESHES`: linearised and over the global modes, and where the linearised mode's
energy lies (per block, at the cuts' feet, around the tendon's loaded vertices);

and on ``--path-mesh`` (cheaper: its static solves run to large curls) the equilibrium path of one uniform
finger, ``--path-log-e``, at increasing fractions of that mesh's linearised buckling tension
(`FemStability.path_stability`), until its tangent's smallest eigenvalue crosses zero or Newton fails.

    python3 scripts/fem_routing_record.py --out tests/data/fem_routing_printed.json

``tests/test_fem_routing.py`` compares the chain against the record without rerunning the FEM. Not part
of the package: a record of how the numbers in the cross-simulator page were made.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time

import numpy as np

from mjcodesign.bench.record import provenance
from mjcodesign.crosscheck.calibration import CONVERGED_MESH, TRAIN_SEEDS
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models import build_finger
from mjcodesign.models.stability import buckling_tension
from mjcodesign.models.types import FingerModel, SimOptions
from mjcodesign.scenarios.static import curl
from mjcodesign.sim.fem import FemFinger, FemOptions

LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)
"""ln E of the uniform fingers (those of the chain's closed-form test, tests/test_routing.py)."""
PRINTED = SimOptions(routing="printed", gravity=False)
"""The chain the record is compared with."""
PATH_MESH = {"h": 4e-3, "spine_layers": 2, "order": 2}
"""The path's mesh: quadratic tets within 4% of Euler-Bernoulli on the presets (`mjcodesign.sim.fem.finger`)."""
PATH_FRACTIONS = (0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.25, 1.5)
"""Tensions of the path, as fractions of its mesh's linearised buckling tension."""
REFINEMENT_MESHES = (
    {"h": 4e-3, "spine_layers": 2, "order": 2},
    {"h": 4e-3, "spine_layers": 4, "order": 2},
    {"h": 4e-3, "spine_layers": 8, "order": 2},
    CONVERGED_MESH,
)
"""Quadratic tets: the spine's layers (and with them the flexures' and cuts' cells) halved twice at 4 mm
cells, then the converged mesh (2 mm cells along the segments)."""
_BISECT_REL = 0.01  # the chain's tension for the target bend, to 1% [N]


def _chain_t_crit(log_e) -> float:
    built = build_finger(FingerDesign(), Stiffness(log_e), FingerModel.CHAIN, options=PRINTED)
    return buckling_tension(built)[0]


def _tension_for_bend(stiffness: Stiffness, bend: float, t_max: float) -> float:
    """The tension [N] at which the printed chain's finger A bends ``bend`` rad (bisection in log T)."""
    lo, hi = 1e-4 * t_max, t_max
    while hi / lo > 1 + _BISECT_REL:
        mid = np.sqrt(lo * hi)
        got = curl(FingerDesign(), stiffness, "chain", mid, options=PRINTED)["bend_angle_rad"]
        lo, hi = (mid, hi) if got < bend else (lo, mid)
    return float(np.sqrt(lo * hi))


def _buckling_row(fem: FemFinger, log_e: float) -> dict:
    """The uniform finger ``log_e``'s buckling (`FemStability.buckling_tension`) and the chain's."""
    t0 = time.perf_counter()
    fem.set_log_e([log_e] * 22)
    b = fem.buckling_tension()
    return {
        "log_e": log_e,
        "fem_follower_eigenvalue_per_n": b.follower_eigenvalue_per_n,
        "fem_follower_n": b.follower_tension_n,
        "fem_linearised_n": b.linearised_tension_n,
        "fem_mode_block": b.mode_block,
        "fem_mode_block_angles": list(b.mode_block_angles),
        "fem_mode_block_energy": list(b.mode_block_energy),
        "fem_mode_energy_at_feet": b.mode_energy_at_feet,
        "fem_mode_energy_at_tendon": b.mode_energy_at_tendon,
        "fem_global_n": b.global_tension_n,
        "fem_global_mode_block_energy": list(b.global_mode_block_energy),
        "fem_global_mode_energy_at_feet": b.global_mode_energy_at_feet,
        "chain_n": _chain_t_crit([log_e] * 11),
        "seconds": time.perf_counter() - t0,
    }


def _buckling(fem: FemFinger, rows: list, log) -> None:
    for log_e in LOG_E:
        rows.append(_buckling_row(fem, log_e))
        log(rows[-1])


def _refinement(log_e: float, rows: list, log) -> None:
    for mesh in REFINEMENT_MESHES:
        fem = FemFinger(
            FingerDesign(), Stiffness([log_e] * 11), options=FemOptions(**mesh, routing="printed")
        )
        rows.append({"mesh": mesh, "free_dofs": int(fem.free_dof.sum()), **_buckling_row(fem, log_e)})
        log(rows[-1])


def _path(log_e: float, row: dict, log) -> None:
    """Fill ``row`` with the path of the uniform finger ``log_e``, point by point (logged as it goes)."""
    t0 = time.perf_counter()
    fem = FemFinger(
        FingerDesign(), Stiffness([log_e] * 11), options=FemOptions(**PATH_MESH, routing="printed")
    )
    t_lin = fem.buckling_tension().linearised_tension_n
    row.update(log_e=log_e, mesh=PATH_MESH, fem_linearised_n=t_lin, chain_n=_chain_t_crit([log_e] * 11))
    row.update(tensions_n=[], eigenvalues=[], bend_angles_rad=[], critical_tension_n=None)

    def point(tension, lam, bend):
        row["tensions_n"].append(tension)
        row["eigenvalues"].append(lam)
        row["bend_angles_rad"].append(bend)
        log({"tension_n": tension, "eigenvalue": lam, "bend_rad": bend})

    path = fem.path_stability(np.array(PATH_FRACTIONS) * t_lin, on_point=point)
    row.update(
        critical_tension_n=path.critical_tension_n,
        failed_tension_n=path.failed_tension_n,
        seconds=time.perf_counter() - t0,
    )


def _curls(fem: FemFinger, seeds, bend: float, rows: list, log) -> None:
    for seed in seeds:
        t0 = time.perf_counter()
        stiffness = Stiffness.random(seed)
        t_crit = _chain_t_crit(stiffness.log_e[0])
        tension = _tension_for_bend(stiffness, bend, t_crit)
        fem.set_log_e(stiffness.log_e)
        c = fem.curl(tension)
        rows.append(
            {
                "design": f"random:{seed}",
                "tension_n": tension,
                "chain_t_crit_n": t_crit,
                "fem_bend_angle_rad": c.bend_angle_rad,
                "fem_tip_displacement_m": list(c.tip_displacement_m),
                "fem_solve_stats": fem.solve_stats,
                "seconds": time.perf_counter() - t0,
            }
        )
        log(rows[-1])


def main(argv=None) -> None:
    """Solve the FEM cases the flags name and write the record (provenance, then the numbers)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True, help="JSON record to write")
    p.add_argument("--seeds", default="0..9", help="Stiffness.random seeds of the curl designs, A..B")
    p.add_argument("--bend", type=float, default=1.0, help="the chain's bend [rad] that sets each tension")
    p.add_argument("--path-log-e", type=float, default=13.5, help="ln E of the path's uniform finger")
    p.add_argument(
        "--refinement-log-e", type=float, default=15.0, help="ln E of the mesh refinement's uniform finger"
    )
    p.add_argument(
        "--parts", default="buckling,curl,path", help="what to record (buckling, curl, path, refinement)"
    )
    p.add_argument(
        "--curl-mesh",
        choices=("converged", "path"),
        default="converged",
        help="the curls' mesh: CONVERGED_MESH, or PATH_MESH where a converged curl is too slow",
    )
    args = p.parse_args(argv)
    a, b = (int(v) for v in args.seeds.split(".."))
    seeds = [s for s in range(a, b + 1) if s not in TRAIN_SEEDS]
    parts = args.parts.split(",")

    command = shlex.join(
        ["python3", "scripts/fem_routing_record.py", *(sys.argv[1:] if argv is None else argv)]
    )
    curl_mesh = CONVERGED_MESH if args.curl_mesh == "converged" else PATH_MESH
    record: dict = {
        "mesh": CONVERGED_MESH,
        "curl_mesh": curl_mesh,
        "log_e": list(LOG_E),
        "bend_target_rad": args.bend,
    }
    out = {"provenance": provenance("fem_routing_record", command=command), "record": record}

    def log(row):
        # Rewritten after every case, so a stopped run keeps what it finished.
        print(json.dumps(row), flush=True)
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)

    fem = None
    if "buckling" in parts or ("curl" in parts and curl_mesh is CONVERGED_MESH):
        options = FemOptions(**CONVERGED_MESH, routing="printed")
        fem = FemFinger(FingerDesign(), Stiffness([LOG_E[0]] * 11), options=options)
    if "buckling" in parts:
        _buckling(fem, record.setdefault("buckling", []), log)
    if "curl" in parts:
        if curl_mesh is not CONVERGED_MESH:
            fem = FemFinger(
                FingerDesign(), Stiffness([LOG_E[0]] * 11), options=FemOptions(**curl_mesh, routing="printed")
            )
        _curls(fem, seeds, args.bend, record.setdefault("curl", []), log)
    if "refinement" in parts:
        _refinement(args.refinement_log_e, record.setdefault("refinement", []), log)
    if "path" in parts:
        _path(args.path_log_e, record.setdefault("path", {}), log)
        log({"path_critical_tension_n": record["path"]["critical_tension_n"]})


if __name__ == "__main__":
    main()
