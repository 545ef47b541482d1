"""Benchmark of grasp candidates: penetration, approach spread, MuJoCo success and poses/s.

Per object: sample ``per_object`` poses (:func:`mjcodesign.poses.sample_poses`), and, when the authors'
AnyGrasp folder is given, import and refine theirs (:func:`mjcodesign.poses.import_anygrasp`): how many
of their rows survive, and why each refused row is refused; then run the fixed grasp motion on the
semi-rigid chain gripper in MuJoCo for every accepted pose. The sampler's time excludes loading the
mesh, its repair and its decomposition; the signed-distance grid is built (or read from the cache)
before the clock starts and timed apart (``sdf_grid_s``). ``cpu_seconds`` is the process's CPU time
(every thread), which a machine shared with other work inflates less than the wall time.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from mjcodesign.errors import MjcodesignError
from mjcodesign.scenarios.outcome import Failure

__all__ = ["FIXED_DESIGNS", "bench_poses"]

_DESIGN = "semi-rigid"  # the reference design: log E 16.5 everywhere
FIXED_DESIGNS = ("semi-rigid", "soft", "paper-optimized") + tuple(f"random:{i}" for i in range(8))
"""The fixed 11-design set of ``--designs fixed11``: does any design hold a pose?"""


def _simulate(obj, cands, scenario, sim, designs: tuple[str, ...] = (_DESIGN,)) -> list[dict]:
    """Rollouts of every candidate with each design (``run_jobs`` batches designs per pose).

    Each row has the first design's ``success`` and ``reason``, and with several designs the list
    ``held_by`` of those that held it.
    """
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.jobs import GraspJob, run_jobs
    from mjcodesign.poses import to_gripper_pose

    stiff = [Stiffness.parse(d) for d in designs]
    jobs, rows = [], []
    for i in range(len(cands)):
        try:
            pose = to_gripper_pose(cands, i)
        except MjcodesignError as exc:
            rows.append({"success": False, "reason": f"{type(exc).__name__}: {exc}", "held_by": []})
            continue
        rows.append(None)
        jobs += [GraspJob(obj=obj, pose=pose, design=d, scenario=scenario) for d in stiff]
    outs = iter(run_jobs(jobs, sim))
    result = []
    for r in rows:
        if r is None:
            per = [next(outs) for _ in designs]
            r = {**_row(per[0]), "held_by": [d for d, o in zip(designs, per, strict=True) if o.success]}
        result.append(r if len(designs) > 1 else {k: v for k, v in r.items() if k != "held_by"})
    return result


def _row(out) -> dict:
    # A bad pose keeps the message the scene raised (PoseError: ...), as when it was raised here.
    reason = (
        out.reason.replace("bad pose: ", "PoseError: ", 1) if out.failure is Failure.BAD_POSE else out.reason
    )
    return {"success": bool(out.success), "reason": reason}


def _summary(cands, seconds: float, sims: list[dict], cpu_seconds: float) -> dict:
    from mjcodesign.poses import approach_spread_deg

    n = len(cands)
    return {
        "accepted": n,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "poses_per_s": n / seconds if seconds > 0 else 0.0,
        "penetration_max_m": float(max(0.0, -float(cands.min_signed_distance.min()))) if n else 0.0,
        "approach_spread_deg": approach_spread_deg(cands.approaches()),
        "top_share": float(np.mean(cands.approaches()[:, 2] < -np.cos(np.deg2rad(45.0)))) if n else 0.0,
        "successes": int(sum(r["success"] for r in sims)),
        "simulated": len(sims),
        "rejected": dict(cands.rejected),
        "failures": sorted({r["reason"] for r in sims if not r["success"]}),
        **({"held_by": [r["held_by"] for r in sims]} if sims and "held_by" in sims[0] else {}),
    }


def _imported(ag, rows: int) -> dict:
    """How many of the file's rows survive refinement, and why each refused row is refused."""
    kept = sorted({int(i) for i in ag.source_index})
    refused = [r for r in ag.refused_dicts() if r["source_index"] not in kept]
    reasons: dict[str, int] = {}
    for r in refused:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    return {
        "imported": rows,
        "survived": len(kept),
        "survived_rows": kept,
        "refused": refused,
        "refused_by_reason": reasons,
    }


