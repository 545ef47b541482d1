"""Tables from the rollouts: the paper's Table 1 layout, the disturbance sweep, a bar chart.

Every cell is ``successes / rollouts`` over the rows it names, so any cell can be recomputed from
``results.json``.
"""

from __future__ import annotations

import json
import os
import uuid
from pathlib import Path

from mjcodesign.evaluation.config import DOMAINS, PAPER_TABLE1, EvalConfig
from mjcodesign.outputs import OutputKind, check_output, staged

__all__ = [
    "cell",
    "disturbance_table",
    "summary_table",
    "table1_markdown",
    "disturbance_markdown",
    "write_report",
]


def cell(rows: list[dict], **where) -> dict:
    """``{"success": k, "rollouts": n, "rate": k/n or None}`` over the rows matching ``where``."""
    sel = [r for r in rows if all(r[k] == v for k, v in where.items())]
    k = sum(1 for r in sel if r["success"])
    return {"success": k, "rollouts": len(sel), "rate": (k / len(sel)) if sel else None}


def _groups(config: EvalConfig) -> list[tuple[str, str]]:
    return [(g.group, g.label) for g in config.designs]


def summary_table(rows: list[dict], config: EvalConfig) -> list[dict]:
    """Table 1: per design group and pose sampling, success per domain and density at the first impulse."""
    imp = float(config.impulses[0])
    out = []
    for group, label in _groups(config):
        for sampling in config.pose_sampling:
            entry = {
                "group": group,
                "design_label": label,
                "pose_sampling": sampling,
                "cells": {},
                "paper": {},
            }
            for dom in DOMAINS:
                for dens in config.densities:
                    key = f"{dom}/{dens}"
                    entry["cells"][key] = cell(
                        rows,
                        design_label=label,
                        pose_sampling=sampling,
                        domain=dom,
                        density=dens,
                        impulse_paper_ns=imp,
                    )
                    entry["paper"][key] = PAPER_TABLE1.get((group, sampling, dom, dens))
            out.append(entry)
    return out


def disturbance_table(rows: list[dict], config: EvalConfig) -> list[dict]:
    """Paper Table 3a: success against impulse, per design group and pose sampling.

    Over all objects and densities evaluated.
    """
    out = []
    for group, label in _groups(config):
        for sampling in config.pose_sampling:
            out.append(
                {
                    "group": group,
                    "design_label": label,
                    "pose_sampling": sampling,
                    "cells": {
                        str(float(i)): cell(
                            rows, design_label=label, pose_sampling=sampling, impulse_paper_ns=float(i)
                        )
                        for i in config.impulses
                    },
                }
            )
    return out


def _pct(c: dict | float | None) -> str:
    if c is None:
        return "—"
    if isinstance(c, dict):
        return "—" if c["rate"] is None else f"{100 * c['rate']:.1f} ({c['success']}/{c['rollouts']})"
    return f"{c:.1f}"


def table1_markdown(table: list[dict], config: EvalConfig) -> str:
    """The table as Markdown: our success [%] (k/n), then the paper's figure where the issue quotes it."""
    keys = [f"{d}/{p}" for d in DOMAINS for p in config.densities]
    head = ["group", "pose"] + [f"ours {k}" for k in keys] + [f"paper {k}" for k in keys]
    lines = [
        f"Success [%] (successes/rollouts), MuJoCo {config.model}, impulse {config.impulses[0]} "
        "(paper units); paper: Table 1 as quoted in the issue (— where not recorded).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for e in table:
        vals = [_pct(e["cells"][k]) for k in keys] + [_pct(e["paper"][k]) for k in keys]
        lines.append("| " + " | ".join([e["design_label"], e["pose_sampling"], *vals]) + " |")
    return "\n".join(lines) + "\n"


def disturbance_markdown(table: list[dict], config: EvalConfig) -> str:
    """The disturbance sweep as Markdown."""
    imps = [str(float(i)) for i in config.impulses]
    head = ["group", "pose"] + [f"impulse {i}" for i in imps]
    lines = [
        "Success [%] (successes/rollouts) against the disturbance impulse (paper units, mapped by "
        "`scenario.paper_impulse`), all evaluated objects and densities.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for e in table:
        lines.append(
            "| "
            + " | ".join([e["design_label"], e["pose_sampling"], *(_pct(e["cells"][i]) for i in imps)])
            + " |"
        )
    return "\n".join(lines) + "\n"


def _bar_chart(table: list[dict], config: EvalConfig, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [f"{d}/{p}" for d in DOMAINS for p in config.densities]
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(keys) * max(1, len(table)) / 2), 4))
    width = 0.8 / max(1, len(table))
    for j, e in enumerate(table):
        vals = [100 * (e["cells"][k]["rate"] or 0.0) for k in keys]
        ax.bar(
            [i + j * width for i in range(len(keys))],
            vals,
            width,
            label=f"{e['design_label']} ({e['pose_sampling']})",
        )
    ax.set_xticks([i + 0.4 - width / 2 for i in range(len(keys))], keys)
    ax.set_ylabel("success [%] (simulated)")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def write_report(out: Path, rows: list[dict], objects: list, config: EvalConfig, meta: dict) -> dict:
    """Write table.md, disturbance.md, results.json and success.png into ``out``; return the summary.

    ``out`` follows the output-folder rule of :mod:`mjcodesign.outputs`: the files are written into a
    temporary sibling and swapped into place together.
    """
    folder = check_output(out, OutputKind.EVALUATION)
    table = summary_table(rows, config)
    dist = disturbance_table(rows, config)
    summary = {
        "table": table,
        "disturbance": dist,
        "objects": [{"name": o.name, "domain": o.domain, "error": o.error} for o in objects],
        **meta,
    }
    with staged(folder) as tmp:
        _bar_chart(table, config, tmp / "success.png")
        _atomic_write(tmp / "table.md", table1_markdown(table, config))
        _atomic_write(tmp / "disturbance.md", disturbance_markdown(dist, config))
        _atomic_write(tmp / "results.json", json.dumps({**summary, "rollouts": rows}, indent=None) + "\n")
    return summary
