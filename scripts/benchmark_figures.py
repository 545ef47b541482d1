"""Draw the benchmark page's figures, each from exactly one record of ``benchmarks/records/``.

Every figure names its record's file, commit and date in its footer. ``FIGURES`` lists them: the
output file under ``docs/_static/benchmarks/``, the record it reads and the function that draws it.
The evaluation's forest plot is drawn by ``mjcodesign evaluate`` itself (``forest.png``) and kept as
``docs/_static/evaluate_default_v1_forest.png``; it is not redrawn here.

    python3 scripts/benchmark_figures.py            # all figures
    python3 scripts/benchmark_figures.py --only landscape_real.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from mjcodesign.outputs import new_figure, save_figure

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records"
OUT = ROOT / "docs" / "_static" / "benchmarks"
DPI = 100  # the docs' images stay small (well under 150 KB each) at this resolution
_UNAVAILABLE = "benchmark_figures.py needs matplotlib"
_GROUPS = ("soft", "semi-rigid", "paper-optimized", "random")


def load(name: str) -> tuple[dict, dict]:
    """The record ``name`` of ``benchmarks/records/``: (its data, its provenance).

    A record keeps its data under ``record`` or, for the benches that write their own file, at the top
    level beside ``provenance``.
    """
    raw = json.loads((RECORDS / name).read_text())
    prov = raw.get("provenance", {})
    data = raw["record"] if "record" in raw else {k: v for k, v in raw.items() if k != "provenance"}
    return data, prov


def footer(name: str, prov: dict) -> str:
    """One line naming the record, its commit (short) and its date."""
    commit = prov.get("commit") or prov.get("installed", {}).get("commit") or "commit not recorded"
    commit = commit.split()[0][:7] if commit != "commit not recorded" else commit
    date = str(prov.get("date", "date not recorded"))[:16].replace("T", " ")
    return f"benchmarks/records/{name} · commit {commit} · {date}"


def _finish(fig, name: str, prov: dict, out: Path) -> Path:
    fig.text(0.01, 0.005, footer(name, prov), fontsize=7, color="0.35", ha="left", va="bottom")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return save_figure(fig, out, dpi=DPI)


def _interval(ax, y: float, cell: dict, **style) -> None:
    """One success rate [%] with its 95% interval as a horizontal error bar at height ``y``."""
    v, lo, hi = (100 * cell[k] for k in ("value", "low", "high"))
    ax.errorbar(v, y, xerr=[[v - lo], [hi - v]], fmt="o", capsize=3, **style)


def landscape_real(name: str, out: Path) -> Path:
    """Success per design group over objects with its 95% interval, and the sensitivity rows."""
    data, prov = load(name)
    fig = new_figure((8.5, 3.6), unavailable=_UNAVAILABLE)
    ax, sens = fig.subplots(1, 2, gridspec_kw={"width_ratios": (1.0, 1.2)})
    n_obj = data["success"]["soft"]["objects"]["n"]
    for i, group in enumerate(_GROUPS):
        _interval(ax, i, data["success"][group]["objects"], color=f"C{i}")
    ax.set_yticks(range(len(_GROUPS)), _GROUPS)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel(f"success [%], mean over {n_obj} objects, 95% interval")
    rollouts = sum(data["success"][g]["rollouts"]["n"] for g in _GROUPS)
    ax.set_title(f"regime '{data['regime']}', {rollouts:,} rollouts", fontsize=9)
    ax.grid(axis="x", alpha=0.3)
    rows = [("reference", data["sensitivity_reference"]["success"])]
    for s in data["sensitivity"]:  # "spool_radius", 0.0075 -> "spool\nradius\n0.0075"
        rows.append(("\n".join([*s["setting"].split("_"), f"{s['value']:g}"]), s["success"]))
    width = 0.8 / len(_GROUPS)
    for j, group in enumerate(_GROUPS):
        vals = [100 * success[group]["objects"]["value"] for _, success in rows]
        sens.bar(np.arange(len(rows)) + (j - 1.5) * width, vals, width, color=f"C{j}", label=group)
    sens.set_xticks(range(len(rows)), [label for label, _ in rows], fontsize=7)
    sens.set_ylim(0, 125)  # headroom above 100% for the legend
    sens.set_yticks(range(0, 101, 20))
    sens.set_ylabel("success [%] over objects")
    sens.set_title(
        f"sensitivity: one setting changed, {len(data['sensitivity_designs'])} designs", fontsize=9
    )
    sens.legend(fontsize=7, ncol=2, loc="upper center")
    sens.grid(axis="y", alpha=0.3)
    return _finish(fig, name, prov, out)


def routing_buckling(name: str, out: Path) -> Path:
    """Buckling tension [N] against ln E: the simulated chain against the closed form."""
    data, prov = load(name)
    rows = data["buckling"]
    log_e = [r["log_e"] for r in rows]
    fig = new_figure((6.0, 3.4), unavailable=_UNAVAILABLE)
    ax = fig.subplots()
    ax.semilogy(log_e, [r["closed_form_n"] for r in rows], "-", color="0.4", label="closed form")
    ax.semilogy(log_e, [r["t_crit_n"] for r in rows], "o", color="C3", label="measured (chain)")
    ratio = [r["ratio"] for r in rows]
    ax.set_xlabel("ln E of the blocks (E in Pa)")
    ax.set_ylabel("buckling tension [N]")
    ax.set_title(
        f"straight finger, printed routing: measured / closed form = {min(ratio):.3f}–{max(ratio):.3f}",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    ax.grid(which="both", alpha=0.3)
    return _finish(fig, name, prov, out)


def finger_speed(name: str, out: Path) -> Path:
    """One finger's curl: steps per second per model, over wall time and over CPU time (log scale)."""
    data, prov = load(name)
    models = list(data)
    fig = new_figure((6.0, 3.0), unavailable=_UNAVAILABLE)
    ax = fig.subplots()
    y = np.arange(len(models))
    wall = [data[m]["steps_per_s"] for m in models]
    cpu = [data[m]["steps_per_cpu_s"] for m in models]
    ax.barh(y - 0.2, wall, 0.4, color="C0", label="steps/s (wall)")
    ax.barh(y + 0.2, cpu, 0.4, color="C2", label="steps per CPU s")
    for yi, (w, c) in enumerate(zip(wall, cpu, strict=True)):
        ax.text(w, yi - 0.2, f" {w:,.0f}", va="center", fontsize=7)
        ax.text(c, yi + 0.2, f" {c:,.0f}", va="center", fontsize=7)
    ax.set_xscale("log")
    ax.set_xlim(right=max(cpu) * 8)
    ax.set_yticks(y, [f"{m} (nv {data[m]['nv']})" for m in models])
    ax.invert_yaxis()
    ax.set_xlabel("MuJoCo C, one thread, dt 2 ms (log scale)")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(axis="x", which="both", alpha=0.3)
    return _finish(fig, name, prov, out)


FIGURES = {
    "landscape_real.png": ("2026-12-03_bench_landscape_real.json", landscape_real),
    "routing_buckling.png": ("2026-12-03_routing_compare.json", routing_buckling),
    "finger_speed.png": ("2026-12-01_bench_finger.json", finger_speed),
}
"""Output file under ``docs/_static/benchmarks/`` → (its record under ``benchmarks/records/``, drawer)."""


def main() -> None:
    """Draw the figures (all, or those named by ``--only``) into ``--out``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT, help="folder for the PNGs")
    ap.add_argument("--only", nargs="*", choices=sorted(FIGURES), help="draw only these figures")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for file in args.only or FIGURES:
        record, draw = FIGURES[file]
        path = draw(record, args.out / file)
        print(f"{path}: {path.stat().st_size / 1024:.0f} KB from {record}")


if __name__ == "__main__":
    main()
