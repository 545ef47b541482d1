"""The grasp depth of the pose refinement: fixed (contacts 50 mm from the fingertips) against fitted.

Runs the pose refinement with and without ``fit_depth`` (:func:`mjcodesign.poses.refine.refine`) on

* the authors' AnyGrasp poses of 006_mustard_bottle (every row of their file), when the shared
  reference is present: the fingertips' height above the ground before and after, and grasps;
* a small landscape: the eight objects of :data:`mjcodesign.bench.landscape.OBJECTS` × 3 sampler poses;

and grasps each pose once with soft, semi-rigid and paper-optimized fingers (chain model, MuJoCo C) in
two regimes: the commands' default scenario at the ``light`` density, and the hardware's
(:data:`~mjcodesign.scenarios.grasp.REAL_REGIME`) at each object's published mass.

Usage: ``nice -n 10 python3 benchmarks/pose_depth.py --out benchmarks/records/DATE_pose_depth.json``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from mjcodesign.bench import write_json
from mjcodesign.bench.landscape import OBJECTS
from mjcodesign.bench.record import provenance
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.evaluation.stats import wilson
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.objects import load_mesh
from mjcodesign.poses import (
    DENSE_EDGE,
    RigidGripper,
    SamplerOptions,
    import_anygrasp,
    load_external,
    sample_poses,
    to_gripper_pose,
)
from mjcodesign.scenarios.grasp import REAL_REGIME, GraspScenario
from mjcodesign.sim import MujocoBackend

DESIGNS = ("soft", "semi-rigid", "paper-optimized")
REGIMES = {"default light": (GraspScenario(), {"density": "light"}), "real": (REAL_REGIME, {"mass": "real"})}
MUSTARD = "006_mustard_bottle"
_REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "codesign-soft-gripper"


def tip_heights(cands) -> np.ndarray:
    """Lowest finger point above the ground per pose [m], shape (n,)."""
    g = RigidGripper.build(FingerDesign(), DENSE_EDGE)
    x = g.world(cands.matrices[:, :3, :3], cands.matrices[:, :3, 3], cands.openings)
    return x[:, g.side != 0, 2].min(axis=1)


def grasp(posed: list, scenario, backend, scenes) -> dict:
    """One rollout per (object, pose, design): success per design and the failures' kinds."""
    jobs = [
        GraspJob(obj=obj, pose=to_gripper_pose(c, i), design=Stiffness.parse(d), scenario=scenario, label=d)
        for obj, c in posed
        for i in range(len(c))
        for d in DESIGNS
    ]
    outs = run_jobs(jobs, backend, scenes=scenes)
    per = {d: [o.success for j, o in zip(jobs, outs, strict=True) if j.label == d] for d in DESIGNS}
    rows = {}
    for d in DESIGNS:
        reasons: dict[str, int] = {}
        for j, o in zip(jobs, outs, strict=True):
            if j.label == d and not o.success:
                for f in o.failures:
                    reasons[f.value] = reasons.get(f.value, 0) + 1
        k = int(sum(per[d]))
        rows[d] = {
            "success": k,
            "of": len(per[d]),
            "rate_wilson_rollouts": wilson(k, len(per[d])).as_dict(),
            "failures": reasons,
            "per_pose": [bool(v) for v in per[d]],
        }
    return rows


def main() -> int:
    """Run both refinements, grasp, and write the record to ``--out``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--poses", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    backend, scenes = MujocoBackend(), SceneCache(size=4)
    record = {
        "provenance": provenance("pose_depth", command="python3 " + " ".join(sys.argv)),
        "designs": list(DESIGNS),
        "regimes": {k: {"scenario": repr(s), **kw} for k, (s, kw) in REGIMES.items()},
    }
    # The authors' mustard-bottle poses, every row in their order.
    path = _REFERENCE / "pose_info" / f"{MUSTARD}.npz"
    if path.is_file():
        T = load_external(path)
        mustard: dict = {"rows": len(T), "by_depth": {}}
        for fit in (False, True):
            entry: dict = {"regimes": {}}
            for regime, (scenario, kw) in REGIMES.items():
                obj = load_grasp_object(MUSTARD, **kw, seed=args.seed)
                t0 = time.perf_counter()
                c = import_anygrasp(obj, T, load_mesh(MUSTARD).vertices, fit_depth=fit, source=path.name)
                c = c.in_source_order()
                if "accepted_rows" not in entry:
                    h = tip_heights(c)
                    entry.update(
                        refine_s=time.perf_counter() - t0,
                        accepted_rows=[int(i) for i in c.source_index],
                        refused=c.refused_dicts(),
                        tip_height_mm=[round(1e3 * float(v), 2) for v in h],
                        com_height_mm=round(1e3 * _com_height(obj), 2),
                    )
                entry["regimes"][regime] = grasp([(obj, c)], scenario, backend, scenes)
            mustard["by_depth"]["fitted" if fit else "fixed"] = entry
        mustard["paired"] = _paired(mustard["by_depth"])
        record["mustard"] = mustard
    else:
        record["mustard"] = "skipped: the shared reference is absent"
    # The landscape: sampler poses of eight objects.
    land: dict = {"objects": list(OBJECTS), "poses_per_object": args.poses, "by_depth": {}}
    for fit in (False, True):
        entry = {"regimes": {}, "tip_height_mm": {}, "skipped": {}}
        t0 = time.perf_counter()
        posed = {}
        for name in OBJECTS:
            try:
                obj = load_grasp_object(name, "light", seed=args.seed)
                c = sample_poses(obj, args.poses, seed=args.seed, options=SamplerOptions(fit_depth=fit))
            except Exception as exc:  # noqa: BLE001 - an object that cannot be posed is reported
                entry["skipped"][name] = f"{type(exc).__name__}: {exc}"
                continue
            posed[name] = c
            entry["tip_height_mm"][name] = [round(1e3 * float(v), 2) for v in tip_heights(c)]
        entry["posing_s"] = time.perf_counter() - t0
        for regime, (scenario, kw) in REGIMES.items():
            objs = []
            for name, c in posed.items():
                objs.append((load_grasp_object(name, **kw, seed=args.seed), c))
            entry["regimes"][regime] = grasp(objs, scenario, backend, scenes)
        land["by_depth"]["fitted" if fit else "fixed"] = entry
        print(f"landscape fit_depth={fit}: {entry['regimes']}", file=sys.stderr, flush=True)
    record["landscape"] = land
    write_json(record, args.out)
    return 0


def _paired(by_depth: dict) -> dict:
    """Per regime and design, successes fixed and fitted on the rows both accepted (same source rows)."""
    fixed, fitted = by_depth["fixed"], by_depth["fitted"]
    both = sorted(set(fixed["accepted_rows"]) & set(fitted["accepted_rows"]))
    out: dict = {"rows": both}
    for regime in fixed["regimes"]:
        out[regime] = {}
        for d in DESIGNS:
            a = dict(zip(fixed["accepted_rows"], fixed["regimes"][regime][d]["per_pose"], strict=True))
            b = dict(zip(fitted["accepted_rows"], fitted["regimes"][regime][d]["per_pose"], strict=True))
            out[regime][d] = {
                "fixed": sum(a[r] for r in both),
                "fitted": sum(b[r] for r in both),
                "of": len(both),
            }
    return out


def _com_height(obj) -> float:
    """Height of the object's COM above the ground in the grasp scene [m]."""
    from mjcodesign.poses import scene_offset

    return float(scene_offset(obj)[2])


if __name__ == "__main__":
    raise SystemExit(main())
