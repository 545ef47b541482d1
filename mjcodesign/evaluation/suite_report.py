"""The files of a suite evaluation: results, summary, Table 1 with intervals, paired differences, a plot.

- ``results.json``: every rollout (suite name, version and digest, object, pose, draw, design, regime,
  outcome) and the surrogate's pose choices; nothing in it depends on the wall clock, so the same suite
  and seed write the same file;
- ``summary.json``: per regime and pose policy, each design's success over objects per split with its
  interval, and every pair's paired difference; the run's settings, counts and wall time;
- ``table.md``: the paper's Table 1 layout with intervals; the paper's published figures only in their
  own labelled column, and only for the designs it measured;
- ``paired.md``: the paired differences; ``per_object.csv``: one row per (regime, policy, design,
  object); ``forest.png``: each design's success and each pair's difference with intervals, per split;
- ``disturbance.md`` when more than one disturbance ran.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from mjcodesign.evaluation.analysis import ALL_POSES, CONTINUOUS, SPLITS
from mjcodesign.evaluation.config import PAPER_TABLE1
from mjcodesign.evaluation.suite import SUITE_VERSION, Suite
from mjcodesign.outputs import OutputFolder, new_figure, save_figure, staged

__all__ = ["PAPER_MEASURED", "suite_header", "write_suite_report"]

PAPER_MEASURED = ("soft", "semi-rigid", "paper-optimized")
"""Designs the paper's Table 1 measured (its jointly optimised design is our ``paper-optimized``)."""


def suite_header(suite: Suite) -> dict:
    """How results name their suite."""
    return {
        "name": suite.name,
        "version": SUITE_VERSION,
        "digest": suite.digest,
        "objects": len(suite.objects),
    }


def _pct(iv: dict | None) -> str:
    if iv is None:
        return "—"
    return f"{100 * iv['value']:.1f} [{100 * iv['low']:.1f}, {100 * iv['high']:.1f}] (n={iv['n']})"


def _paper(design: str, policy: str, split: str, density: str) -> str:
    if design not in PAPER_MEASURED:
        return ""
    group = "joint" if design == "paper-optimized" else design
    v = PAPER_TABLE1.get((group, policy, split, density))
    return "" if v is None else f"{v:.1f}"


def table_markdown(analysis: dict, designs: list[str], header: dict) -> str:
    """Table 1: rows design × pose policy, columns the splits, per regime; the paper's own column."""
    lines = [
        f"# Success [%] over objects, 95 % bootstrap interval (suite {header['name']} v{header['version']})",
        "",
        "Each cell: mean over objects of the per-object success probability (poses × perturbed rollouts),",
        "[95 % interval, objects resampled] and the number of objects. The paper's column holds its own",
        "published figures (its simulator and objects), only for designs it measured; they are not",
        "comparable with ours cell by cell.",
    ]
    if header.get("regime"):
        lines += ["", f"Grasp regime: {header['regime']} (docs/regime.md)."]
    for reg in analysis["regimes"]:
        lines += [
            "",
            f"## density {reg['density']}, disturbance {reg['impulse_paper_ns']:g} N·s (paper units)",
            "",
            "| design | pose policy | " + " | ".join(SPLITS) + " | paper, in-domain (their Table 1) |",
            "|---|---|" + "---|" * len(SPLITS) + "---|",
        ]
        for policy, entry in reg["policies"].items():
            for d in designs:
                cells = [_pct(entry["designs"][d][s]) for s in SPLITS]
                paper = _paper(d, policy, "in-domain", str(reg["density"]))
                lines.append(f"| {d} | {policy} | " + " | ".join(cells) + f" | {paper} |")
    return "\n".join(lines) + "\n"


