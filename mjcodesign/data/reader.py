"""Reading a dataset back: its tables as Arrow, and the summary ``mjcodesign data info`` prints.

Only the files the manifest lists are read, so a folder that a run is still writing (or was killed
while writing) reads as its finished part. Each file is checked as it is read (its size and SHA-256
against the manifest, its rows' keys against its entry: :mod:`mjcodesign.data.integrity`), so a damaged
dataset is refused with :class:`DatasetError` naming the file. No torch here; the surrogate's
``Dataset`` wraps this.

Design groups, from the mean ln E of a design's 22 blocks (printable range 13.5–17.0, midpoint 15.25):
``soft-like`` below 15.0, ``stiff-like`` above 15.5, ``mixed`` in between. Uniform draws per block
give a mean of 15.25 ± 0.22 (1σ), so about 12 % of them are soft-like, 12 % stiff-like and 76 % mixed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa

from mjcodesign.data.config import DatagenConfig
from mjcodesign.data.integrity import Integrity, listed_files, read_table, verify
from mjcodesign.data.schema import tables
from mjcodesign.data.store import FORMAT, MANIFEST
from mjcodesign.design.stiffness import N_LOG_E
from mjcodesign.errors import OutputError
from mjcodesign.outputs import new_figure, save_figure

__all__ = [
    "DESIGN_GROUPS",
    "SOFT_BELOW",
    "STIFF_ABOVE",
    "Dataset",
    "design_group",
    "label_spread",
    "open_dataset",
    "plot_success",
    "summarize",
]

SOFT_BELOW = 15.0
"""A design whose mean ln(E / Pa) is below this is soft-like (soft preset: 13.5)."""
STIFF_ABOVE = 15.5
"""A design whose mean ln(E / Pa) is above this is stiff-like (semi-rigid preset: 16.5)."""
DESIGN_GROUPS = ("soft-like", "mixed", "stiff-like")
_KEYS = {
    "poses": ["object_index", "pose_index"],
    "samples": ["object_index", "pose_index", "design_index"],
    "rollouts": ["object_index", "pose_index", "design_index", "draw"],
}
_EXACT_DENSITIES = 6  # up to this many distinct densities are listed one by one, more are binned
_DENSITY_BINS = 4
_PLOT_BINS = 8  # mean-ln-E bins of the success plot
_PLOT_DPI = 120
_TOP_REASONS = 10
_INTEGRITY_HASHED = "every file's size and SHA-256 checked against the manifest"
_INTEGRITY_LEGACY = (
    "written before file hashes were recorded: sizes and hashes not checked (rows' keys checked); "
    "`datagen --resume` with the same settings records them"
)


def design_group(mean_log_e: float) -> str:
    """``soft-like``, ``mixed`` or ``stiff-like`` for a design's mean ln(E / Pa) (module docstring)."""
    if mean_log_e < SOFT_BELOW:
        return "soft-like"
    return "stiff-like" if mean_log_e > STIFF_ABOVE else "mixed"


class Dataset:
    """A dataset folder: its manifest and its three tables (:mod:`mjcodesign.data.schema`)."""

    def __init__(self, root: Path, manifest: dict):
        self.root = root
        self.manifest = manifest

    @property
    def perturbed(self) -> bool:
        """Whether a cell is K > 1 perturbed rollouts (``datagen --perturbations``)."""
        return "perturbations" in self.manifest.get("config", {})

    def files(self, table: str) -> list[Path]:
        """Files of ``table`` (poses, samples, rejected) that the manifest lists."""
        return [self.root / it.rel for it in listed_files(self.root, self.manifest, table)]

    def table(self, table: str) -> pa.Table:
        """All rows of ``table``, sorted by object, pose (design, draw); :class:`DatasetError` if a file is damaged.

        ``rollouts`` exists in a dataset of K > 1 perturbed rollouts per cell only (:class:`OutputError`).
        """
        schemas = tables(self.perturbed)
        if table not in schemas:
            raise OutputError(
                f"{self.root}: no {table} table (a dataset made with --perturbations K > 1 has one)"
            )
        schema = schemas[table]
        parts = [read_table(self.root, it, schema) for it in listed_files(self.root, self.manifest, table)]
        t = pa.concat_tables(parts) if parts else schema.empty_table()
        keys = _KEYS["samples" if table == "rejected" else table]
        return t.sort_by([(k, "ascending") for k in keys])

    def samples(self) -> pa.Table:
        """The training rows."""
        return self.table("samples")

    def poses(self) -> pa.Table:
        """One row per (object, pose), with the point clouds."""
        return self.table("poses")

    def rejected(self) -> pa.Table:
        """The sample errors (diverged, implausible, bad pose)."""
        return self.table("rejected")

    def rollouts(self) -> pa.Table:
        """Every perturbed rollout of every cell (K > 1 only)."""
        return self.table("rollouts")

    def verify(self) -> Integrity:
        """Every listed file checked against the manifest (the damaged ones listed, none raised)."""
        return verify(self.root, self.manifest)


