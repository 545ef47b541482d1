"""The paper-scale pipeline as one resumable command sequence: data, surrogate, co-designs, oracle, Table 1.

    python3 scripts/paper_pipeline.py --work DIR [--scale paper|smoke] [--oracle-budget N | --oracle-design FILE]
        [--record FILE]

Runs, in order, from ``DIR`` (each step's command is printed, and recorded with its exit code, start,
end and wall time in ``DIR/steps/NAME.json``; a rerun skips the steps that finished and resumes the
dataset, so an interrupted run goes on where it stopped):

1. ``datagen``: the 46 in-domain YCB objects x 50 poses x 8 designs, labels of 3 perturbed rollouts
   extended to 12 where they disagree (about 80k rollouts, the paper's scale), in the default regime;
2. ``train``: the surrogate with its success head, one object split (10 in-domain objects held out);
3. ``optimize``: Algorithm 1 through it on the 36 training objects: joint under L_opt (the paper), joint
   under the success objective, and individual (one design per object) under the success objective;
4. ``hybrid``: surrogate then simulator: CMA-ES on the simulator from the joint (success) design, for
   ``--hybrid-budget`` rollouts (default 10 % of the dataset's);
5. ``oracle`` (with ``--oracle-budget N``): CMA-ES on the simulator alone from semi-rigid, N rollouts;
   or (with ``--oracle-design FILE``) the design of an earlier oracle run on the same training objects,
   regime and suite (``bench oracle``'s ``design.json`` or its record), copied to ``oracle/design.json``;
6. ``evaluate``: every design, the oracle's included, against soft, semi-rigid and paper-optimized by
   perturbed re-simulation on the frozen suite (46 in-domain, 41 out-of-domain objects), both pose
   policies, the disturbance sweep: one evaluation, so every design meets the same draws;
7. ``groups``: the evaluation split into the surrogate's training objects, its held-out objects and
   out of domain, each co-design paired against each preset and the oracle, per pose policy (every
   pose, the first, each design's best) and per disturbance (``scripts/object_groups.py``);
8. ``limits``: the objects no design holds at any pose, and their failure kinds (``scripts/suite_limits.py``).

``--scale smoke`` runs the same steps on five objects, two poses and tiny budgets (a minute or two):
what the tests run. ``--record FILE`` writes the steps, their times and the headline numbers, with
the provenance of the installed code. ``--dry-run`` prints the commands only.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Scale:
    """The sizes of one pipeline run."""

    objects: str
    poses: int
    designs: int
    perturbations: str
    workers: int
    threads: int
    epochs: int
    iterations: int
    eval_objects: str  # "suite" (the frozen default suite) or ad-hoc objects for ``evaluate --objects``
    eval_poses: int
    eval_perturbations: int
    impulses: str
    hybrid_fraction: float
    population: int  # CMA-ES's population in the hybrid and the oracle (13: the oracle's default)
    hybrid_floor: int  # the hybrid's least budget [rollouts]


SCALES = {
    "paper": Scale(objects="ycb-in-domain", poses=50, designs=8, perturbations="3:12", workers=2, threads=2,
                   epochs=200, iterations=2000, eval_objects="suite", eval_poses=10, eval_perturbations=4,
                   impulses="0.1,0.4", hybrid_fraction=0.1, population=13, hybrid_floor=0),
    "smoke": Scale(objects="013_apple,014_lemon,017_orange,055_baseball,056_tennis_ball", poses=2, designs=8,
                   perturbations="1", workers=1, threads=1, epochs=2, iterations=20, eval_objects="smoke",
                   eval_poses=1, eval_perturbations=1, impulses="0.1", hybrid_fraction=0.0, population=4,
                   hybrid_floor=40),
}  # fmt: skip
PRESETS = ("soft", "semi-rigid", "paper-optimized")


def _done(work: Path, name: str) -> bool:
    f = work / "steps" / f"{name}.json"
    return f.is_file() and json.loads(f.read_text()).get("exit_code") == 0


def _same_command(recorded: str, argv: list[str]) -> bool:
    """Whether a step's recorded command line is ``argv``, whatever interpreter and checkout ran it."""

    def key(args: list[str]) -> list[str]:
        args = args if args[0] == "mjcodesign" else args[1:]  # a script step starts with the interpreter
        return [Path(a).name if a.endswith(".py") else a for a in args]

    return key(shlex.split(recorded)) == key(argv)


