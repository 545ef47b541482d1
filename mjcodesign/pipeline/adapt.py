"""``design --adapt N``: fine-tune the surrogate on the user's own objects before the co-design.

:func:`adapt_surrogate` simulates ``N`` grasps of each object at the design's own sampled poses
(spread evenly over them), in the design run's regime: its scenario and finger model, each object at its
own density. The designs are drawn as ``datagen`` draws them (:func:`~mjcodesign.data.sample_designs`,
uniform per block, from the stream of object ``k``'s pose ``p``: :class:`~mjcodesign.data.PoseStreams`);
a rollout that is a sample error is left out, as ``datagen`` leaves it out of the training rows.

The poses are split (seeded): a share of them is held out for the test, a share validates (early stopping),
the rest trains. The network continues from the checkpoint's weights with its normaliser kept
(:func:`~mjcodesign.surrogate.train`'s ``init``, the path of ``train --init``) at :data:`ADAPT_LR`. The
held-out poses' metrics are measured before and after. When every rollout succeeded, or none did, there
is nothing to learn: the checkpoint is kept as it is, and the record says why.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mjcodesign.codesign import PoseSet
from mjcodesign.data import PoseStreams, StoredPoses, sample_designs
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.jobs import GraspJob, run_jobs
from mjcodesign.sim.mujoco_c import MujocoBackend

__all__ = ["ADAPT_EPOCHS", "ADAPT_LR", "ADAPT_PATIENCE", "adapt_surrogate", "summary_line"]

ADAPT_LR = 1e-4
"""Fine-tuning learning rate: on new poses of the adapted objects it raised the held-out success ROC AUC
from 0.879 to 0.957-0.967 over 3 seeds, against 0.900-0.945 at 1e-3
(``benchmarks/records/2026-12-03_finetune.json``)."""
ADAPT_EPOCHS = 100
"""Most fine-tuning epochs (that record's)."""
ADAPT_PATIENCE = 20
"""Epochs without a better validation loss before fine-tuning stops (that record's)."""
_TEST_SHARE = 0.25  # of the poses, held out for the adapted network's test
_VAL_SHARE = 0.15  # of the poses, the validation of early stopping
_MIN_POSES = 3  # one pose each to train, validate and test

Progress = Callable[[str, int, int], None]


def _per_pose(n: int, poses: int) -> list[int]:
    """``n`` rollouts spread over ``poses`` poses: the first ``n mod poses`` get one more."""
    return [n // poses + (i < n % poses) for i in range(poses)]


def _rollouts(poses: PoseSet, objs, rho, scenario, model, n: int, seed: int, say: Progress):
    """Per object ``n`` rollouts at its poses: (pose row, ln E, outcome) of each, sample errors dropped."""
    rows, log_e, outs, errors = [], [], [], 0
    for k, name in enumerate(poses.objects):
        jobs, job_rows, job_e = [], [], []
        for i, (row, count) in enumerate(zip(poses.rows(k), _per_pose(n, len(poses.rows(k))), strict=True)):
            designs = sample_designs(PoseStreams(seed, k, i).designs, count)
            for d in designs:
                jobs.append(
                    GraspJob(
                        obj=objs[name],
                        pose=poses.gripper_pose(int(row)),
                        design=Stiffness(d),
                        finger_model=model,
                        scenario=scenario,
                        density=rho[name],
                        seed=seed,
                        label=f"adapt/{name}",
                    )
                )
                job_rows.append(int(row))
                job_e.append(d)
        for row, d, o in zip(job_rows, job_e, run_jobs(jobs, MujocoBackend()), strict=True):
            if any(f.is_sample_error for f in o.failures):
                errors += 1
                continue
            rows.append(row)
            log_e.append(d)
            outs.append(o)
        say("adapting: simulating objects", k + 1, len(poses.objects))
    return np.asarray(rows, dtype=np.int64), np.asarray(log_e, dtype=float).reshape(-1, 22), outs, errors


def _grasp_data(poses: PoseSet, rho, rows, log_e, outs, scenario):
    """The rollouts as a :class:`~mjcodesign.surrogate.GraspData` (what ``load_grasp_data`` makes of a dataset)."""
    from mjcodesign.surrogate import GraspData

    pose_rho = np.array([rho[poses.objects[k]] for k in poses.object_of], dtype=float)
    index = np.concatenate([np.arange(len(poses.rows(k))) for k in range(len(poses.objects))])
    stored = StoredPoses(poses, np.stack([poses.object_of, index], axis=1), pose_rho * poses.volume, pose_rho)
    outputs = np.array([(*o.body_force, *o.displacement, float(o.ground_contact)) for o in outs], dtype=float)
    return GraspData(
        stored=stored,
        pose=rows,
        log_e=log_e,
        density=pose_rho[rows],
        outputs=outputs.reshape(-1, 10),
        success=np.array([o.success for o in outs], dtype=bool),
        lift=float(scenario.lift),
        lifted_fraction=float(scenario.lifted_fraction),
        manifest={"config": {"source": "design --adapt"}},
        manifest_sha256="",
        root=Path("."),
    )


def _pose_split(data, n_poses: int, seed: int):
    """Training, validation and test rows, whole poses each (a seeded draw)."""
    from mjcodesign.surrogate import Split

    perm = np.random.default_rng(seed).permutation(n_poses)
    n_test = max(1, round(_TEST_SHARE * n_poses))
    n_val = max(1, round(_VAL_SHARE * n_poses))
    parts = perm[:n_test], perm[n_test : n_test + n_val], perm[n_test + n_val :]
    test, val, train = (np.flatnonzero(np.isin(data.pose, p)) for p in parts)
    return Split("pose", train, val, test)


def _finite(x):
    return None if isinstance(x, float) and not math.isfinite(x) else x


def _held_out(sur, data, parts) -> dict:
    """Success ROC AUC and accuracy, and the loss (the checkpoint's normaliser), on the test rows."""
    from mjcodesign.surrogate.metrics import score_outputs
    from mjcodesign.surrogate.report import predict_rows, standard_loss

    pred, val = predict_rows(sur, data, parts.test), predict_rows(sur, data, parts.val)
    s = score_outputs(pred, data, parts.test, val, parts.val)
    return {
        "success_roc_auc": _finite(s["success"]["roc_auc"]),
        "success_accuracy": _finite(s["success"]["accuracy"]),
        "loss": _finite(standard_loss(pred, data, parts.test, sur.normalizer)["loss"]),
    }


def adapt_surrogate(
    surrogate,
    poses: PoseSet,
    objs: dict,
    rho: dict[str, float],
    scenario,
    model,
    rollouts: int,
    *,
    seed: int = 0,
    progress: Progress | None = None,
) -> tuple[object, dict]:
    """The surrogate fine-tuned on ``rollouts`` grasps of each object (module docstring), and its record.

    ``poses``: the design's candidates; ``objs``: the loaded objects by name; ``rho``: each object's
    density [kg/m³]. Returns ``surrogate`` itself when there is nothing to learn (record ``adapted``:
    false, ``reason``). Raises :class:`~mjcodesign.errors.DesignError` for fewer than three poses in all
    (the split needs one each to train, validate and test).
    """
    from mjcodesign.surrogate import OptimizerConfig, Surrogate, TrainConfig, train

    say = progress or (lambda _s, _d, _t: None)
    if rollouts < 1:
        raise DesignError(f"--adapt must be >= 1 rollout per object to adapt, got {rollouts}")
    if len(poses) < _MIN_POSES:
        raise DesignError(
            f"--adapt splits the poses to train, validate and test: it needs {_MIN_POSES} or more in all, "
            f"the objects have {len(poses)} (raise --poses-per-object)"
        )
    if surrogate.input_range is not None:  # a density the co-design would refuse, refused before the rollouts
        surrogate.input_range.check(None, np.array(list(rho.values()), dtype=float))
    rows, log_e, outs, errors = _rollouts(poses, objs, rho, scenario, model, rollouts, seed, say)
    record = {
        "rollouts_per_object": rollouts,
        "rollouts": rollouts * len(poses.objects),
        "sample_errors": errors,
        "samples": len(rows),
        "successes": int(sum(o.success for o in outs)),
        "lr": ADAPT_LR,
    }
    if record["successes"] in (0, len(rows)):
        what = "none succeeded" if record["successes"] == 0 or not len(rows) else "every one succeeded"
        record.update(
            adapted=False,
            reason=f"of the {len(rows)} adaptation rollouts {what}: nothing to learn, the checkpoint is used as it is",
        )
        return surrogate, record
    data = _grasp_data(poses, rho, rows, log_e, outs, scenario)
    parts = _pose_split(data, len(poses), seed)
    before = _held_out(surrogate, data, parts)
    cfg = TrainConfig(
        epochs=ADAPT_EPOCHS,
        early_stop_patience=ADAPT_PATIENCE,
        seed=seed,
        optimizer=OptimizerConfig(lr=ADAPT_LR),
    )
    res = train(
        data,
        parts,
        cfg,
        init=(surrogate.model, surrogate.normalizer),
        on_epoch=lambda log: say("adapting: fine-tune epochs", log.epoch + 1, ADAPT_EPOCHS),
    )
    adapted = Surrogate(
        res.model, res.normalizer, lift=surrogate.lift, lifted_fraction=surrogate.lifted_fraction,
        meta=dict(surrogate.meta), input_range=surrogate.trained_range,
    )  # fmt: skip
    record.update(
        adapted=True,
        reason="",
        split={
            **parts.as_dict(),
            "poses": {
                "train": _count(data, parts.train),
                "val": _count(data, parts.val),
                "test": _count(data, parts.test),
            },
            "test_success_rate": float(np.mean(data.success[parts.test])),
        },
        epochs=len(res.history),
        held_out={"before": before, "after": _held_out(adapted, data, parts)},
    )
    adapted.meta["adapt"] = record
    return adapted, record


def _count(data, rows) -> int:
    """Poses the sample ``rows`` come from."""
    return len(set(data.pose[rows].tolist()))


def summary_line(record: dict) -> str:
    """One line of what ``--adapt`` did, for the report and the terminal."""
    head = f"{record['rollouts_per_object']} rollouts per object ({record['samples']} usable)"
    if not record["adapted"]:
        return f"not adapted ({head}): {record['reason']}"
    b, a = record["held_out"]["before"], record["held_out"]["after"]

    def change(key: str) -> str:
        if b[key] is None or a[key] is None:  # held-out rows of one outcome have no ROC AUC
            return f"n/a ({record['split']['test_success_rate']:.0%} succeeded)"
        return f"{b[key]:.3f} → {a[key]:.3f}"

    return (
        f"adapted on {head}, lr {record['lr']:g}, {record['epochs']} epochs; on the "
        f"{record['split']['poses']['test']} held-out pose(s) ({record['split']['test']} rollouts): success "
        f"ROC AUC {change('success_roc_auc')}, accuracy {change('success_accuracy')}, loss {change('loss')}"
    )
