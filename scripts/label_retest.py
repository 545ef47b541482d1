"""Test-retest of a perturbed dataset's labels: the same cells rerun under fresh perturbation draws.

    python3 scripts/label_retest.py --data DIR --poses N [--seed S] [--replicate R] [--workers W]
        [--shift-mm D1,D2,...] --out FILE.json

For N poses drawn (``--seed``) from those the design ranking scores (>= 8 designs, a measured
``success_p`` that varies over them: :func:`~mjcodesign.surrogate.ranking.ranking_fidelity`'s poses),
every design of the pose is rerun with the dataset's own procedure (K perturbed rollouts, extended to M
where they disagree) under the pose's ``--replicate``-th independent stream of draws
(:class:`~mjcodesign.data.sampling.PoseStreams`). Each cell then has two labels made the same way.

Reported: per cell, how often the two labels agree (the same success, within 0.1, within 0.25) and
their mean absolute difference; per pose, the Spearman over its designs between the two labels (0 where
the replicate is constant: it ranks nothing), its median ``r``. Classical test theory: a perfect
predictor of a cell's true success probability correlates with one label by about sqrt(r) at most, the
**ceiling** of the design-ranking fidelity these labels can show. Unlike the split-half estimate
(:func:`~mjcodesign.surrogate.ranking.split_half`), which must halve a cell's draws, this compares two
whole labels: no Spearman–Brown step and no adaptive-extension bias. The poses are chosen on the first
label varying, as the ranking's are, so the retest measures what that metric meets. Before the
replicate, the first chosen pose is rerun with its own draws and must give its stored labels exactly
(else exit 2: this code no longer makes the dataset). Objects load from datagen's CoACD cache.

``--shift-mm``: each pose is also rerun, under the same replicate's draws, with its palm moved by each
distance along both signs of each palm axis (x across the fingers, y the closing axis, z the approach
axis; :class:`~mjcodesign.models.types.GripperPose`). Per axis and distance, the Spearman between the
first label and the moved pose's label, beside the unmoved retest's on the same poses (the paired
difference, its interval resampling objects): how far a grasp can move before its design ranking is
another one. A moved pose counts only where every design has a usable rollout (a palm moved into the
object gives none).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

_WORKER = None


def _fail(message: str) -> None:
    """Exit 2 with ``message`` as the one line on stderr (bad input)."""
    print(f"label_retest: {message}", file=sys.stderr)
    sys.exit(2)


def _run(task) -> tuple[int, int, dict[int, tuple[float, int]]]:
    """One replicate shard: (object, pose) and per design index its (success_p, rollouts)."""
    global _WORKER
    from mjcodesign.data.tasks import Worker

    if _WORKER is None:
        _WORKER = Worker(nthread=1)
    (res,) = _WORKER.run([task])
    s = res.samples.to_pydict()
    cells = {
        int(d): (float(p), int(n))
        for d, p, n in zip(s["design_index"], s["success_p"], s["rollouts"], strict=True)
    }
    return task.object_index, task.pose_index, cells


def varying_poses(
    obj: np.ndarray, pose: np.ndarray, p: np.ndarray, min_designs: int
) -> list[tuple[int, int]]:
    """(object_index, pose_index) of the poses with >= ``min_designs`` samples whose ``p`` varies."""
    uniq, inverse = np.unique(np.stack([obj, pose], axis=1), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    count = np.bincount(inverse, minlength=len(uniq))
    high = np.full(len(uniq), -np.inf)
    np.maximum.at(high, inverse, p)
    low = np.full(len(uniq), np.inf)
    np.minimum.at(low, inverse, p)
    keep = (count >= min_designs) & (high - low > 1e-12)
    out = [(int(o), int(q)) for o, q in uniq[keep]]
    return out


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman of one pose's two labels over its designs; 0 where one is constant (it ranks nothing)."""
    from mjcodesign.surrogate.ranking import group_spearman

    r = group_spearman(y, x, [np.arange(len(x))])[0] if len(x) >= 2 else float("nan")
    return 0.0 if np.isnan(r) else float(r)


def retest_summary(first: dict, second: dict) -> dict:
    """Agreement of two labels per cell and per pose; ``first``/``second``: (object, pose) -> {design: p}."""
    a, b, rho = [], [], []
    for key, cells in first.items():
        both = sorted(set(cells) & set(second.get(key, {})))
        x = np.array([cells[d] for d in both])
        y = np.array([second[key][d] for d in both])
        a.extend(x)
        b.extend(y)
        rho.append(_spearman(x, y))
    a, b, rho = np.array(a), np.array(b), np.array(rho)
    diff = np.abs(a - b)
    med = float(np.median(rho)) if len(rho) else float("nan")
    q25, q75 = np.percentile(rho, [25, 75]) if len(rho) else (float("nan"),) * 2
    return {
        "cells": int(len(a)),
        "same_success": float(np.mean((a >= 0.5) == (b >= 0.5))),
        "within_0.1": float(np.mean(diff <= 0.1 + 1e-12)),
        "within_0.25": float(np.mean(diff <= 0.25 + 1e-12)),
        "mean_abs_difference": float(diff.mean()),
        "poses": int(len(rho)),
        "pose_spearman": {
            "median": med,
            "iqr": [float(q25), float(q75)],
            "mean": float(rho.mean()),
            "positive": int(np.sum(rho > 0)),
        },  # fmt: skip
        "ceiling": float(np.sqrt(med)) if med > 0 else 0.0,
    }