def _run(work: Path, name: str, argv: list[str], dry: bool) -> dict:
    """Run one step (or report it as done); its record; exit the script on a failure.

    A step done before with another command line (a folder from an older pipeline, or other flags)
    stops the run: its results would not be what the later steps expect.
    """
    text = shlex.join(argv)
    rec_file = work / "steps" / f"{name}.json"
    if _done(work, name):
        rec = json.loads(rec_file.read_text())
        if not _same_command(rec["command"], argv):
            print(f"pipeline: step {name} was done with another command ({rec['command']}); remove "
                  f"{rec_file} and its output to run it as: {text}", file=sys.stderr)  # fmt: skip
            raise SystemExit(2)
        print(f"pipeline: {name}: done before, skipped", file=sys.stderr)
        return rec
    print(f"pipeline: {name}: {text}", file=sys.stderr)
    if dry:
        return {"command": text}
    start = datetime.now(UTC).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    proc = subprocess.run(argv, cwd=work, stdout=subprocess.PIPE, text=True)
    rec = {"command": text, "exit_code": proc.returncode, "start": start,
           "end": datetime.now(UTC).isoformat(timespec="seconds"), "wall_s": round(time.perf_counter() - t0, 1)}  # fmt: skip
    (work / "logs").mkdir(exist_ok=True)
    (work / "logs" / f"{name}.out").write_text(proc.stdout)
    rec_file.parent.mkdir(exist_ok=True)
    rec_file.write_text(json.dumps(rec, indent=1))
    print(f"pipeline: {name}: exit {proc.returncode} after {rec['wall_s']} s", file=sys.stderr)
    if proc.returncode != 0:
        raise SystemExit(f"pipeline: step {name} failed (exit {proc.returncode}); fix it and rerun to resume")
    return rec


def _objects(work: Path) -> tuple[list[str], list[str]]:
    """(training objects, held-out objects) of the surrogate's split, from its report."""
    m = json.loads((work / "surrogate" / "metrics.json").read_text())
    held = list(m["split"]["test_objects"])
    manifest = json.loads((work / "data" / "manifest.json").read_text())
    names = [o["name"] for o in manifest["objects"] if o["status"] == "ready"]
    return [n for n in names if n not in held], held


def _rollouts(work: Path) -> int:
    """The dataset's rollouts (its samples when each cell is one rollout)."""
    counts = json.loads((work / "data" / "manifest.json").read_text())["counts"]
    return int(counts.get("rollouts", counts["samples"]))


ORACLE = "joint:oracle/design.json"
POLICIES = ("all", "fixed", "oracle")
"""The groups' pose policies: every pose of the suite, its first (fixed), each design's best (oracle)."""


def optimize_command(s: Scale, *, seed: int, ckpt: str, objects: list[str]) -> list[str]:
    """``mjcodesign optimize`` through ``ckpt`` on ``objects`` at this scale (add ``--mode``, ``--objective``, ``--out``)."""
    return ["mjcodesign", "optimize", "--ckpt", ckpt, "--objects", ",".join(objects), "--poses", "data",
            "--poses-per-object", str(s.poses), "--max-iterations", str(s.iterations), "--threads", str(s.threads),
            "--seed", str(seed), "--json"]  # fmt: skip