def open_dataset(path: str | Path) -> Dataset:
    """The dataset in folder ``path``; :class:`OutputError` if it holds none."""
    root = Path(path)
    mpath = root / MANIFEST
    if not mpath.is_file():
        raise OutputError(f"{root}: not a dataset ({MANIFEST} missing)")
    try:
        manifest = json.loads(mpath.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise OutputError(f"{mpath}: unreadable manifest ({type(exc).__name__})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise OutputError(f"{root}: not an mjcodesign grasp dataset")
    return Dataset(root, manifest)


def _rate(success: np.ndarray) -> dict:
    return {"samples": int(len(success)), "success_rate": float(success.mean()) if len(success) else 0.0}


def _mean_log_e(samples: pa.Table) -> np.ndarray:
    flat = samples.column("log_e").combine_chunks().flatten().to_numpy()
    return flat.reshape(-1, N_LOG_E).mean(axis=1) if len(flat) else np.zeros(0)


def summarize(ds: Dataset) -> dict:
    """Counts, success rate per object, per density and per design group, rejections by kind and reason."""
    s = ds.samples()
    rej = ds.rejected()
    success = np.asarray(s.column("success").to_numpy(zero_copy_only=False), dtype=bool)
    objects = np.asarray(s.column("object").to_pylist(), dtype=object)
    density = s.column("density").to_numpy()
    groups = np.array([design_group(v) for v in _mean_log_e(s)], dtype=object)
    m = ds.manifest
    per_object = {}
    for o in m["objects"]:
        name = o.get("name", o["source"])
        sel = objects == name
        per_object[name] = {**_rate(success[sel]), "status": o["status"], "poses": o.get("poses", 0)}
        if o["status"] == "failed":
            per_object[name]["error"] = o.get("error")
    by_density = {}
    values = np.unique(density)
    if len(values) <= _EXACT_DENSITIES:
        for v in values:
            by_density[f"{v:g}"] = _rate(success[density == v])
    else:
        edges = np.linspace(density.min(), density.max(), _DENSITY_BINS + 1)
        idx = np.clip(np.searchsorted(edges, density, side="right") - 1, 0, _DENSITY_BINS - 1)
        for b in range(_DENSITY_BINS):
            by_density[f"{edges[b]:.0f}-{edges[b + 1]:.0f}"] = _rate(success[idx == b])
    kinds = rej.column("failure").to_pylist()
    reasons = rej.column("reason").to_pylist()
    top = sorted({r: reasons.count(r) for r in set(reasons)}.items(), key=lambda kv: (-kv[1], kv[0]))
    failures = s.column("failure").to_pylist()
    listed = list(listed_files(ds.root, m))
    hashed = sum(it.check is not None for it in listed)
    return {
        "path": str(ds.root),
        "complete": bool(m.get("complete")),
        "integrity": _INTEGRITY_HASHED if hashed == len(listed) else _INTEGRITY_LEGACY,
        "files_with_hash": f"{hashed}/{len(listed)}",
        "schema_version": m.get("schema_version"),
        "project_version": m.get("project_version"),
        "backend": m["config"]["backend"],
        "regime": m.get("regime") or DatagenConfig.from_dict(m["config"]).regime,
        "routing": m["config"].get("sim_options", {}).get("routing", "guided"),
        "objects": len(m["objects"]),
        "objects_ready": sum(o["status"] == "ready" for o in m["objects"]),
        "objects_failed": sum(o["status"] == "failed" for o in m["objects"]),
        "poses": ds.poses().num_rows,
        "shards": len(m["shards"]),
        "shards_failed": sum("error" in v for v in m["shards"].values()),
        "samples": s.num_rows,
        "rejected": rej.num_rows,
        "success_rate": _rate(success)["success_rate"],
        "failures": {k: failures.count(k) for k in sorted(set(failures)) if k != "none"},
        "by_object": per_object,
        "by_density": by_density,
        "by_design_group": {g: _rate(success[groups == g]) for g in DESIGN_GROUPS},
        "design_groups": {"soft_like_below": SOFT_BELOW, "stiff_like_above": STIFF_ABOVE},
        "rejected_by_kind": {k: kinds.count(k) for k in sorted(set(kinds))},
        "rejected_top_reasons": dict(top[:_TOP_REASONS]),
        **({"labels": label_spread(ds)} if ds.perturbed else {}),
    }


def label_spread(ds: Dataset) -> dict:
    """How the cells' labels of a K > 1 dataset spread: draws asked, cells with 0 < p < 1, rollouts a cell.

    ``mean_rollouts_per_cell`` counts every rollout run (usable or not) over every cell (samples and
    rejected); ``extended`` is the share of cells that ran more than K.
    """
    s, rej = ds.samples(), ds.rejected()
    p = s.column("success_p").to_numpy()
    run = np.concatenate(
        [
            s.column("rollouts").to_numpy() + s.column("unusable").to_numpy(),
            rej.column("rollouts").to_numpy() + rej.column("unusable").to_numpy(),
        ]
    )
    cfg = ds.manifest["config"]["perturbations"]
    cells = len(run)
    return {
        "draws": cfg["draws"],
        "extend_to": cfg["extend_to"],
        "cells": cells,
        "varying_share": float(np.mean((p > 0) & (p < 1))) if len(p) else 0.0,
        "mean_rollouts_per_cell": float(run.mean()) if cells else 0.0,
        "extended_share": float(np.mean(run > cfg["draws"])) if cells else 0.0,
        "mean_success_p": float(p.mean()) if len(p) else 0.0,
    }


def plot_success(ds: Dataset, path: str | Path) -> Path:
    """Draw success rate against mean ln E (binned), one line per object, into a PNG; the path.

    Raises :class:`UnsupportedError` without matplotlib, :class:`OutputError` if the file cannot be written.
    """
    fig = new_figure((8, 5), unavailable="--plot needs matplotlib (pip install matplotlib)")
    ax = fig.subplots()
    s = ds.samples()
    mean = _mean_log_e(s)
    success = np.asarray(s.column("success").to_numpy(zero_copy_only=False), dtype=float)
    objects = np.asarray(s.column("object").to_pylist(), dtype=object)
    if len(mean):
        edges = np.linspace(mean.min(), mean.max() + 1e-9, _PLOT_BINS + 1)
        centre = 0.5 * (edges[1:] + edges[:-1])
        idx = np.clip(np.searchsorted(edges, mean, side="right") - 1, 0, _PLOT_BINS - 1)
        for name in sorted(set(objects)):
            sel = objects == name
            rate = [
                success[sel & (idx == b)].mean() if np.any(sel & (idx == b)) else np.nan
                for b in range(_PLOT_BINS)
            ]
            ax.plot(centre, rate, marker="o", label=name)
    ax.axvline(SOFT_BELOW, color="0.6", ls=":")
    ax.axvline(STIFF_ABOVE, color="0.6", ls=":")
    ax.set_xlabel("mean ln(E / Pa) of the design's 22 blocks")
    ax.set_ylabel("success rate")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title(f"{ds.root.name}: {s.num_rows} samples")
    if len(set(objects)) <= 20:
        ax.legend(fontsize="small", loc="best")
    return save_figure(fig, path, dpi=_PLOT_DPI)