AXES = ("x", "y", "z")
"""The palm axes a pose is moved along (:class:`~mjcodesign.models.types.GripperPose`'s frame)."""


def shifted_matrix(matrix, axis: int, distance_m: float) -> tuple[float, ...]:
    """The 4x4 row-major palm pose ``matrix`` moved by ``distance_m`` along its own axis ``axis``."""
    t = np.array(matrix, dtype=float).reshape(4, 4)
    t[:3, 3] += distance_m * t[:3, axis]
    return tuple(t.ravel())


def _pose_rho(first: dict, second: dict) -> float | None:
    """:func:`_spearman` of one pose's labels ({design: p}); None unless ``second`` has every design."""
    if set(first) - set(second):
        return None
    d = sorted(first)
    return _spearman(np.array([first[k] for k in d]), np.array([second[k] for k in d]))


def shift_summary(first: dict, retest: dict, moved: dict, *, seed: int = 0) -> dict:
    """Per moved distance: the design ranking of the moved poses against the first label.

    ``first``/``retest``: (object, pose) -> {design: p}, the stored and the unmoved replicate's labels;
    ``moved``: (axis, signed distance in mm) -> the same for the moved poses (designs without a usable
    rollout left out). Per axis and distance (both signs pooled: a pose's mean over the signs it has),
    and over every axis: the median and mean Spearman of the moved poses, the unmoved retest's mean on
    the same poses and the paired difference with its object-resampled 95 % interval; and the mean
    absolute difference of a cell's two labels, moved and unmoved.
    """
    from mjcodesign.evaluation.stats import cluster_bootstrap_mean

    base = {k: _pose_rho(v, retest.get(k, {})) for k, v in first.items()}
    distances = sorted({abs(d) for _, d in moved})
    groups = {f"{a}{d:g}mm": [(a, d), (a, -d)] for d in distances for a in AXES}
    groups |= {f"all{d:g}mm": [(a, s * d) for a in AXES for s in (1, -1)] for d in distances}
    out = {}
    for name, keys in groups.items():
        rho, rho0, obj, dp, dp0 = [], [], [], [], []
        for key, cells in first.items():
            scored = [(g, _pose_rho(cells, g)) for k in keys if (g := moved.get(k, {}).get(key)) is not None]
            scored = [(g, r) for g, r in scored if r is not None]  # None: a design without a usable rollout
            if scored and base[key] is not None:
                rho.append(float(np.mean([r for _, r in scored])))
                rho0.append(base[key])
                obj.append(key[0])
                dp.extend(abs(g[d] - v) for g, _ in scored for d, v in cells.items())
                dp0.extend(abs(retest[key][d] - v) for d, v in cells.items())
        if not rho:
            out[name] = {"poses": 0}
            continue
        rho, rho0 = np.array(rho), np.array(rho0)
        diff = cluster_bootstrap_mean(rho - rho0, np.array(obj), np.random.default_rng(seed))
        out[name] = {
            "poses": int(len(rho)),
            "objects": int(len(set(obj))),
            "median": float(np.median(rho)),
            "mean": float(rho.mean()),
            "retest_median": float(np.median(rho0)),
            "retest_mean": float(rho0.mean()),
            "paired_difference": {"mean": diff.value, "ci95": [diff.low, diff.high]},
            "mean_abs_difference": float(np.mean(dp)),
            "retest_mean_abs_difference": float(np.mean(dp0)),
        }
    return out