def cma_command(s: Scale, *, seed: int, suite: list[str], objects: list[str]) -> list[str]:
    """``mjcodesign bench oracle`` (CMA-ES on the simulator) on ``objects`` (add ``--start``, ``--budget``, ``--out``)."""
    return ["mjcodesign", "bench", "oracle", *suite, "--only", ",".join(objects), "--perturbations", "1",
            "--population", str(s.population), "--seed", str(seed), "--json"]  # fmt: skip


def step_commands(
    s: Scale, *, seed: int, train: list[str], held: list[str], hybrid_budget: int, oracle: str | int
) -> dict[str, list[str]]:
    """Every step's command line (argv) after ``datagen`` and ``train``, in order, run from the work folder.

    ``train`` / ``held``: the surrogate's training and held-out objects. ``suite`` appears only at a
    scale that evaluates an ad-hoc suite (``smoke``). ``oracle``: its budget in rollouts (0: no oracle)
    or an earlier oracle's design file (its step copies it, see :func:`adopt_oracle`).
    """
    sd = str(seed)
    out: dict[str, list[str]] = {}
    base = optimize_command(s, seed=seed, ckpt="surrogate", objects=train)
    codesigns = {"joint_lopt": ["--mode", "joint", "--objective", "lopt"],
                 "joint_success": ["--mode", "joint", "--objective", "success"],
                 "individual": ["--mode", "individual", "--objective", "success"]}  # fmt: skip
    for name, extra in codesigns.items():
        out[name] = [*base, *extra, "--out", name]
    suite = [] if s.eval_objects == "suite" else ["--suite", "suite.json"]
    if suite:  # an ad-hoc suite of the objects and one procedural shape, posed once, frozen for every step
        out["suite"] = ["mjcodesign", "evaluate", "--objects", s.objects, "--egad-like", "1", "--poses-per-object",
                        str(s.eval_poses), "--designs", "soft", "--perturbations", "1", "--save-suite", "suite.json",
                        "--out", "suite_check"]  # fmt: skip
    cma = cma_command(s, seed=seed, suite=suite, objects=train)
    out["hybrid"] = [*cma, "--start", "joint:joint_success/design.txt", "--budget", str(hybrid_budget),
                     "--out", "hybrid"]  # fmt: skip
    codesigned = [
        "joint:joint_lopt/design.txt",
        "joint:joint_success/design.txt",
        "joint:hybrid/design.json",
        "individual:individual",
    ]
    designs = [*PRESETS, *codesigned, *([ORACLE] if oracle else [])]
    if isinstance(oracle, str):
        out["oracle"] = [
            sys.executable,
            str(HERE / "paper_pipeline.py"),
            "--work",
            ".",
            "--adopt-oracle",
            oracle,
        ]
    elif oracle:
        out["oracle"] = [*cma, "--start", "semi-rigid", "--budget", str(oracle), "--out", "oracle"]
    evaluate = ["mjcodesign", "evaluate", *suite, "--perturbations", str(s.eval_perturbations), "--pose-sampling",
                "fixed,oracle", "--impulse", s.impulses, "--seed", sd, "--json"]  # fmt: skip
    out["evaluate"] = [*evaluate, "--designs", ",".join(designs), "--out", "evaluation"]
    compare = [arg for m in codesigned for p in PRESETS for arg in ("--compare", f"{m},{p}")]
    if oracle:
        compare += [a for m in (*PRESETS, *codesigned) for a in ("--compare", f"{ORACLE},{m}")]
    for i, impulse in enumerate(s.impulses.split(",")):
        for policy in POLICIES:
            name = f"groups_{policy}" + (f"_impulse{impulse}" if i else "")
            out[name] = [sys.executable, str(HERE / "object_groups.py"), "evaluation", "--group",
                         "train=train_objects.txt", "--group", "held-out=held_out_objects.txt", *compare,
                         "--policy", policy, "--impulse", impulse, "--out", f"{name}.json"]  # fmt: skip
    out["limits"] = [sys.executable, str(HERE / "suite_limits.py"), "evaluation/results.json", "--impulse",
                     s.impulses.split(",")[0], "--out", "limits.json"]  # fmt: skip
    return out


