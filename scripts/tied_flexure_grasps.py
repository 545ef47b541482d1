"""Grasps of the printed chain with one guided hinge per flexure against two hinges tied to one angle.

    python3 scripts/tied_flexure_grasps.py --out benchmarks/records/2026-12-05_tied_flexure_grasps.json

The grasps that the one-hinge printed chain (its flexure guides, ``SimOptions(routing="printed")``) was
checked on, as ``mjcodesign grasp --routing printed --object O --design D --regime R --json`` runs them:
O 013_apple and 025_mug, D soft, semi-rigid, random:3 and random:12, R real (the servo at 1000 ticks) and
paper (10 N). Each runs under the one-hinge chain (``hinges_per_block=1``) and the chain whose flexures
have two hinges tied by joint equalities (the routing's default), at its 1 ms step and at 2 ms. Per
grasp: the outcome
and its reason (a diverged rollout stays ``diverged``), and from the rollout's states finger A's and B's
largest tie violation |θ_j − θ_{j+1}| [rad], the most inward and outward flexure turn [rad] and the
flexures' largest stop violation. Also the tied chain's buckling tension of uniform fingers against the
converged FEM's over its global modes.

Several minutes on one core. Not part of the package: a record of how the numbers in the docs were made.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from dataclasses import replace

import mujoco
import numpy as np

_OBJECTS = ("013_apple", "025_mug")
_DESIGNS = ("soft", "semi-rigid", "random:3", "random:12")
_REGIMES = ("real", "paper")
_LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)  # uniform fingers, those of tests/test_routing.py


def _models() -> dict:
    from mjcodesign.models.types import DEFAULT_TIMESTEP, SimOptions

    tied = SimOptions(routing="printed")  # the routing's default: two tied hinges at TIED_TIMESTEP
    return {
        "one hinge, guides": SimOptions(routing="printed", hinges_per_block=1),
        "two tied hinges, 2 ms": replace(tied, timestep=DEFAULT_TIMESTEP),
        "two tied hinges, 1 ms": tied,
    }


class _Angles:
    """Observer: from every state of a rollout, the tie violations and flexure turns of both fingers."""

    def __init__(self) -> None:
        self.last: dict = {}

    def rollout(self, rollout) -> None:
        from mjcodesign.design.finger import BlockKind
        from mjcodesign.sim.mujoco_c import STATE_SPEC

        m = rollout.model
        d = mujoco.MjData(m)
        design = rollout.scene.built.design
        flexures = [b.index for b in design.blocks() if b.kind is BlockKind.FLEXURE]
        pairs, flex_adr = [], []
        for h in rollout.scene.built.fingers:
            blocks = np.array(h.joint_blocks)
            adr = np.array(
                [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in h.joints]
            )
            for f in flexures:
                a = adr[blocks == f]
                flex_adr.append(a)
                pairs += list(zip(a[:-1], a[1:], strict=True))
        tie, inward, outward = 0.0, -np.inf, np.inf
        for row in rollout.states:
            mujoco.mj_setState(m, d, row, mujoco.mjtState(STATE_SPEC))
            q = d.qpos
            if pairs:
                tie = max(tie, max(abs(q[a] - q[b]) for a, b in pairs))
            turns = [q[a].sum() for a in flex_adr]
            inward, outward = max(inward, max(turns)), min(outward, min(turns))
        self.last = {
            "steps": len(rollout.states),
            "max_tie_violation_rad": float(tie),
            "final_tie_violation_rad": float(max((abs(q[a] - q[b]) for a, b in pairs), default=0.0)),
            "most_inward_flexure_rad": float(inward),
            "most_outward_flexure_rad": float(outward),
        }

    def snapshot(self, snapshot) -> None:
        """Unused: grasps only."""

    def close(self) -> None:
        """Nothing to flush."""


def _grasps(objects, designs, regimes) -> list[dict]:
    from mjcodesign.cli.common import user_cache_dir
    from mjcodesign.cli.grasp import grasp, prepare_object
    from mjcodesign.errors import SimulationDiverged
    from mjcodesign.scenarios import get_regime

    rows = []
    for regime in regimes:
        density, mass = get_regime(regime).masses(None, None)
        for obj in objects:
            prepared = prepare_object(obj, density, "auto", mass=mass, cache_dir=user_cache_dir())
            for design in designs:
                for name, options in _models().items():
                    angles = _Angles()
                    t0 = time.perf_counter()
                    try:
                        out = grasp(
                            obj,
                            design,
                            "chain",
                            regime=regime,
                            observer=angles,
                            prepared=prepared,
                            options=options,
                            cache_dir=user_cache_dir(),
                        )
                        outcome = {k: out[k] for k in ("success", "failure", "failures", "reason")}
                    except SimulationDiverged as exc:  # a diverged rollout stays flagged, never dropped
                        outcome = {
                            "success": False,
                            "failure": "diverged",
                            "failures": ["diverged"],
                            "reason": str(exc),
                        }
                    row = {
                        "regime": regime,
                        "object": obj,
                        "design": design,
                        "flexure_model": name,
                        **outcome,
                        **angles.last,
                        "seconds": time.perf_counter() - t0,
                    }
                    rows.append(row)
                    print(json.dumps(row), file=sys.stderr)
    return rows


def _buckling() -> list[dict]:
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models import build_finger
    from mjcodesign.models.stability import buckling_tension
    from mjcodesign.models.types import FingerModel, SimOptions

    fem = json.loads(open("tests/data/fem_routing_refinement.json", encoding="utf-8").read())
    ref = fem["record"]["refinement"][-1]
    rows = []
    for log_e in _LOG_E:
        opts = SimOptions(routing="printed", gravity=False, hinges_per_block=2, tied_flexures=True)
        built = build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=opts)
        t, mode = buckling_tension(built)
        fem_n = ref["fem_global_n"] * np.exp(log_e - ref["log_e"])  # uniform: every tension ∝ E
        rows.append(
            {
                "log_e": log_e,
                "tied_n": t,
                "fem_global_n": fem_n,
                "tied_over_fem": t / fem_n,
                "mode_block": int(built.fingers[0].joint_blocks[int(np.argmax(np.abs(mode)))]),
            }
        )
    return rows


def main() -> None:
    """Run the grasps and the buckling tensions and write the record."""
    from mjcodesign.bench.record import provenance

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="record file (JSON)")
    p.add_argument("--objects", default=",".join(_OBJECTS))
    p.add_argument("--designs", default=",".join(_DESIGNS))
    p.add_argument("--regimes", default=",".join(_REGIMES))
    args = p.parse_args()
    command = shlex.join(["python3", "scripts/tied_flexure_grasps.py", *sys.argv[1:]])
    grasps = _grasps(args.objects.split(","), args.designs.split(","), args.regimes.split(","))
    summary = {}
    for regime in sorted({g["regime"] for g in grasps}):
        for name in _models():
            rows = [g for g in grasps if g["regime"] == regime and g["flexure_model"] == name]
            summary[f"{regime}, {name}"] = {
                "held": sum(g["success"] for g in rows),
                "diverged": sum("diverged" in g["failures"] for g in rows),
                "of": len(rows),
            }
    record = {
        "regimes": {"real": "XL330 at 1000 ticks, published masses", "paper": "10 N, density masses"},
        "summary": summary,
        "grasps": grasps,
        "buckling_tied": _buckling(),
    }
    with open(args.out, "w", encoding="utf-8") as f:
        json.dump(
            {"provenance": provenance("tied_flexure_grasps", command=command), "record": record}, f, indent=1
        )
        f.write("\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