def main() -> None:
    """Parse the flags, rerun the cells, write the JSON and print it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--poses", type=int, default=100, help="varying poses to rerun")
    ap.add_argument("--seed", type=int, default=0, help="seeds the choice of poses")
    ap.add_argument("--replicate", type=int, default=1, help="which independent stream of draws (>= 1)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--shift-mm", default="", help="also move each palm by these distances [mm], e.g. 2,5,10")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    if a.poses < 1 or a.replicate < 1 or a.workers < 1:
        _fail("--poses, --replicate and --workers must be at least 1")
    try:
        shifts = sorted({float(x) for x in a.shift_mm.split(",")}) if a.shift_mm.strip() else []
    except ValueError:
        _fail(f"--shift-mm {a.shift_mm}: write distances in mm separated by commas, e.g. 2,5,10")
    if not all(np.isfinite(d) and d > 0 for d in shifts):
        _fail(f"--shift-mm {a.shift_mm}: every distance must be a finite number > 0")
    from mjcodesign.bench.record import provenance
    from mjcodesign.cli.common import user_cache_dir
    from mjcodesign.data import open_dataset
    from mjcodesign.data.config import DatagenConfig
    from mjcodesign.data.store import shard_tasks
    from mjcodesign.errors import MjcodesignError
    from mjcodesign.surrogate.ranking import MIN_DESIGNS

    t0 = time.perf_counter()
    try:
        ds = open_dataset(a.data)
        config = DatagenConfig.from_dict(ds.manifest["config"])
    except (MjcodesignError, OSError) as exc:
        _fail(str(exc))  # the error names the path
    if not ds.perturbed:
        _fail(f"{a.data}: one rollout per cell; this needs a perturbed dataset (datagen --perturbations)")
    s = ds.samples().select(["object_index", "pose_index", "design_index", "success_p"]).to_pydict()
    obj, pose = np.array(s["object_index"]), np.array(s["pose_index"])
    design, p = np.array(s["design_index"]), np.array(s["success_p"], dtype=float)
    candidates = varying_poses(obj, pose, p, MIN_DESIGNS)
    if not candidates:
        _fail(f"{a.data}: no pose with >= {MIN_DESIGNS} designs whose success_p varies")
    rng = np.random.default_rng(a.seed)
    chosen = sorted(
        candidates[i] for i in rng.choice(len(candidates), min(a.poses, len(candidates)), replace=False)
    )
    tasks = []
    for o in sorted({o for o, _ in chosen}):
        want = {q for oo, q in chosen if oo == o}
        tasks += [
            t
            for t in shard_tasks(
                ds.root, ds.manifest, o, config, str(user_cache_dir()), replicate=a.replicate
            )
            if t.pose_index in want
        ]
    first = {key: {} for key in chosen}
    for o, q, d, v in zip(obj, pose, design, p, strict=True):
        if (int(o), int(q)) in first:
            first[(int(o), int(q))][int(d)] = float(v)
    # This code must still make the dataset's labels: the first pose's own draws (replicate 0) again.
    check = dataclasses.replace(tasks[0], replicate=0)
    _, _, cells = _run(check)
    key = (check.object_index, check.pose_index)
    if {d: v for d, (v, _) in cells.items()} != first[key]:
        _fail(f"{a.data}: pose o{key[0]:04d}-p{key[1]:03d} rerun with its own draws gives other labels: "
              "this code does not reproduce the dataset")  # fmt: skip
    moves = [None] + [(ax, s * d) for d in shifts for ax in range(len(AXES)) for s in (1, -1)]
    runs = [
        (m, t if m is None else dataclasses.replace(t, matrix=shifted_matrix(t.matrix, m[0], m[1] / 1000)))
        for t in tasks
        for m in moves
    ]
    second: dict = {}
    moved: dict = {}
    rollouts = 0
    with ProcessPoolExecutor(a.workers) as pool:
        done = pool.map(_run, [t for _, t in runs])
        for i, ((m, _), (o, q, cells)) in enumerate(zip(runs, done, strict=True), start=1):
            usable = {d: v for d, (v, n) in cells.items() if n > 0}
            if m is None:
                second[(o, q)] = {d: v for d, (v, _) in cells.items()}
            else:
                moved.setdefault((AXES[m[0]], m[1]), {})[(o, q)] = usable
            rollouts += sum(n for _, n in cells.values())
            where = "" if m is None else f" palm {AXES[m[0]]} {m[1]:+g} mm"
            print(
                f"label_retest: shard {i}/{len(runs)} o{o:04d}-p{q:03d}{where} ({time.perf_counter() - t0:.0f} s)",
                flush=True,
            )
    out = {
        "data": a.data,
        "manifest_sha256": hashlib.sha256((ds.root / "manifest.json").read_bytes()).hexdigest(),
        "perturbations": ds.manifest["config"]["perturbations"],
        "reproduced": f"o{key[0]:04d}-p{key[1]:03d}: its own draws rerun give the stored labels exactly",
        "candidate_poses": len(candidates),
        "poses_rerun": len(tasks),
        "replicate": a.replicate,
        "seed": a.seed,
        "rollouts": rollouts,
        **retest_summary(first, second),
        "wall_s": round(time.perf_counter() - t0, 1),
    }
    if shifts:
        out["shift_mm"] = shifts
        out["shifted"] = shift_summary(first, second, moved, seed=a.seed)
    cmd = (f"python3 scripts/label_retest.py --data {a.data} --poses {a.poses} --seed {a.seed} "
           f"--replicate {a.replicate} --workers {a.workers}"
           + (f" --shift-mm {a.shift_mm}" if shifts else "") + f" --out {a.out}")  # fmt: skip
    out["provenance"] = provenance("label_retest", command=cmd)
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k != "provenance"}, indent=1))


if __name__ == "__main__":
    main()