def oracle_gaps(groups: dict[str, dict]) -> dict:
    """Per groups record and object group: each design's paired difference to the oracle (design − oracle)."""
    out: dict = {}
    for name, rec in groups.items():
        for group, entry in rec["groups"].items():
            for q in entry["paired"]:
                if q["a"] == ORACLE and q["b"] not in PRESETS:
                    d = q["difference"]
                    iv = {"value": -d["value"], "low": -d["high"], "high": -d["low"], "n": d["n"]}
                    out.setdefault(name, {}).setdefault(group, {})[q["b"]] = iv
    return out


_GROUP_COLUMNS = ("train", "held-out", "out-of-domain")


def _pct(iv: dict | None) -> str:
    return "—" if not iv else f"{100 * iv['value']:.1f} [{100 * iv['low']:.1f}, {100 * iv['high']:.1f}]"


def table_markdown(groups: dict[str, dict]) -> str:
    """Table 1 from the groups records (``object_groups.py``'s output, by step name).

    Per disturbance and pose policy: each design's success [%] with its interval on the training,
    held-out and out-of-domain objects, then each design's paired difference to the best preset of
    that column.
    """
    lines = []
    for name, rec in groups.items():
        g = rec["groups"]
        lines += [f"### {name}: pose policy {rec['policy']}, disturbance {rec.get('impulse_paper_ns')} N·s", "",
                  "| design | " + " | ".join(_GROUP_COLUMNS) + " |", "|---|" + "---|" * len(_GROUP_COLUMNS)]  # fmt: skip
        found = list(next(iter(g.values()))["designs"])
        designs = [d for d in PRESETS if d in found] + [d for d in found if d not in PRESETS]
        for d in designs:
            lines.append(
                f"| {d} | " + " | ".join(_pct(g[c]["designs"].get(d)) for c in _GROUP_COLUMNS) + " |"
            )
        lines += ["", "| design − best preset | " + " | ".join(_GROUP_COLUMNS) + " |",
                  "|---|" + "---|" * len(_GROUP_COLUMNS)]  # fmt: skip
        best = {
            c: max(PRESETS, key=lambda p: (g[c]["designs"].get(p) or {"value": -1.0})["value"])
            for c in _GROUP_COLUMNS
        }
        for d in designs:
            if d in PRESETS:
                continue
            cells = []
            for c in _GROUP_COLUMNS:
                pair = next((q for q in g[c]["paired"] if q["a"] == d and q["b"] == best[c]), None)
                cells.append("—" if pair is None else f"{_signed(pair['difference'])} vs {best[c]}")
            lines.append(f"| {d} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _signed(iv: dict) -> str:
    v, lo, hi = (round(100 * iv[k], 1) + 0.0 for k in ("value", "low", "high"))  # + 0.0: no "-0.0"
    return f"{v:+.1f} [{lo:+.1f}, {hi:+.1f}]"


def adopt_oracle(work: Path, source: str) -> None:
    """Copy an earlier oracle's design (any file ``joint:FILE`` reads) to ``work/oracle/design.json``."""
    from mjcodesign.design.stiffness import read_design_file, write_design_file

    design = read_design_file(source)
    (work / "oracle").mkdir(parents=True, exist_ok=True)
    write_design_file(work / "oracle" / "design.json", design, source=str(Path(source).resolve()))


def first_commands(s: Scale, *, seed: int, resume: bool) -> dict[str, list[str]]:
    """The ``datagen`` and ``train`` command lines (``resume``: continue the dataset in ``data``)."""
    sd = str(seed)
    data = ["mjcodesign", "datagen", "--objects", s.objects, "--poses-per-object", str(s.poses), "--designs-per-pose",
            str(s.designs), "--perturbations", s.perturbations, "--workers", str(s.workers), "--seed", sd,
            "--out", "data", *(["--resume"] if resume else [])]  # fmt: skip
    train = ["mjcodesign", "train", "--data", "data", "--out", "surrogate", "--epochs", str(s.epochs), "--seed", sd,
             "--threads", str(s.threads), "--efficiency", "0", "--smoothness-poses", "0", "--json"]  # fmt: skip
    return {"datagen": data, "train": train}


def main() -> int:
    """Run the pipeline's steps in order; write the record."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", required=True, help="folder of every step's output (made if missing)")
    ap.add_argument("--scale", choices=sorted(SCALES), default="paper")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--hybrid-budget", type=int, default=None, help="rollouts (default: 10 %% of the dataset's)"
    )
    oracle = ap.add_mutually_exclusive_group()
    oracle.add_argument("--oracle-budget", type=int, default=0, help="rollouts of the oracle (0: no oracle)")
    oracle.add_argument(
        "--oracle-design", default=None, help="an earlier oracle's design file instead (above)"
    )
    ap.add_argument("--adopt-oracle", default=None, help=argparse.SUPPRESS)  # the oracle step itself
    ap.add_argument("--record", default=None, help="write the record (JSON) here")
    ap.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    a = ap.parse_args()
    if a.adopt_oracle:
        adopt_oracle(Path(a.work), a.adopt_oracle)
        return 0
    s = SCALES[a.scale]
    work = Path(a.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    steps: dict[str, dict] = {}
    t_all = time.perf_counter()
    resume = (work / "data" / "manifest.json").is_file() and not _done(work, "datagen")
    for name, argv in first_commands(s, seed=a.seed, resume=resume).items():
        steps[name] = _run(work, name, argv, a.dry_run)
    if a.dry_run:
        train, held, budget = ["<training objects>"], ["<held-out objects>"], a.hybrid_budget or 0
    else:
        train, held = _objects(work)
        (work / "train_objects.txt").write_text("\n".join(train) + "\n")
        (work / "held_out_objects.txt").write_text("\n".join(held) + "\n")
        budget = a.hybrid_budget or max(s.hybrid_floor, int(s.hybrid_fraction * _rollouts(work)))
    later = step_commands(
        s,
        seed=a.seed,
        train=train,
        held=held,
        hybrid_budget=budget,
        oracle=str(Path(a.oracle_design).resolve()) if a.oracle_design else a.oracle_budget,
    )
    for name, argv in later.items():
        steps[name] = _run(work, name, argv, a.dry_run)
    if a.record and not a.dry_run:
        from mjcodesign.bench.record import provenance

        read = lambda f: json.loads((work / f).read_text())  # noqa: E731
        rec = {
            "provenance": provenance("paper_pipeline", command=shlex.join([sys.executable, *sys.argv])),
            "scale": a.scale,
            "settings": s.__dict__,
            "steps": steps,
            "wall_s_this_call": round(time.perf_counter() - t_all, 1),
            "wall_s_steps": round(sum(r.get("wall_s", 0.0) for r in steps.values()), 1),
            "objects": {"train": train, "held_out": held},
            "dataset": read("data/manifest.json")["counts"],
            # every datagen call that wrote the dataset (a resumed one has several) and when it last wrote
            "dataset_runs": read("data/manifest.json")["runs"],
            "dataset_updated": read("data/manifest.json")["updated"],
            "surrogate": {k: read("surrogate/metrics.json").get(k) for k in ("verdict", "split")},
            "groups": {n: read(f"{n}.json") for n in later if n.startswith("groups_")},
        }
        rec["table_md"] = table_markdown(rec["groups"])
        rec["oracle_gaps"] = oracle_gaps(rec["groups"])
        limits = read("limits.json")
        rec["limits"] = {k: v for k, v in limits.items() if k != "provenance"}
        Path(a.record).write_text(json.dumps(rec, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