def paired_markdown(analysis: dict, header: dict) -> str:
    """Every pair's mean paired difference (a − b) per regime, policy and split."""
    lines = [
        f"# Paired differences a − b [points] (suite {header['name']} v{header['version']})",
        "",
        "Same objects, poses and perturbation draws for both designs. Interval: 95 % bootstrap over",
        "objects; p: two-sided sign-flip permutation test over objects; detectable: the smallest true",
        "difference this many objects detect at 80 % power with the observed spread.",
    ]
    for reg in analysis["regimes"]:
        for policy, entry in reg["policies"].items():
            lines += [
                "",
                f"## density {reg['density']}, disturbance {reg['impulse_paper_ns']:g}, pose policy {policy}",
                "",
                "| a | b | split | a − b | 95 % interval | p | detectable | a wins / b wins | objects |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
            for p in entry["paired"]:
                d = p["difference"]
                lines.append(
                    f"| {p['a']} | {p['b']} | {p['split']} | {100 * d['value']:+.1f} | "
                    f"[{100 * d['low']:+.1f}, {100 * d['high']:+.1f}] | {p['p_value']:.3g} | "
                    f"{100 * p['detectable']:.1f} | {p['wins']} / {p['losses']} | {d['n']} |"
                )
    return "\n".join(lines) + "\n"


def disturbance_markdown(analysis: dict, designs: list[str]) -> str:
    """Success over objects against the disturbance, per density and policy (the sweep)."""
    impulses = sorted({r["impulse_paper_ns"] for r in analysis["regimes"]})
    lines = ["# Disturbance sweep: success [%] over objects, 95 % interval", ""]
    for dens in sorted({r["density"] for r in analysis["regimes"]}):
        regs = {r["impulse_paper_ns"]: r for r in analysis["regimes"] if r["density"] == dens}
        for policy in regs[impulses[0]]["policies"]:
            for split in SPLITS:
                lines += [
                    f"## density {dens}, pose policy {policy}, {split}",
                    "",
                    "| design | " + " | ".join(f"{i:g} N·s" for i in impulses) + " |",
                    "|---|" + "---|" * len(impulses),
                ]
                for d in designs:
                    row = [_pct(regs[i]["policies"][policy]["designs"][d][split]) for i in impulses]
                    lines.append(f"| {d} | " + " | ".join(row) + " |")
                lines.append("")
    return "\n".join(lines)


def per_object_csv(analysis: dict) -> str:
    """One row per (regime, policy, design, object)."""
    buf = io.StringIO()
    cols = [
        "density", "impulse_paper_ns", "pose_policy", "design", "object", "domain", "fold",
        "successes", "valid", "sample_errors", "p", "p_low", "p_high",
    ]  # fmt: skip
    for name in CONTINUOUS:
        cols += [name, f"{name}_low", f"{name}_high"]
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for c in analysis["cells"]:
        row = [c[k] for k in cols[:10]] + [c["p"]["value"], c["p"]["low"], c["p"]["high"]]
        for name in CONTINUOUS:
            iv = c[name]
            row += ["", "", ""] if iv is None else [iv["value"], iv["low"], iv["high"]]
        w.writerow(row)
    return buf.getvalue()


def _short(label: str) -> str:
    """A design label as a plot shows it: a file's name instead of its path."""
    kind, sep, arg = label.partition(":")
    return f"{kind}:{Path(arg).name}" if sep and kind in ("joint", "individual") else label


def forest_plot(analysis: dict, designs: list[str], path: Path) -> None:
    """Each design's success and each pair's difference with intervals, per split (first regime)."""
    reg = analysis["regimes"][0]
    policy = next((p for p in reg["policies"] if p != ALL_POSES), ALL_POSES)
    entry = reg["policies"][policy]
    fig = new_figure(
        (7.5 * len(SPLITS), 2.0 + 0.35 * (len(designs) + len(entry["paired"]))),
        unavailable="forest.png needs matplotlib",
    )
    axes = fig.subplots(
        2, len(SPLITS), squeeze=False, height_ratios=[len(designs) + 1, len(entry["paired"]) // 2 + 1]
    )
    for col, split in enumerate(SPLITS):
        ax = axes[0][col]
        for i, d in enumerate(designs):
            iv = entry["designs"][d][split]
            if iv is not None:
                ax.errorbar(
                    100 * iv["value"],
                    i,
                    xerr=[[100 * (iv["value"] - iv["low"])], [100 * (iv["high"] - iv["value"])]],
                    fmt="o",
                    capsize=3,
                )
        ax.set_yticks(range(len(designs)), [_short(d) for d in designs])
        ax.set_xlim(0, 100)
        ax.set_xlabel("success [%]")
        ax.set_title(f"{split} ({policy} pose)")
        ax.invert_yaxis()
        ax = axes[1][col]
        pairs = [p for p in entry["paired"] if p["split"] == split]
        for i, p in enumerate(pairs):
            d = p["difference"]
            ax.errorbar(
                100 * d["value"],
                i,
                xerr=[[100 * (d["value"] - d["low"])], [100 * (d["high"] - d["value"])]],
                fmt="s",
                capsize=3,
            )
        ax.axvline(0.0, color="0.5", lw=0.8)
        ax.set_yticks(range(len(pairs)), [f"{_short(p['a'])} − {_short(p['b'])}" for p in pairs])
        ax.set_xlabel("paired difference [points]")
        ax.invert_yaxis()
    fig.suptitle(
        f"density {reg['density']}, disturbance {reg['impulse_paper_ns']:g} N·s; 95 % intervals over objects"
    )
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def write_suite_report(
    folder: OutputFolder, result: dict, analysis: dict, designs: list[str], header: dict, meta: dict
) -> dict:
    """Write every file of the module docstring into ``folder`` (staged: all or none); the summary."""
    summary = {
        "suite": header,
        **meta,
        "regimes": analysis["regimes"],
        "objects": result["objects"],
        "rollouts": len(result["rows"]),
    }
    results = {
        "suite": header,
        "run": {
            k: meta[k]
            for k in (
                "designs",
                "perturbations",
                "densities",
                "impulses_paper_ns",
                "pose_policies",
                "model",
                "seed",
                "tendon",
                "regime",
                "scenario",
                "mass",
            )
            if k in meta
        },
        "surrogate_choice": result["surrogate_choice"],
        "rows": result["rows"],
    }
    with staged(folder) as tmp:
        (tmp / "results.json").write_text(
            json.dumps(results, indent=None, sort_keys=True) + "\n", encoding="utf-8"
        )
        (tmp / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        table_header = {**header, "regime": meta.get("regime")}
        (tmp / "table.md").write_text(table_markdown(analysis, designs, table_header), encoding="utf-8")
        (tmp / "paired.md").write_text(paired_markdown(analysis, header), encoding="utf-8")
        (tmp / "per_object.csv").write_text(per_object_csv(analysis), encoding="utf-8")
        if len({r["impulse_paper_ns"] for r in analysis["regimes"]}) > 1:
            (tmp / "disturbance.md").write_text(disturbance_markdown(analysis, designs), encoding="utf-8")
        forest_plot(analysis, designs, tmp / "forest.png")
    return summary
