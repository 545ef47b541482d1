"""The chain's two tendon routings compared: buckling tension and grasps of the 50 g box.

``guided`` (the default: a waypoint on every block, constant levers) against ``printed`` (through the
segments' channels at the printed finger's heights, straight across each flexure gap;
`mjcodesign.models.channels`; each flexure two hinges tied to one angle, the routing's default):

* the straight finger's buckling tension of uniform fingers, ln E 13.5-17.0 (`mjcodesign.models.stability`,
  MuJoCo's forces differenced), against the closed form k (a+b)/(ab) of the first flexure to go as one
  hinge across the channel ends;
* the tests' 50 g box (50 mm, 400 kg/m³, auto pose) grasped by the three presets and by uniform fingers,
  under force 4 N (the FEM grasp study's), force 10 N (the default) and position 1000 ticks (the
  hardware servo): the outcome, and the most outward turn of finger A's flexures during the rollout
  (the sum of its hinges; negative: a flexure folded outward, opening its gap);
* the printed routing's position-mode grasps of soft and semi-rigid at 2 ms and 0.25 ms steps (its
  default is 1 ms).

    python3 scripts/routing_compare.py --out benchmarks/records/2026-12-05_routing_compare_tied.json

About a minute on one core. Not part of the package: a record of how the numbers in the models page
were made.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys

import mujoco
import numpy as np

from mjcodesign.bench.record import provenance
from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.models import build_finger
from mjcodesign.models.chain import hinge_stiffness
from mjcodesign.models.channels import channel_points
from mjcodesign.models.stability import buckling_tension
from mjcodesign.models.types import ROUTINGS, FingerModel, SimOptions
from mjcodesign.objects import box_object
from mjcodesign.scenarios import parse_tendon
from mjcodesign.scenarios.grasp import (
    GraspScenario,
    auto_pose,
    build_scene,
    control_spec,
    drive_scene,
    phase_controls,
)
from mjcodesign.sim import MujocoBackend
from mjcodesign.sim.mujoco_c import STATE_SPEC, initial_state

_LOG_E = (13.5, 14.0, 14.5, 15.0, 15.5, 16.0, 16.5, 17.0)
_DRIVES = ("force:4", "force:10", "position:1000")
_PRESETS = ("soft", "semi-rigid", "paper-optimized")
_STEPS = (2e-3, 2.5e-4)  # [s]: the printed routing's position-mode grasps beside its default 1 ms


def _buckling() -> list[dict]:
    design = FingerDesign()
    pts = channel_points(design)
    flex = [b for b in design.blocks() if b.kind is BlockKind.FLEXURE]
    rows = []
    for log_e in _LOG_E:
        built = build_finger(
            design,
            Stiffness([log_e] * 11),
            FingerModel.CHAIN,
            options=SimOptions(routing="printed", gravity=False),
        )
        t_crit, mode = buckling_tension(built)
        k = hinge_stiffness(design, np.full(design.n_blocks, np.exp(log_e)))  # each block's, one hinge
        closed = [
            k[f.index] * (a + b) / (a * b)
            for f, a, b in ((f, f.mid - pts[i, 2, 0], pts[i + 1, 0, 0] - f.mid) for i, f in enumerate(flex))
        ]
        rows.append(
            {
                "log_e": log_e,
                "t_crit_n": t_crit,
                "closed_form_n": min(closed),
                "ratio": t_crit / min(closed),
                "mode_block": built.fingers[0].joint_blocks[int(np.argmax(np.abs(mode)))],
                "closed_form_flexure_block": flex[int(np.argmin(closed))].index,
            }
        )
    return rows


def _most_outward(scene, scenario) -> float:
    """Smallest turn [rad] any of finger A's flexures (the sum of its hinges) reaches in the rollout."""
    scene = drive_scene(scene, scenario)
    m = scene.model
    ctrl, _ = phase_controls(scene, scenario)
    d = mujoco.MjData(m)
    mujoco.mj_setState(m, d, initial_state(scene), mujoco.mjtState(STATE_SPEC))
    hand = scene.built.fingers[0]
    blocks = np.array(hand.joint_blocks)
    adr = np.array([m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in hand.joints])
    flexures = [adr[blocks == b.index] for b in scene.built.design.blocks() if b.kind is BlockKind.FLEXURE]
    low = 0.0
    for row in ctrl:
        mujoco.mj_setState(m, d, row, control_spec())
        mujoco.mj_step(m, d)
        low = min(low, min(float(d.qpos[a].sum()) for a in flexures))
    return low


def _grasps() -> list[dict]:
    obj = box_object((0.05,) * 3, 400.0)
    designs = [(p, Stiffness.preset(p)) for p in _PRESETS] + [
        (f"uniform {e}", Stiffness([e] * 11)) for e in _LOG_E
    ]
    rows = []
    for drive in _DRIVES:
        scenario = GraspScenario(tendon=parse_tendon(drive))
        for name, stiffness in designs:
            for routing in ROUTINGS:
                scene = build_scene(
                    obj,
                    FingerDesign(),
                    stiffness,
                    FingerModel.CHAIN,
                    auto_pose(obj),
                    options=SimOptions(routing=routing),
                )
                out = MujocoBackend(nthread=1).run(scene, scenario).as_dict()
                rows.append(
                    {
                        "drive": drive,
                        "design": name,
                        "routing": routing,
                        "success": bool(out["success"]),
                        "reason": out["reason"],
                        "most_outward_flexure_rad": _most_outward(scene, scenario),
                    }
                )
    return rows


def _timesteps() -> list[dict]:
    """The printed routing in position mode at finer steps than the default 2 ms."""
    obj = box_object((0.05,) * 3, 400.0)
    scenario = GraspScenario(tendon=parse_tendon("position:1000"))
    rows = []
    for dt in _STEPS:
        for name in ("soft", "semi-rigid"):
            options = SimOptions(routing="printed", timestep=dt)  # two tied hinges per flexure
            scene = build_scene(
                obj,
                FingerDesign(),
                Stiffness.preset(name),
                FingerModel.CHAIN,
                auto_pose(obj),
                options=options,
            )
            out = MujocoBackend(nthread=1).run(scene, scenario).as_dict()
            rows.append(
                {"timestep_s": dt, "design": name, "success": bool(out["success"]), "reason": out["reason"]}
            )
    return rows


def main() -> None:
    """Run both comparisons and write the record."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="record file (JSON)")
    args = p.parse_args()
    command = shlex.join(["python3", "scripts/routing_compare.py", *sys.argv[1:]])
    record = {"buckling": _buckling(), "grasps": _grasps(), "printed_position_timesteps": _timesteps()}
    ok = {r: sum(g["success"] for g in record["grasps"] if g["routing"] == r) for r in ROUTINGS}
    record["successes"] = {r: f"{ok[r]} of {len(record['grasps']) // len(ROUTINGS)}" for r in ROUTINGS}
    with open(args.out, "w", encoding="utf-8") as f:
        json.dump(
            {"provenance": provenance("routing_compare", command=command), "record": record}, f, indent=1
        )
        f.write("\n")
    print(json.dumps(record["successes"]))


if __name__ == "__main__":
    main()
