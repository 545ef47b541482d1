"""K-fold co-design: every in-domain object scored by co-designs whose surrogate never saw it.

    python3 scripts/kfold_codesign.py --work DIR [--scale paper|smoke] [--folds K] [--record FILE]

Runs after ``scripts/paper_pipeline.py`` in the same ``DIR`` (its dataset, its evaluation's suite, seed
and perturbation draws), resumable as the pipeline is (each step recorded in ``DIR/steps/NAME.json``; a
rerun skips the steps that finished):

1. ``folds``: ``mjcodesign train --folds K`` on the pipeline's dataset with its training flags: K
   surrogates, each holding out one fold of the in-domain objects (the default suite's folds);
2. per fold k, on the fold's training objects with the fold's checkpoint: ``fold{k}_joint_lopt`` and
   ``fold{k}_joint_success`` (Algorithm 1, joint design, under L_opt and under the success objective),
   then ``fold{k}_hybrid`` (CMA-ES on the simulator from the success design, the pipeline's hybrid budget);
3. ``assemble``: for each of the three co-designs, a folder ``kfold_NAME`` of per-object design files:
   each in-domain object gets the design of the fold that held it out (``evaluate``'s ``individual:DIR``);
4. ``evaluate_kfold``: semi-rigid and the three K-fold co-designs with the pipeline's evaluation flags
   (a K-fold design is evaluated on the in-domain objects only); semi-rigid must agree with the
   pipeline's evaluation rollout by rollout, which checks the pairing;
5. ``kfold_groups_POLICY[_impulseX]``: ``scripts/object_groups.py`` on the pipeline's evaluation with
   this one added: each K-fold co-design paired against each preset over all in-domain objects (each
   object held out), and against the pipeline's single-split design of the same objective.

The pipeline scores its co-designs on one object split (its 10 held-out objects); this scores every
in-domain object as held out. ``--record FILE`` writes the steps, the folds, the designs and the table.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import shlex
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _pipeline():
    """``scripts/paper_pipeline.py`` as a module (its scales, step runner and commands)."""
    name = "paper_pipeline"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


CODESIGNS = ("joint_lopt", "joint_success", "hybrid")
"""The K-fold co-designs, named as the pipeline's single-split steps."""
SINGLE = {
    "joint_lopt": "joint:joint_lopt/design.txt",
    "joint_success": "joint:joint_success/design.txt",
    "hybrid": "joint:hybrid/design.json",
}
"""Each K-fold co-design's single-split counterpart in the pipeline's evaluation."""
DEFAULT_FOLDS = {"paper": 5, "smoke": 2}


def label(name: str) -> str:
    """The evaluation's design label of a K-fold co-design."""
    return f"individual:kfold_{name}"


def design_file(fold: int, name: str) -> str:
    """Fold ``fold``'s design file of co-design ``name``, relative to the work folder."""
    return f"fold{fold}_{name}/design.json" if name == "hybrid" else f"fold{fold}_{name}/design.txt"


def _without(argv: list[str], flags: tuple[str, ...]) -> list[str]:
    """``argv`` less each of ``flags`` and the value after it."""
    out, skip = [], False
    for x in argv:
        if skip or x in flags:
            skip = not skip and x in flags
            continue
        out.append(x)
    return out


def folds_command(s, *, seed: int, k: int) -> list[str]:
    """``train --folds K``: the pipeline's ``train`` flags but the runs ``--folds`` does not make."""
    train = _pipeline().first_commands(s, seed=seed, resume=False)["train"]
    train = _without(train, ("--out", "--efficiency", "--smoothness-poses"))
    return [*train[: train.index("--json")], "--folds", str(k), "--out", "folds", "--json"]


_RUN_KEYS = ("runs", "updated")
"""Manifest keys a datagen call that finds the dataset complete rewrites, its rows unchanged."""


def same_dataset(data: Path, trained_on: dict) -> str | None:
    """Why the dataset in ``data`` is not the one a folds run was trained on (its ``dataset`` entry), or None.

    The same manifest file (SHA-256), or a copy of it whose every key but :data:`_RUN_KEYS` is equal:
    the same fingerprint, objects, shards and counts.
    """
    ours = (data / "manifest.json").read_bytes()
    if hashlib.sha256(ours).hexdigest() == trained_on["manifest_sha256"]:
        return None
    theirs_file = Path(trained_on.get("path", "")) / "manifest.json"
    if not theirs_file.is_file():
        return (
            f"trained on another manifest ({trained_on['manifest_sha256'][:12]}…), and {theirs_file} is gone"
        )
    theirs = theirs_file.read_bytes()
    if hashlib.sha256(theirs).hexdigest() != trained_on["manifest_sha256"]:
        return f"{theirs_file} changed since the folds were trained"
    a, b = json.loads(ours), json.loads(theirs)
    differ = sorted(key for key in set(a) | set(b) if key not in _RUN_KEYS and a.get(key) != b.get(key))
    return f"trained on another dataset ({', '.join(differ)} differ)" if differ else None


