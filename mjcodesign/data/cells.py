"""Cells of K perturbed rollouts (``datagen --perturbations K`` or ``K:M``): run them, label them.

A cell is one (pose, design) of a shard. Its rollouts differ by a :class:`~mjcodesign.scenarios.perturb.
Perturbation` (palm pose, object mass, finger friction, tendon drive) drawn from the (object, pose)'s own
stream (:attr:`~mjcodesign.data.sampling.PoseStreams.perturbations`), so every design of a pose meets the
same draws (common random numbers), whichever worker runs the shard and whenever. A draw whose start
overlaps the object or the ground is drawn again (:func:`~mjcodesign.scenarios.perturb.draw_perturbations`,
the evaluation's rule); one given up after
:data:`~mjcodesign.scenarios.perturb.MAX_REDRAWS` tries is a ``bad_pose`` rollout (stored with the nominal
draw's numbers).

With ``K:M``, a cell whose first K usable rollouts disagree (a success and a failure among them) runs M;
the extra draws are the pose's draws K to M - 1, the same for every design extended.

A cell's label (:func:`cell_row`): ``success_p`` = successes / usable rollouts, the outputs' means and
spreads (ddof 0) over the usable rollouts, ``success`` = ``success_p >= 0.5``. A sample error (diverged,
implausible, bad pose) is no success and in no mean; it is counted in ``unusable``. A cell without a
usable rollout is a ``rejected/`` row (its means over all its rollouts, ``success_p`` 0).
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from mjcodesign.data.config import DatagenConfig
from mjcodesign.data.sampling import PoseStreams
from mjcodesign.data.schema import ROLLOUTS, SAMPLES_P, build_table, empty_columns
from mjcodesign.design.stiffness import N_LOG_E
from mjcodesign.errors import PoseError
from mjcodesign.jobs import GraspJob, SceneCache, run_jobs
from mjcodesign.poses.candidates import MAX_PENETRATION
from mjcodesign.scenarios.grasp import scene_at_pose
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome
from mjcodesign.scenarios.perturb import MAX_REDRAWS, NOMINAL, Perturbation, draw_perturbations

__all__ = ["CellTables", "cell_row", "cell_tables", "disagree", "run_cells"]

_GIVEN_UP = f"bad pose: no perturbed start without penetration in {MAX_REDRAWS} draws"


@dataclass(frozen=True)
class CellTables:
    """The rows of one shard's cells: ``samples/``, ``rejected/`` and ``rollouts/``."""

    samples: pa.Table
    rejected: pa.Table
    rollouts: pa.Table


def _usable(o: Outcome) -> bool:
    return not any(f.is_sample_error for f in o.failures)


def disagree(outs: list[Outcome]) -> bool:
    """Whether the usable rollouts of ``outs`` hold both a success and a failure."""
    labels = {o.success for o in outs if _usable(o)}
    return len(labels) == 2


def run_cells(
    jobs_of: list[GraspJob],
    *,
    config: DatagenConfig,
    object_index: int,
    pose_index: int,
    backend,
    scenes: SceneCache,
    replicate: int = 0,
) -> list[list[tuple[Perturbation, Outcome]]]:
    """Every cell's rollouts: per job of ``jobs_of`` (one pose, a design each), its (draw, outcome) pairs.

    K draws for every design; with :attr:`~DatagenConfig.perturbations_max`, M for those whose first K
    disagree (:func:`disagree`). ``replicate`` r >= 1: the same procedure under the pose's r-th
    independent stream of draws (:class:`~mjcodesign.data.sampling.PoseStreams`), not the dataset's.
    """
    c = config
    rng = PoseStreams(c.seed, object_index, pose_index, replicate).perturbations
    pose = jobs_of[0].pose
    base = scenes.scene(jobs_of[0])
    try:
        scene_at_pose(base, pose)
        posable = True
    except PoseError:  # the pose itself cannot be simulated: every draw of it is given up
        posable = False

    def draw(n: int) -> list[Perturbation | None]:
        if not posable:
            return [None] * n
        got, _ = draw_perturbations(
            c.perturbation,
            rng,
            n,
            base,
            c.scenario,
            pose,
            max_penetration=MAX_PENETRATION,
            keep=lambda p, scene: scenes.keep_perturbed(base, c.scenario, pose, p, scene),
        )
        return got

    cells: list[list[tuple[Perturbation, Outcome]]] = [[] for _ in jobs_of]
    _run(jobs_of, range(len(jobs_of)), draw(c.perturbations), cells, backend, scenes)
    if c.perturbations_max is not None:
        extend = [i for i, cell in enumerate(cells) if disagree([o for _, o in cell])]
        if extend:
            _run(jobs_of, extend, draw(c.perturbations_max - c.perturbations), cells, backend, scenes)
    return cells