def _aggregate(rows: list[dict], key: str) -> dict:
    parts = [r[key] for r in rows if key in r]
    accepted = sum(p["accepted"] for p in parts)
    sims = sum(p["simulated"] for p in parts)
    secs = sum(p["seconds"] for p in parts)
    cpu = sum(p["cpu_seconds"] for p in parts)
    out = {}
    if parts and "imported" in parts[0]:
        reasons: dict[str, int] = {}
        for p in parts:
            for k, v in p["refused_by_reason"].items():
                reasons[k] = reasons.get(k, 0) + v
        out = {
            "imported": sum(p["imported"] for p in parts),
            "survived": sum(p["survived"] for p in parts),
            "refused_by_reason": reasons,
        }
    held = [h for p in parts for h in p.get("held_by", [])]
    if held:  # the fixed design set: (object, pose) pairs that every design lets fall
        out["all_designs_fail"] = sum(not h for h in held)
        out["all_designs_fail_fraction"] = out["all_designs_fail"] / len(held)
    return {
        **out,
        "objects": len(parts),
        "accepted": accepted,
        "penetration_max_m": max((p["penetration_max_m"] for p in parts), default=0.0),
        "approach_spread_deg_mean": float(np.mean([p["approach_spread_deg"] for p in parts]))
        if parts
        else 0.0,
        "success_fraction": sum(p["successes"] for p in parts) / sims if sims else 0.0,
        "simulated": sims,
        "seconds": secs,
        "cpu_seconds": cpu,
        "poses_per_s": accepted / secs if secs > 0 else 0.0,
        "poses_per_cpu_s": accepted / cpu if cpu > 0 else 0.0,
    }


def bench_poses(
    objects: list[str],
    per_object: int = 4,
    *,
    seed: int = 0,
    density: float = 100.0,
    impulse: float | None = None,
    top_fraction: float = 0.0,
    anygrasp_dir: str | Path | None = None,
    simulate: bool = True,
    allow_open: bool = False,
    designs: tuple[str, ...] = (_DESIGN,),
    cache_dir: str | Path | None = None,
) -> dict:
    """Per-object rows and totals (JSON-ready). Objects that cannot be loaded are listed with the reason.

    ``designs``: the first is the reference whose success is reported; with several (e.g.
    :data:`FIXED_DESIGNS`) every pose runs with each, and the totals count the (object, pose) pairs that
    every design fails (``all_designs_fail``).
    """
    from mjcodesign.objects import CoacdSettings, convex_decomposition, load_mesh, load_object
    from mjcodesign.poses import SamplerOptions, import_anygrasp, load_external, sample_poses
    from mjcodesign.poses.grid import ObjectSDF
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
            obj = load_object(name, density, allow_open=allow_open, seed=seed, cache_dir=cache_dir)
            convex_decomposition(obj, CoacdSettings(seed=seed), cache_dir=cache_dir)
            t0 = time.perf_counter()
            grid = ObjectSDF(obj.mesh, cache_dir=cache_dir).grid  # built once, then read from the cache
            row["sdf_grid_s"] = time.perf_counter() - t0
            row["sdf_grid_nodes"] = int(grid.values.size)
            t0, c0 = time.perf_counter(), time.process_time()
            cands = sample_poses(obj, per_object, seed=seed, options=options, cache_dir=cache_dir)
            secs, cpu = time.perf_counter() - t0, time.process_time() - c0
            sims = _simulate(obj, cands, scenario, sim, designs) if simulate else []
            row["sampler"] = _summary(cands, secs, sims, cpu)
            path = Path(anygrasp_dir) / f"{name}.npz" if anygrasp_dir is not None else None
            if path is not None and path.is_file():
                T = load_external(path)
                t0, c0 = time.perf_counter(), time.process_time()
                ag = import_anygrasp(
                    obj, T, load_mesh(name).vertices, seed=seed, source=path.name, cache_dir=cache_dir
                )
                secs, cpu = time.perf_counter() - t0, time.process_time() - c0
                sims = _simulate(obj, ag.head(per_object), scenario, sim, designs) if simulate else []
                row["anygrasp"] = {**_imported(ag, len(T)), **_summary(ag, secs, sims, cpu)}
        except MjcodesignError as exc:
            row["error"] = f"{type(exc).__name__}: {exc}"
    return {
        "design": designs[0],
        "designs": list(designs),
        "per_object": per_object,
        "seed": seed,
        "density_kg_m3": density,
        "impulse_ns": scenario.impulse,
        "sampler": _aggregate(rows, "sampler"),
        "anygrasp": _aggregate(rows, "anygrasp"),
        "objects": rows,
    }