def adopt_folds(work: Path, source: Path, k: int) -> str | None:
    """Link ``work/folds`` to an earlier ``train --folds K`` run on the same dataset, as the ``folds`` step.

    Returns the reason it cannot be adopted, or None.
    """
    try:
        manifest = json.loads((source / "folds.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return f"no readable folds.json ({exc})"
    if len(manifest["folds"]) != k:
        return f"{len(manifest['folds'])} folds, not {k}"
    problem = same_dataset(work / "data", manifest["dataset"])
    if problem:
        return problem
    link = work / "folds"
    if link.exists() or link.is_symlink():
        if link.resolve() != source:
            return f"{link} exists and is not a link to it"
    else:
        link.symlink_to(source, target_is_directory=True)
    step = work / "steps" / "folds.json"
    if not step.is_file():
        step.parent.mkdir(exist_ok=True)
        step.write_text(json.dumps({"command": f"adopted {source}", "exit_code": 0, "wall_s": 0.0,
                                    "train": manifest.get("train")}, indent=1))  # fmt: skip
    return None


def fold_commands(
    s, *, seed: int, fold: int, ckpt: str, train: list[str], hybrid_budget: int, suite: list[str]
) -> dict[str, list[str]]:
    """Fold ``fold``'s co-design steps (argv, run from the work folder), named ``fold{k}_NAME``."""
    pp = _pipeline()
    base = pp.optimize_command(s, seed=seed, ckpt=ckpt, objects=train)
    out = {
        f"fold{fold}_joint_lopt": [*base, "--mode", "joint", "--objective", "lopt", "--out", f"fold{fold}_joint_lopt"],
        f"fold{fold}_joint_success": [*base, "--mode", "joint", "--objective", "success", "--out",
                                      f"fold{fold}_joint_success"],
    }  # fmt: skip
    out[f"fold{fold}_hybrid"] = [
        *pp.cma_command(s, seed=seed, suite=suite, objects=train),
        "--start", f"joint:{design_file(fold, 'joint_success')}", "--budget", str(hybrid_budget),
        "--out", f"fold{fold}_hybrid",
    ]  # fmt: skip
    return out


def evaluate_commands(pipeline_cmds: dict[str, list[str]], impulses: str) -> dict[str, list[str]]:
    """``evaluate_kfold`` (the pipeline's evaluate flags, other designs and folder) and the groups steps."""
    ev = pipeline_cmds["evaluate"]
    cut = ev.index("--designs")
    designs = ["semi-rigid", *(label(n) for n in CODESIGNS)]
    out = {"evaluate_kfold": [*ev[:cut], "--designs", ",".join(designs), "--out", "evaluation_kfold"]}
    pp = _pipeline()
    compare = [a for n in CODESIGNS for p in pp.PRESETS for a in ("--compare", f"{label(n)},{p}")]
    compare += [a for n in CODESIGNS for a in ("--compare", f"{label(n)},{SINGLE[n]}")]
    for i, impulse in enumerate(impulses.split(",")):
        for policy in pp.POLICIES:
            name = f"kfold_groups_{policy}" + (f"_impulse{impulse}" if i else "")
            out[name] = [sys.executable, str(HERE / "object_groups.py"), "evaluation", "--also", "evaluation_kfold",
                         *compare, "--policy", policy, "--impulse", impulse, "--out", f"{name}.json"]  # fmt: skip
    return out


def assemble(work: Path, folds: list[dict]) -> dict[str, dict[str, str]]:
    """Write ``kfold_NAME/OBJECT.json``: each held-out object's fold design; {name: {object: fold}}."""
    from mjcodesign.design.stiffness import read_design_file, write_design_file

    made: dict[str, dict[str, str]] = {}
    for name in CODESIGNS:
        folder = work / f"kfold_{name}"
        folder.mkdir(exist_ok=True)
        for k, entry in enumerate(folds):
            src = work / design_file(k, name)
            design = read_design_file(src)
            for obj in entry["held_out"]:
                write_design_file(folder / f"{obj}.json", design, source=str(src.relative_to(work)), fold=k)
                made.setdefault(name, {})[obj] = entry["path"]
    return made


def table_markdown(groups: dict[str, dict]) -> str:
    """The K-fold table, per disturbance and pose policy, on the in-domain objects.

    Each design's success, and each K-fold co-design's paired difference to the best preset and to its
    single-split counterpart.
    """
    pp = _pipeline()
    lines = []
    for name, rec in groups.items():
        g = rec["groups"]["in-domain"]
        lines += [f"### {name}: pose policy {rec['policy']}, disturbance {rec.get('impulse_paper_ns')} N·s, "
                  f"{len(g['objects'])} in-domain objects", "", "| design | success | − best preset | − single split |",
                  "|---|---|---|---|"]  # fmt: skip
        best = max(pp.PRESETS, key=lambda p: (g["designs"].get(p) or {"value": -1.0})["value"])
        shown = [*pp.PRESETS, *(label(n) for n in CODESIGNS)]  # the single-split designs saw some of these
        for d, iv in ((d, g["designs"].get(d)) for d in shown if d in g["designs"]):
            cells = [pp._pct(iv), "", ""]
            for j, other in enumerate((best, SINGLE.get(d.removeprefix("individual:kfold_")))):
                pair = next((q for q in g["paired"] if q["a"] == d and q["b"] == other), None)
                if pair is not None:
                    cells[1 + j] = f"{pp._signed(pair['difference'])}" + (f" vs {best}" if j == 0 else "")
            lines.append(f"| {d} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    """Run the K-fold steps in order; write the record."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--work", required=True, help="the pipeline's work folder (scripts/paper_pipeline.py --work)"
    )
    ap.add_argument("--scale", choices=("paper", "smoke"), default="paper", help="the pipeline's scale")
    ap.add_argument("--folds", type=int, default=None, help="K (default: 5 at paper scale, 2 at smoke)")
    ap.add_argument(
        "--folds-from", default=None, help="an earlier train --folds K folder on the same dataset"
    )
    ap.add_argument("--seed", type=int, default=0, help="the pipeline's seed")
    ap.add_argument(
        "--hybrid-budget", type=int, default=None, help="rollouts per fold (default: the pipeline's)"
    )
    ap.add_argument("--record", default=None, help="write the record (JSON) here")
    ap.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    a = ap.parse_args()
    pp = _pipeline()
    s = pp.SCALES[a.scale]
    k_folds = a.folds or DEFAULT_FOLDS[a.scale]
    if k_folds < 2:
        print("kfold_codesign: --folds must be at least 2", file=sys.stderr)
        return 2
    work = Path(a.work).resolve()
    if not a.dry_run and not (work / "steps" / "evaluate.json").is_file():
        print(
            f"kfold_codesign: {work} holds no finished paper_pipeline.py run (steps/evaluate.json)",
            file=sys.stderr,
        )
        return 2
    t_all = time.perf_counter()
    if a.folds_from and not a.dry_run:
        problem = adopt_folds(work, Path(a.folds_from).resolve(), k_folds)
        if problem:
            print(f"kfold_codesign: --folds-from {a.folds_from}: {problem}", file=sys.stderr)
            return 2
    steps = {"folds": pp._run(work, "folds", folds_command(s, seed=a.seed, k=k_folds), a.dry_run)}
    if a.dry_run:
        folds = [
            {"path": f"fold{k}", "held_out": ["<held out>"], "train_objects": ["<train>"]}
            for k in range(k_folds)
        ]
        budget, held, train = a.hybrid_budget or 0, ["<held-out objects>"], ["<training objects>"]
    else:
        folds = json.loads((work / "folds" / "folds.json").read_text())["folds"]
        train, held = pp._objects(work)
        budget = a.hybrid_budget or max(s.hybrid_floor, int(s.hybrid_fraction * pp._rollouts(work)))
    suite = [] if s.eval_objects == "suite" else ["--suite", "suite.json"]
    for k, entry in enumerate(folds):
        cmds = fold_commands(s, seed=a.seed, fold=k, ckpt=f"folds/{entry['path']}", train=entry["train_objects"],
                             hybrid_budget=budget, suite=suite)  # fmt: skip
        for name, argv in cmds.items():
            steps[name] = pp._run(work, name, argv, a.dry_run)
    made = {} if a.dry_run else assemble(work, folds)
    pipeline_cmds = pp.step_commands(s, seed=a.seed, train=train, held=held, hybrid_budget=budget, oracle=0)
    later = evaluate_commands(pipeline_cmds, s.impulses)
    for name, argv in later.items():
        steps[name] = pp._run(work, name, argv, a.dry_run)
    if a.record and not a.dry_run:
        from mjcodesign.bench.record import provenance
        from mjcodesign.design.stiffness import read_design_file

        groups = {
            n: json.loads((work / f"{n}.json").read_text()) for n in later if n.startswith("kfold_groups_")
        }
        rec = {
            "provenance": provenance("kfold_codesign", command=shlex.join([sys.executable, *sys.argv])),
            "scale": a.scale,
            "k": k_folds,
            "hybrid_budget_per_fold": budget,
            "steps": steps,
            "wall_s_this_call": round(time.perf_counter() - t_all, 1),
            "wall_s_steps": round(sum(r.get("wall_s", 0.0) for r in steps.values()), 1),
            "folds": [
                {
                    "path": f["path"],
                    "held_out": f["held_out"],
                    "designs": {n: read_design_file(work / design_file(k, n)).as_list() for n in CODESIGNS},
                }
                for k, f in enumerate(folds)
            ],  # fmt: skip
            "objects_per_design": {n: len(m) for n, m in made.items()},
            "groups": groups,
            "table_md": table_markdown(groups),
        }
        Path(a.record).write_text(json.dumps(rec, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