def _run(jobs_of, which, draws, cells, backend, scenes) -> None:
    """Run designs ``which`` under ``draws`` (None: given up) and append to their cells in draw order."""
    jobs, where = [], []
    for i in which:
        for j, p in enumerate(draws):
            if p is not None:
                jobs.append(dataclasses.replace(jobs_of[i], perturbation=p))
                where.append((i, j))
    outs = dict(zip(where, run_jobs(jobs, backend, scenes=scenes), strict=True))
    for i in which:
        for j, p in enumerate(draws):
            if p is None:
                cells[i].append((NOMINAL, failed_outcome(Failure.BAD_POSE, _GIVEN_UP)))
            else:
                cells[i].append((p, outs[(i, j)]))


def cell_row(outs: list[Outcome]) -> dict:
    """The label of one cell from its rollouts (module docstring): the :data:`SAMPLES_P` output columns."""
    usable = [o for o in outs if _usable(o)]
    counted = usable or outs  # a cell without a usable rollout: its means over all of them
    force = np.array([o.body_force for o in counted], dtype=float)
    disp = np.array([o.displacement for o in counted], dtype=float)
    lift = np.array([o.lift_height for o in counted], dtype=float)
    ground = np.array([o.ground_contact for o in counted], dtype=float)
    finger = np.array([o.finger_contact for o in counted], dtype=float)
    wins = sum(o.success for o in usable)
    p = wins / len(usable) if usable else 0.0
    success = bool(usable) and p >= 0.5
    kinds = Counter(o.failure for o in counted if o.failure is not None)
    # Every kind by how often it comes first, then in the order the rollouts met it.
    seen = list(dict.fromkeys(f for o in counted for f in o.failures))
    every = sorted(seen, key=lambda f: (-kinds.get(f, 0), seen.index(f)))
    first = kinds.most_common(1)[0][0] if kinds else None
    if success:
        failure = "none"
        reason = "ok" if wins == len(usable) else f"{wins} of {len(usable)} usable rollouts succeed"
    else:
        failure = first.value
        example = next(o.reason for o in counted if o.failure == first)
        reason = f"{wins} of {len(usable)} usable rollouts succeed; most often {example}"
    return {
        "body_force": force.mean(axis=0),
        "displacement": disp.mean(axis=0),
        "ground_contact": bool(ground.mean() >= 0.5),
        "finger_contact": bool(finger.mean() >= 0.5),
        "lift_height": float(lift.mean()),
        "success": success,
        "failure": failure,
        "failures": [f.value for f in every],
        "reason": reason,
        "wall_time_s": float(sum(o.wall_time_s for o in outs)),
        "success_p": float(p),
        "rollouts": len(usable),
        "unusable": len(outs) - len(usable),
        "body_force_std": force.std(axis=0),
        "displacement_std": disp.std(axis=0),
        "lift_height_std": float(lift.std()),
        "ground_contact_p": float(ground.mean()),
        "finger_contact_p": float(finger.mean()),
    }


def cell_tables(
    cells: list[list[tuple[Perturbation, Outcome]]],
    designs: np.ndarray,
    *,
    name: str,
    object_index: int,
    pose_index: int,
    density: float,
    config: DatagenConfig,
) -> CellTables:
    """The ``samples/``, ``rejected/`` and ``rollouts/`` tables of one shard's cells."""
    keys = {"object_index": object_index, "object": name, "pose_index": pose_index}
    rows = {"samples": empty_columns(SAMPLES_P), "rejected": empty_columns(SAMPLES_P)}
    per = empty_columns(ROLLOUTS)
    for i, cell in enumerate(cells):
        outs = [o for _, o in cell]
        label = cell_row(outs)
        row = {
            **keys,
            "design_index": i,
            "density": density,
            "log_e": designs[i],
            "backend": config.backend,
            "seed": config.seed,
            **label,
        }
        table = rows["samples" if label["rollouts"] else "rejected"]
        for k, v in row.items():
            table[k].append(v)
        for j, (p, o) in enumerate(cell):
            r = {
                **keys,
                "design_index": i,
                "draw": j,
                "perturbation": p.as_array(),
                "body_force": o.body_force,
                "displacement": o.displacement,
                "ground_contact": bool(o.ground_contact),
                "finger_contact": bool(o.finger_contact),
                "lift_height": float(o.lift_height),
                "success": bool(o.success),
                "sample_error": not _usable(o),
                "failure": o.failure.value if o.failure else "none",
                "failures": [f.value for f in o.failures],
                "reason": o.reason,
                "wall_time_s": float(o.wall_time_s),
                "seed": config.seed,
            }
            for k, v in r.items():
                per[k].append(v)
    vectors = {"log_e": N_LOG_E, "body_force": 6, "displacement": 3, "body_force_std": 6}
    vectors |= {"displacement_std": 3, "perturbation": 9}
    for cols in (*rows.values(), per):
        for k, n in vectors.items():
            if k in cols:
                cols[k] = np.array(cols[k], dtype=float).reshape(len(cols[k]), n)
    return CellTables(
        build_table(rows["samples"], SAMPLES_P),
        build_table(rows["rejected"], SAMPLES_P),
        build_table(per, ROLLOUTS),
    )
