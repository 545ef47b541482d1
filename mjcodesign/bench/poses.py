"""Benchmark of grasp candidates: penetration, approach spread, MuJoCo success and poses/s.

Per object: sample ``per_object`` poses (:func:`mjcodesign.poses.sample_poses`), and, when the authors'
AnyGrasp folder is given, import and refine theirs (:func:`mjcodesign.poses.import_anygrasp`); then
run the fixed grasp motion on the semi-rigid chain gripper in MuJoCo for every accepted pose.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from mjcodesign.errors import MjcodesignError
from mjcodesign.scenarios.outcome import Failure

__all__ = ["bench_poses"]

_DESIGN = "semi-rigid"  # the reference design: log E 16.5 everywhere


def _simulate(obj, cands, scenario, sim) -> list[dict]:
    """One rollout per candidate on the semi-rigid chain gripper (one ``run_poses`` batch)."""
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.jobs import GraspJob, run_jobs
    from mjcodesign.poses import to_gripper_pose

    design = Stiffness.preset(_DESIGN)
    jobs, rows = [], []
    for i in range(len(cands)):
        try:
            pose = to_gripper_pose(cands, i)
        except MjcodesignError as exc:
            rows.append({"success": False, "reason": f"{type(exc).__name__}: {exc}"})
            continue
        rows.append(None)
        jobs.append(GraspJob(obj=obj, pose=pose, design=design, scenario=scenario))
    outs = iter(run_jobs(jobs, sim))
    return [r if r is not None else _row(next(outs)) for r in rows]


def _row(out) -> dict:
    # A bad pose keeps the message the scene raised (PoseError: ...), as when it was raised here.
    reason = (
        out.reason.replace("bad pose: ", "PoseError: ", 1) if out.failure is Failure.BAD_POSE else out.reason
    )
    return {"success": bool(out.success), "reason": reason}


def _summary(cands, seconds: float, sims: list[dict]) -> dict:
    from mjcodesign.poses import approach_spread_deg

    n = len(cands)
    return {
        "accepted": n,
        "seconds": seconds,
        "penetration_max_m": float(max(0.0, -float(cands.min_signed_distance.min()))) if n else 0.0,
        "approach_spread_deg": approach_spread_deg(cands.approaches()),
        "top_share": float(np.mean(cands.approaches()[:, 2] < -np.cos(np.deg2rad(45.0)))) if n else 0.0,
        "successes": int(sum(r["success"] for r in sims)),
        "simulated": len(sims),
        "rejected": dict(cands.rejected),
        "failures": sorted({r["reason"] for r in sims if not r["success"]}),
    }


def _aggregate(rows: list[dict], key: str) -> dict:
    parts = [r[key] for r in rows if key in r]
    accepted = sum(p["accepted"] for p in parts)
    sims = sum(p["simulated"] for p in parts)
    secs = sum(p["seconds"] for p in parts)
    return {
        "objects": len(parts),
        "accepted": accepted,
        "penetration_max_m": max((p["penetration_max_m"] for p in parts), default=0.0),
        "approach_spread_deg_mean": float(np.mean([p["approach_spread_deg"] for p in parts]))
        if parts
        else 0.0,
        "success_fraction": sum(p["successes"] for p in parts) / sims if sims else 0.0,
        "simulated": sims,
        "poses_per_s": accepted / secs if secs > 0 else 0.0,
    }


def bench_poses(
    objects: list[str],
    per_object: int = 4,
    *,
    seed: int = 0,
    density: float = 100.0,
    impulse: float | None = None,
    top_fraction: float = 0.5,
    anygrasp_dir: str | Path | None = None,
    simulate: bool = True,
    cache_dir: str | Path | None = None,
) -> dict:
    """Per-object rows and totals (JSON-ready). Objects that cannot be loaded are listed with the reason."""
    from mjcodesign.objects import CoacdSettings, convex_decomposition, load_mesh, load_object
    from mjcodesign.poses import SamplerOptions, import_anygrasp, load_external, sample_poses
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.sim.protocol import get_backend

    scenario = GraspScenario() if impulse is None else GraspScenario(impulse=impulse)
    sim = get_backend("mujoco")
    options = SamplerOptions(top_fraction=top_fraction)
    rows = []
    for name in objects:
        row: dict = {"object": name}
        rows.append(row)
        try:
            obj = load_object(name, density, allow_open=True, seed=seed)
            convex_decomposition(obj, CoacdSettings(seed=seed), cache_dir=cache_dir)
            t0 = time.perf_counter()
            cands = sample_poses(obj, per_object, seed=seed, options=options)
            secs = time.perf_counter() - t0
            sims = _simulate(obj, cands, scenario, sim) if simulate else []
            row["sampler"] = _summary(cands, secs, sims)
            path = Path(anygrasp_dir) / f"{name}.npz" if anygrasp_dir is not None else None
            if path is not None and path.is_file():
                t0 = time.perf_counter()
                ag = import_anygrasp(obj, load_external(path), load_mesh(name).vertices, seed=seed)
                secs = time.perf_counter() - t0
                sims = _simulate(obj, ag.head(per_object), scenario, sim) if simulate else []
                row["anygrasp"] = {"imported": len(load_external(path)), **_summary(ag, secs, sims)}
        except MjcodesignError as exc:
            row["error"] = f"{type(exc).__name__}: {exc}"
    return {
        "design": _DESIGN,
        "per_object": per_object,
        "seed": seed,
        "density_kg_m3": density,
        "impulse_ns": scenario.impulse,
        "sampler": _aggregate(rows, "sampler"),
        "anygrasp": _aggregate(rows, "anygrasp"),
        "objects": rows,
    }
