"""What ``mjcodesign train`` does: train, save the checkpoint, measure it against baselines, report.

:func:`train_and_report` writes into its output folder:

* the checkpoint (``model.safetensors``, ``config.json`` with the metrics: :mod:`.checkpoint`);
* ``metrics.json``: the split (its ``poses_per_object``: the cut of the training rows, or null), the
  training curve, the held-out metrics of the network, of the training mean and of gradient-boosted
  trees on the same split (:mod:`.metrics`; with a success head, its probability beside the trees'
  success classifier), the design-ranking fidelity of each and the labels' own repeatability
  (:mod:`.ranking`), the success rule's agreement with the simulator on the simulator's own outputs,
  the 25 % data run, and the smoothness lines (:mod:`.smoothness`);
* ``summary.md``: the same as tables, with a plain verdict against the baselines;
* ``curves.png``, ``calibration.png`` and ``smoothness.png``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mjcodesign.errors import OutputError, UnsupportedError
from mjcodesign.objects import MESH_SUFFIXES
from mjcodesign.outputs import OutputKind, check_output, staged, write_atomic
from mjcodesign.surrogate.checkpoint import load_surrogate, save_checkpoint
from mjcodesign.surrogate.data import (
    N_OUTPUTS,
    N_REGRESSION,
    GraspData,
    Normalizer,
    Split,
    first_poses,
    fold_splits,
    load_grasp_data,
    pose_rank,
    split,
    subsample,
)
from mjcodesign.surrogate.folds import FOLDS_FILE, FOLDS_FORMAT, FOLDS_VERSION
from mjcodesign.surrogate.inference import GraspBatch, InputRange, Poses, Surrogate
from mjcodesign.surrogate.metrics import (
    mean_baseline,
    score_outputs,
    success_scores,
    tree_baseline,
    tree_success,
)
from mjcodesign.surrogate.model import ModelConfig
from mjcodesign.surrogate.plots import plot_calibration, plot_curves, plot_lines
from mjcodesign.surrogate.ranking import linear_design_effect, ranking_fidelity, split_half
from mjcodesign.surrogate.smoothness import smoothness
from mjcodesign.surrogate.train import (
    EpochLog,
    TrainConfig,
    evaluate_loss,
    success_labels,
    train,
    training_set,
)

__all__ = [
    "SUCCESS_RATE_WARN",
    "TensorBoardLog",
    "checkpoint_smoothness",
    "dataset_warnings",
    "predict_rows",
    "predict_success",
    "standard_loss",
    "train_and_report",
    "train_folds",
    "user_objects",
]

_PREDICT_CHUNK = 8192  # rows per predict call
_EPS = 1e-6  # probability clip of the cross-entropy
_RANKING_TARGET = 0.5  # median design-ranking Spearman a surrogate must reach (the co-design's need)
LINEAR_DESIGN = "linear design effect (training rows)"  # the design-only ranking baseline (surrogate.ranking)
SUCCESS_RATE_WARN = (0.05, 0.95)
"""A dataset whose success rate is outside this range is one outcome with a few exceptions: the
success the surrogate learns rests on those few samples (a user's 96/96 at the light density)."""


def _predict(surrogate: Surrogate, data: GraspData, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Outputs (S, 10) of the samples ``rows`` and the success head's probability (S,) or None."""
    poses = Poses.of(data.poses)
    features = surrogate.features(poses)
    out = np.zeros((len(rows), N_REGRESSION + 1))
    head = np.zeros(len(rows)) if surrogate.has_success_head else None
    for i in range(0, len(rows), _PREDICT_CHUNK):
        r = rows[i : i + _PREDICT_CHUNK]
        b = GraspBatch(poses, data.pose[r], data.density[r], data.log_e[r], features=features)
        pred = surrogate.predict(b)
        out[i : i + len(r)] = np.concatenate(
            [pred.body_force, pred.displacement, pred.ground_contact[:, None]], axis=1
        )
        if head is not None:
            head[i : i + len(r)] = pred.success_p
    return out, head


def predict_rows(surrogate: Surrogate, data: GraspData, rows: np.ndarray) -> np.ndarray:
    """Outputs (S, 10) of the samples ``rows`` in physical units, contact as a probability."""
    return _predict(surrogate, data, rows)[0]


def predict_success(surrogate: Surrogate, data: GraspData, rows: np.ndarray) -> np.ndarray | None:
    """The success head's probability (S,) of the samples ``rows``; None for a network without a head."""
    return _predict(surrogate, data, rows)[1]


def standard_loss(pred: np.ndarray, data: GraspData, rows: np.ndarray, norm: Normalizer) -> dict:
    """The training loss of physical outputs ``pred``: mean z-scored L1 of the 9, the contact's BCE."""
    y = data.outputs[rows]
    l1 = np.abs((pred[:, :N_REGRESSION] - y[:, :N_REGRESSION]) / norm.out_std).mean(axis=0)
    p = np.clip(pred[:, N_REGRESSION], _EPS, 1 - _EPS)
    c = y[:, N_REGRESSION]
    bce = float(-np.mean(c * np.log(p) + (1 - c) * np.log(1 - p)))
    return {
        "loss": float((l1.sum() + bce) / (N_REGRESSION + 1)),
        "l1_z_mean": float(l1.mean()),
        "contact_bce": bce,
    }


class TensorBoardLog:
    """An ``on_epoch`` callback writing the losses and learning rate as TensorBoard events in ``logdir``."""

    def __init__(self, logdir: str | Path):
        self.check()
        from torch.utils.tensorboard import SummaryWriter

        try:
            self.writer = SummaryWriter(log_dir=str(logdir))
        except OSError as exc:
            raise OutputError(f"cannot write {logdir}: {exc.strerror or exc}") from exc

    @staticmethod
    def check() -> None:
        """Raise :class:`UnsupportedError` when the tensorboard package is missing."""
        try:
            from torch.utils.tensorboard import SummaryWriter  # noqa: F401
        except ImportError:
            raise UnsupportedError(
                "--tensorboard needs the tensorboard package (pip install tensorboard)"
            ) from None

    def __call__(self, log: EpochLog) -> None:
        """Log one epoch."""
        self.writer.add_scalar("loss/train", log.train_loss, log.epoch)
        self.writer.add_scalar("loss/val", log.val_loss, log.epoch)
        self.writer.add_scalar("lr", log.lr, log.epoch)

    def close(self) -> None:
        """Flush and close the event file."""
        self.writer.close()


def _measure(name, pred, val_pred, data, parts: Split, norm, success_p=None) -> dict:
    return {"name": name, **standard_loss(pred, data, parts.test, norm),
            **score_outputs(pred, data, parts.test, val_pred, parts.val, success_p)}  # fmt: skip


def _held_out(
    sur: Surrogate, data: GraspData, parts: Split, name: str
) -> tuple[dict, np.ndarray, np.ndarray | None]:
    """A network's held-out metrics (:func:`_measure`), its test outputs and its head's test probability."""
    (pred, head), (val_pred, _) = _predict(sur, data, parts.test), _predict(sur, data, parts.val)
    return _measure(name, pred, val_pred, data, parts, sur.normalizer, head), pred, head


def _ranking(data: GraspData, parts: Split, net: tuple, tree: tuple) -> dict:
    """Design-ranking fidelity of the network and the trees on the test poses, and the labels' own ceiling.

    ``net`` and ``tree``: (test outputs (S, 10), success probability (S,) or None).
    """
    rows = parts.test
    preds = {"surrogate (score)": success_scores(net[0], data, rows),
             "gradient-boosted trees (score)": success_scores(tree[0], data, rows)}  # fmt: skip
    if net[1] is not None:
        preds["surrogate (head)"] = net[1]
    if tree[1] is not None:
        preds["gradient-boosted trees (classifier)"] = tree[1]
    preds[LINEAR_DESIGN] = linear_design_effect(data, parts.train, rows)
    return {**ranking_fidelity(preds, data, rows), "repeatability": split_half(data, rows)}


def _rule_ceiling(data: GraspData, rows: np.ndarray) -> dict:
    """The success rule on the simulator's own outputs against its success flag."""
    score = success_scores(data.outputs[rows], data, rows)
    truth = data.success[rows]
    return {"accuracy": float(np.mean((score > 0) == truth)), "false_success": int(np.sum((score > 0) & ~truth)),
            "missed_success": int(np.sum((score <= 0) & truth))}  # fmt: skip


def _smoothness_poses(data: GraspData, parts: Split, n: int, part: str = "test") -> np.ndarray:
    """Up to ``n`` poses of the split's ``part`` (``test`` or ``train``), one per object in turn."""
    poses = np.unique(data.pose[getattr(parts, part)])
    by_object: dict[str, list[int]] = {}
    for p in poses:
        by_object.setdefault(data.objects[p], []).append(int(p))
    order = [
        ps[i] for i in range(max(map(len, by_object.values()))) for ps in by_object.values() if i < len(ps)
    ]
    return np.array(order[:n], dtype=int)


def checkpoint_smoothness(
    ckpt: str | Path,
    data_dir: str | Path,
    *,
    poses: int = 16,
    lines: int = 4,
    part: str = "test",
    cache_dir=None,
) -> dict:
    """Re-measure a trained checkpoint's smoothness on the held-out poses of the dataset it was trained on.

    ``part="train"`` takes training poses instead: whether the network follows the design on objects
    it has seen.

    The split is rebuilt from the checkpoint's record (mode and seed) and must hold out the same objects;
    the lines are those ``train`` draws for its seed, so checkpoints of one dataset are compared on the
    same lines. :class:`OutputError` if the dataset is not the checkpoint's.
    """
    if poses < 1 or lines < 1:
        raise OutputError(f"smoothness needs poses >= 1 and lines >= 1, got {poses} and {lines}")
    if part not in ("test", "train"):
        raise OutputError(f"smoothness part must be test or train, got {part!r}")
    sur = load_surrogate(ckpt)
    data = load_grasp_data(data_dir)
    meta = sur.meta
    try:
        recorded, mode, seed = (
            meta["dataset"]["manifest_sha256"],
            meta["split"]["mode"],
            int(meta["train"]["seed"]),
        )
        split_seed = meta["train"].get("split_seed")
        split_seed = seed if split_seed is None else int(split_seed)
        held_out = list(meta["split"]["test_objects"])
    except (KeyError, TypeError, ValueError) as exc:
        raise OutputError(f"{ckpt}: the checkpoint records no dataset split ({exc})") from exc
    if recorded != data.manifest_sha256:
        raise OutputError(f"{ckpt} was trained on another dataset (manifest sha256 {recorded[:12]}, "
                          f"{data_dir} has {data.manifest_sha256[:12]})")  # fmt: skip
    parts = split(data, mode, seed=split_seed)
    if list(parts.test_objects) != held_out:
        raise OutputError(
            f"{ckpt}: the rebuilt split holds out {list(parts.test_objects)}, the checkpoint {held_out}"
        )
    if (n := meta["split"].get("poses_per_object")) is not None:
        parts = first_poses(data, parts, int(n))
    rows = _smoothness_poses(data, parts, poses, part)
    return {**smoothness(sur, data, rows, lines=lines, seed=seed, cache_dir=cache_dir), "part": part}


def train_and_report(
    data_dir: str | Path,
    out: str | Path,
    *,
    overwrite: bool = False,
    split_mode: str = "object",
    config: TrainConfig | None = None,
    model_config: ModelConfig | None = None,
    efficiency: float = 0.25,
    smoothness_poses: int = 16,
    smoothness_lines: int = 4,
    cache_dir=None,
    on_epoch: Callable[[str, EpochLog], None] | None = None,
    init: str | Path | None = None,
    warn: Callable[[str], None] | None = None,
    poses_per_object: int | None = None,
) -> dict:
    """Train on the dataset in ``data_dir``, write the checkpoint and report into ``out``; the metrics.

    ``init``: a checkpoint folder to continue from (fine-tuning, :func:`~.train.train`'s ``init``):
    its architecture and its normaliser are kept (``model_config`` must be None), and the record names
    it. ``warn`` receives one line per :func:`dataset_warnings` finding.

    ``poses_per_object``: train and early-stop on the first N poses of each object only
    (:func:`~.data.first_poses` of the split; None: all), every design of those poses; the split's
    objects are the same for every N, and the held-out metrics are taken on all the test rows, so that
    runs of different N are comparable (a learning curve). The report's ``split`` records N;
    ``warn`` is told how many training objects have fewer poses than N (they keep all theirs).

    ``efficiency``: the share of training data of the second run (0: none). ``smoothness_poses``: test
    poses re-simulated along ``smoothness_lines`` design lines each (0: none). ``on_epoch(run, log)``
    sees every epoch of the runs ``full`` and ``efficiency``. ``out`` follows the output-folder rule of
    :mod:`mjcodesign.outputs` (checked before any work; ``overwrite`` keeps another writer's files beside
    the checkpoint); every file lands there at once when the report is complete.
    """
    cfg = config or TrainConfig()
    folder = check_output(
        out, OutputKind.CHECKPOINT, overwrite=overwrite, inputs={"--data": data_dir, "--init": init}
    )
    start, mcfg = _initial(init, model_config)
    data = load_grasp_data(data_dir)
    parts = split(data, split_mode, seed=cfg.data_seed)
    lines = dataset_warnings(data, parts)
    if poses_per_object is not None:
        lines += _short_objects(data, parts, poses_per_object)  # of the uncut split: all their poses
        parts = first_poses(data, parts, poses_per_object)
    for line in lines:
        if warn:
            warn(line)
    split_record = {**parts.as_dict(), "poses_per_object": poses_per_object}
    runs = {"full": train(data, parts, cfg, None if start else mcfg, init=start,
                          on_epoch=on_epoch and (lambda log: on_epoch("full", log)))}  # fmt: skip
    res = runs["full"]
    dataset = _dataset_record(data)
    sur = Surrogate(
        res.model,
        res.normalizer,
        lift=data.lift,
        lifted_fraction=data.lifted_fraction,
        input_range=_trained_range(data),
    )
    test_set = training_set(data, parts.test, res.normalizer, res.model.config)
    net, net_pred, net_head = _held_out(sur, data, parts, "surrogate")
    net["loss_check"] = evaluate_loss(
        res.model, test_set, success_weight=cfg.success_weight, rank_weight=cfg.rank_weight
    )
    mean = mean_baseline(data, parts.train, parts.test), mean_baseline(data, parts.train, parts.val)
    mean_p = np.full(len(parts.test), float(success_labels(data, parts.train).mean()))
    tree = tree_baseline(data, parts.train, [parts.test, parts.val], seed=cfg.seed)
    (tree_p,) = tree_success(data, parts.train, [parts.test], seed=cfg.seed)
    models = {"surrogate": net, "training mean": _measure("training mean", *mean, data, parts, res.normalizer, mean_p),
              "gradient-boosted trees": _measure("gradient-boosted trees", *tree, data, parts, res.normalizer, tree_p)}  # fmt: skip
    metrics = {"dataset": dataset, "split": split_record, "train_config": cfg.as_dict(), "model": mcfg.as_dict(),
               "training": res.summary(), "test": models, "success_rule_on_simulator_outputs": _rule_ceiling(data, parts.test),
               "ranking": _ranking(data, parts, (net_pred, net_head), (tree[0], tree_p))}  # fmt: skip
    if efficiency:
        small = train(data, subsample(parts, efficiency, seed=cfg.seed), cfg, None if start else mcfg, init=start,
                      on_epoch=on_epoch and (lambda log: on_epoch("efficiency", log)))  # fmt: skip
        runs["efficiency"] = small
        s_sur = Surrogate(
            small.model,
            small.normalizer,
            lift=data.lift,
            lifted_fraction=data.lifted_fraction,
            input_range=_trained_range(data),
        )
        metrics["efficiency"] = {"fraction": efficiency, "training": small.summary(),
                                 "test": _held_out(s_sur, data, parts, f"surrogate on {efficiency:.0%}")[0]}  # fmt: skip
    if smoothness_poses:
        poses = _smoothness_poses(data, parts, smoothness_poses)
        metrics["smoothness"] = smoothness(
            sur, data, poses, lines=smoothness_lines, seed=cfg.seed, cache_dir=cache_dir
        )
    metrics["verdict"] = verdict(models, metrics["ranking"])
    sur.meta = {
        "dataset": dataset,
        "split": split_record,
        "train": cfg.as_dict(),
        "metrics": _brief(metrics),
    }
    if start is not None:
        metrics["init"] = sur.meta["init"] = _init_record(init)
    with staged(folder) as root:
        if smoothness_poses:
            plot_lines(metrics["smoothness"], root / "smoothness.png")
        save_checkpoint(root, sur)
        plot_curves({k: r.summary() for k, r in runs.items()}, root / "curves.png")
        plot_calibration(
            {k: m["success"]["calibration"] for k, m in models.items()}, root / "calibration.png"
        )
        write_atomic(root / "metrics.json", json.dumps(metrics, indent=1, allow_nan=False))
        write_atomic(root / "summary.md", summary_markdown(metrics))
    return metrics


def _trained_range(data: GraspData) -> InputRange:
    """The inputs' range of a checkpoint trained on ``data`` (:meth:`InputRange.of_dataset`)."""
    d = data.manifest["config"]["density"]
    return InputRange.of_dataset(data.density, (float(d["low_kg_m3"]), float(d["high_kg_m3"])))


def _dataset_record(data: GraspData) -> dict:
    """What a checkpoint records of its dataset."""
    return {"path": str(data.root), "manifest_sha256": data.manifest_sha256,
            "fingerprint": data.manifest.get("fingerprint"), "schema_version": data.manifest.get("schema_version"),
            "object_seed": data.manifest["config"]["object_seed"], "density": data.manifest["config"]["density"],
            "cloud_points": int(data.clouds.shape[1]), "samples": len(data), "poses": len(data.clouds),
            "config": data.manifest["config"]}  # fmt: skip


def _initial(init, model_config: ModelConfig | None) -> tuple[tuple | None, ModelConfig]:
    """(network, normaliser) of checkpoint ``init`` (None without one) and the architecture to train."""
    if init is None:
        return None, model_config or ModelConfig()
    base = load_surrogate(init)
    if model_config is not None and model_config != base.config:
        raise OutputError(
            f"--init {init}: fine-tuning keeps the checkpoint's architecture; give no model options"
        )
    return (base.model, base.normalizer), base.config


def _init_record(init) -> dict:
    """The checkpoint fine-tuning started from: its path and the dataset it was trained on."""
    from mjcodesign.surrogate.checkpoint import read_record

    ds = read_record(init).get("dataset") or {}
    return {"path": str(init), "dataset_manifest_sha256": ds.get("manifest_sha256"),
            "normalizer": "kept from the initial checkpoint (not refitted on this dataset)"}  # fmt: skip


def _short_objects(data: GraspData, parts: Split, n: int) -> list[str]:
    """A line when some of ``parts``' training objects have fewer than ``n`` sampled poses (none otherwise)."""
    rank = pose_rank(data)
    rows = np.concatenate([parts.train, parts.val])
    names = sorted(set(data.objects[data.pose[rows]]))
    counts = [int(rank[data.objects == name].max()) + 1 for name in names]
    short = [c for c in counts if c < n]
    if not short:
        return []
    return [
        f"--poses-per-object {n}: {len(short)} of {len(names)} training objects have fewer poses "
        f"(min {min(short)}) and train on all of theirs"
    ]


def user_objects(data: GraspData) -> set[str]:
    """Objects of ``data`` made from a mesh file (the user's own), not a YCB name or ``egad-like:N``."""
    return {str(o["name"]) for o in data.manifest.get("objects", ())
            if Path(str(o.get("source", ""))).suffix.lower() in MESH_SUFFIXES}  # fmt: skip


def dataset_warnings(data: GraspData, parts: Split | None = None) -> list[str]:
    """One line per finding about a dataset and its split.

    A success rate outside :data:`SUCCESS_RATE_WARN`, and a user's own object (:func:`user_objects`)
    among ``parts``' held-out test objects.
    """
    lines = []
    rate, low, high = float(np.mean(data.success)), *SUCCESS_RATE_WARN
    if not low <= rate <= high:
        lines.append(
            f"the dataset's success rate is {rate:.1%} of {len(data)} samples ({'above' if rate > high else 'below'} "
            f"{high if rate > high else low:.0%}): the surrogate has few {'failures' if rate > high else 'successes'} "
            "to learn from (a heavier or lighter --density, or another --tendon, gives both outcomes)"
        )
    mine = sorted(user_objects(data) & set(parts.test_objects)) if parts is not None else []
    if mine:
        lines.append(
            f"your own object{'s' if len(mine) > 1 else ''} {', '.join(mine)} {'are' if len(mine) > 1 else 'is'} "
            "held out as the test: the network never trains on it (--split random, or train on it with --init)"
        )
    return lines


def train_folds(
    data_dir: str | Path,
    out: str | Path,
    fold_of: dict[str, int],
    *,
    overwrite: bool = False,
    config: TrainConfig | None = None,
    model_config: ModelConfig | None = None,
    init: str | Path | None = None,
    on_epoch: Callable[[str, EpochLog], None] | None = None,
    warn: Callable[[str], None] | None = None,
) -> dict:
    """Train one surrogate per object-level fold (:func:`~.data.fold_splits` of ``fold_of``) into ``out``.

    ``out`` receives ``foldK/`` (a checkpoint each) and ``folds.json`` (:mod:`.folds`): per fold its
    held-out and training objects, its training summary and held-out metrics, and over all folds the
    held-out success accuracy and ROC AUC, each sample scored by the fold that never saw its object (and
    with a success head its ROC AUC and Brier score, ``held_out.success_head``).
    ``on_epoch(run, log)`` sees each fold's epochs as run ``foldK``. Returns the manifest.
    """
    from sklearn.metrics import roc_auc_score

    cfg = config or TrainConfig()
    folder = check_output(
        out, OutputKind.CHECKPOINT, overwrite=overwrite, inputs={"--data": data_dir, "--init": init}
    )
    start, mcfg = _initial(init, model_config)
    data = load_grasp_data(data_dir)
    folds = fold_splits(data, fold_of, seed=cfg.seed)
    for line in dataset_warnings(data):
        if warn:
            warn(line)
    dataset = _dataset_record(data)
    pooled = np.zeros((len(data), N_OUTPUTS))
    pooled_head = np.full(len(data), np.nan)  # the success head's probability; NaN without a head
    entries, surrogates = [], []
    for parts in folds:
        name = parts.mode
        res = train(data, parts, cfg, None if start else mcfg, init=start,
                    on_epoch=on_epoch and (lambda log, name=name: on_epoch(name, log)))  # fmt: skip
        sur = Surrogate(
            res.model,
            res.normalizer,
            lift=data.lift,
            lifted_fraction=data.lifted_fraction,
            input_range=_trained_range(data),
        )
        m, pooled[parts.test], head = _held_out(sur, data, parts, "surrogate")
        if head is not None:
            pooled_head[parts.test] = head
        seen = sorted(set(data.objects[data.pose[np.concatenate([parts.train, parts.val])]]))
        entry = {"path": name, "held_out": list(parts.test_objects), "train_objects": seen, "split": parts.as_dict(),
                 "training": {k: v for k, v in res.summary().items() if not isinstance(v, list)},
                 "test": {"loss": m["loss"], "success": {k: m["success"][k] for k in ("accuracy", "roc_auc", "rate")},
                          **({"success_head": {k: m["success_head"][k] for k in ("roc_auc", "brier")}} if "success_head" in m else {})}}  # fmt: skip
        sur.meta = {"dataset": dataset, "split": parts.as_dict(), "train": cfg.as_dict(), "fold": entry}
        if start is not None:
            sur.meta["init"] = _init_record(init)
        entries.append(entry)
        surrogates.append(sur)
    rows = np.concatenate([p.test for p in folds])
    score, truth = success_scores(pooled[rows], data, rows), data.success[rows]
    both = 0 < truth.sum() < len(truth)
    manifest = {"format": FOLDS_FORMAT, "version": FOLDS_VERSION, "dataset": dataset, "train": cfg.as_dict(),
                "model": mcfg.as_dict(), "folds": entries,
                "held_out": {"objects": sum(len(p.test_objects) for p in folds), "samples": int(len(rows)),
                             "success_accuracy": float(np.mean((score > 0) == truth)),
                             "success_roc_auc": float(roc_auc_score(truth, score)) if both else None}}  # fmt: skip
    if not np.isnan(pooled_head[rows]).any():
        p = pooled_head[rows]
        manifest["held_out"]["success_head"] = {"roc_auc": float(roc_auc_score(truth, p)) if both else None,
                                                "brier": float(np.mean((p - truth) ** 2))}  # fmt: skip
    if start is not None:
        manifest["init"] = _init_record(init)
    with staged(folder) as root:
        for parts, sur in zip(folds, surrogates, strict=True):
            save_checkpoint(root / parts.mode, sur)
        write_atomic(root / FOLDS_FILE, json.dumps(manifest, indent=1, allow_nan=False))
    return manifest


def _brief(metrics: dict) -> dict:
    net = metrics["test"]["surrogate"]
    head = (
        {"success_head": {k: net["success_head"][k] for k in ("roc_auc", "brier")}}
        if "success_head" in net
        else {}
    )
    return {"test_loss": net["loss"], "mae": net["mae"], "success": {k: net["success"][k] for k in ("accuracy", "roc_auc")},
            **head, "epochs": metrics["training"]["epochs"], "verdict": metrics["verdict"]}  # fmt: skip


def _success_probabilities(m: dict) -> list[dict]:
    """A model's success predictions that have an AUC and a Brier score: the score (calibrated), the head."""
    return [m[k] for k in ("success", "success_head") if k in m]


def verdict(models: dict, ranking: dict | None = None) -> dict:
    """Whether the surrogate beats both baselines: on the test loss, per output MAE, success AUC.

    With a success head: whether the head's AUC is above, and its Brier score below, every baseline's
    success prediction (score and classifier). With ``ranking`` (:func:`_ranking`): whether the head's
    (else the score's) median design-ranking Spearman reaches :data:`_RANKING_TARGET` and beats the trees'.
    """
    net, base = models["surrogate"], [m for k, m in models.items() if k != "surrogate"]
    per_output = {k: all(v < b["mae"][k] for b in base) for k, v in net["mae"].items()}
    auc = net["success"]["roc_auc"]
    auc_better = auc is not None and all(
        b["success"]["roc_auc"] is None or auc > b["success"]["roc_auc"] for b in base
    )
    out = {"loss": all(net["loss"] < b["loss"] for b in base), "outputs_better": sum(per_output.values()),
           "outputs": len(per_output), "per_output": per_output, "success_auc": auc_better}  # fmt: skip
    if "success_head" in net:
        head, rivals = net["success_head"], [p for b in base for p in _success_probabilities(b)]
        out["head_auc"] = head["roc_auc"] is not None and all(
            r["roc_auc"] is None or head["roc_auc"] > r["roc_auc"] for r in rivals
        )
        out["head_brier"] = all(head["brier"] < r["brier"] for r in rivals)
    if ranking is not None:
        ms = ranking["models"]
        mine = ms.get("surrogate (head)", ms["surrogate (score)"])["median"]
        trees = [
            v["median"] for k, v in ms.items() if k.startswith("gradient-boosted") and v["median"] is not None
        ]
        out["ranking_median"] = mine
        out["ranking_target"] = mine is not None and mine >= _RANKING_TARGET
        out["ranking_beats_trees"] = mine is not None and all(mine > t for t in trees)
        if LINEAR_DESIGN in ms:
            lin = ms[LINEAR_DESIGN]["median"]
            out["ranking_beats_linear"] = mine is not None and (lin is None or mine > lin)
    return out


def _fmt(v) -> str:
    if v is None:
        return "–"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def ranking_markdown(r: dict, v: dict) -> list[str]:
    """The design-ranking section of the summary (:func:`_ranking`, the verdict's ranking keys)."""
    lines = ["## Design ranking", "",
             f"Per held-out pose with >= {r['min_designs']} designs, the Spearman correlation over its designs between a "
             f"predicted success probability and the measured success_p: {r['poses']} poses ranked, {r['constant']} left out "
             f"(the same measured p for every design), {r['too_few_designs']} with fewer designs.", "",
             "| prediction | median | IQR | mean | poses > 0 |", "|---|---|---|---|---|"]  # fmt: skip
    for name, s in r["models"].items():
        iqr = "–" if s["iqr"] is None else f"{s['iqr'][0]:.3f} – {s['iqr'][1]:.3f}"
        lines.append(f"| {name} | {_fmt(s['median'])} | {iqr} | {_fmt(s['mean'])} | {s['positive']} |")
    rep = r["repeatability"]
    if rep.get("computable"):
        lo, hi = rep["first_draws"], rep["all_draws"]
        lines += ["", f"The labels' own repeatability on the same {rep['poses']} poses, even against odd perturbed draws "
                  f"of each cell: median split-half Spearman {_fmt(lo['split_half_spearman']['median'])} over the first "
                  f"{rep['draws']} draws, {_fmt(hi['split_half_spearman']['median'])} over all draws; by Spearman–Brown a "
                  f"perfect predictor of the true probability reaches about {_fmt(lo['ceiling'])} to {_fmt(hi['ceiling'])} "
                  "(the first estimate is biased down, the second up by the adaptive extension)."]  # fmt: skip
    else:
        lines += ["", f"The labels' repeatability is not computable here: {rep['reason']}."]
    if "ranking_median" in v:
        lines += ["", f"Median {_fmt(v['ranking_median'])}: "
                  + ("reaches" if v["ranking_target"] else "does not reach") + f" {_RANKING_TARGET}, and "
                  + ("beats" if v["ranking_beats_trees"] else "does not beat") + " the trees'"
                  + ("" if "ranking_beats_linear" not in v else ", and "
                     + ("beats" if v["ranking_beats_linear"] else "does not beat")
                     + " the design-only linear baseline's (one preference for every pose, fitted on the training rows)")
                  + "."]  # fmt: skip
    return [*lines, ""]


def summary_markdown(m: dict) -> str:
    """The report as Markdown tables, with the verdict in words."""
    models = m["test"]
    names = list(models)
    v = m["verdict"]
    lines = [
        "# Surrogate report",
        "",
        f"Dataset `{m['dataset']['path']}` ({m['dataset']['samples']} samples, {m['dataset']['poses']} poses; "
        f"manifest sha256 `{m['dataset']['manifest_sha256'][:12]}`). Split **{m['split']['mode']}**: "
        f"train {m['split']['train']}, validation {m['split']['val']}, test {m['split']['test']}"
        + (f" (training and validation on the first {n} poses of each object, the test on all)"
           if (n := m["split"].get("poses_per_object")) is not None else "")
        + (f" (held-out objects: {', '.join(m['split']['test_objects'])})" if m["split"]["test_objects"] else "")
        + ".",
        "",
        f"Training: {m['training']['epochs']} epochs ({m['training']['stopped']}), best epoch "
        f"{m['training']['best_epoch']}, {m['training']['wall_s']:.0f} s ({m['training']['s_per_epoch']:.1f} s/epoch).",
        "",
        "## Verdict",
        "",
        ("The surrogate **beats both baselines** on the test loss."
         if v["loss"] else "The surrogate **does not beat both baselines** on the test loss.")
        + f" It has the lowest MAE on {v['outputs_better']} of {v['outputs']} outputs, and "
        + ("the best success ROC AUC." if v["success_auc"] else "not the best success ROC AUC.")
        + ("" if "head_auc" not in v else
           f" Its success head has {'the best' if v['head_auc'] else 'not the best'} success ROC AUC and "
           f"{'the lowest' if v['head_brier'] else 'not the lowest'} Brier score of all success predictions."),
        "",
        "## Held-out test",
        "",
        "| | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]  # fmt: skip
    rows = [("loss (paper's scale)", lambda x: x["loss"]), ("mean z-scored L1", lambda x: x["l1_z_mean"]),
            ("contact BCE", lambda x: x["contact_bce"])]  # fmt: skip
    rows += [(f"MAE {k}", lambda x, k=k: x["mae"][k]) for k in models["surrogate"]["mae"]]
    rows += [("ground contact accuracy", lambda x: x["contact"]["accuracy"]), ("ground contact ROC AUC", lambda x: x["contact"]["roc_auc"]),
             ("success accuracy", lambda x: x["success"]["accuracy"]), ("success ROC AUC", lambda x: x["success"]["roc_auc"]),
             ("success Brier (calibrated)", lambda x: x["success"]["brier"]), ("predicted success rate", lambda x: x["success"]["predicted_rate"])]  # fmt: skip
    if "success_head" in models["surrogate"]:
        head = (("success probability ROC AUC (head; trees: classifier)", "roc_auc"), ("success probability Brier (vs 0/1)", "brier"),
                ("success probability Brier (vs success_p)", "brier_p"), ("success probability accuracy (p > 0.5)", "accuracy"))  # fmt: skip
        rows += [(label, lambda x, k=key: x.get("success_head", {}).get(k)) for label, key in head]
    lines += [f"| {label} | " + " | ".join(_fmt(f(models[n])) for n in names) + " |" for label, f in rows]
    rule = m["success_rule_on_simulator_outputs"]
    lines += ["", f"Simulator success rate on the test rows: {models['surrogate']['success']['rate']:.3f}. The success rule "
              f"applied to the simulator's own outputs agrees with its flag on {rule['accuracy']:.3f} of them (the ceiling "
              "of success from outputs).", ""]  # fmt: skip
    if "ranking" in m:
        lines += ranking_markdown(m["ranking"], v)
    if "efficiency" in m:
        e = m["efficiency"]
        lines += ["## Data efficiency", "", "| training rows | epochs | test loss | success ROC AUC |", "|---|---|---|---|",
                  f"| {m['training']['train_rows']} (all) | {m['training']['epochs']} | {_fmt(models['surrogate']['loss'])} | {_fmt(models['surrogate']['success']['roc_auc'])} |",
                  f"| {e['training']['train_rows']} ({e['fraction']:.0%}) | {e['training']['epochs']} | {_fmt(e['test']['loss'])} | {_fmt(e['test']['success']['roc_auc'])} |",
                  "", "The paper: 80k samples reached 0.141, 20k reached 0.192 (its own data and random split).", ""]  # fmt: skip
    if "smoothness" in m:
        s = m["smoothness"]
        lines += ["## Smoothness along random design lines", "",
                  f"{len(s['lines'])} lines over {len({r['pose_row'] for r in s['lines']})} held-out poses, {s['points']} points each, "
                  f"length {s['length']} in ln E (step {s['step']:.3g}); L_opt of the simulator's outcome (contact 0/1) "
                  "beside the surrogate's.", "",
                  "| object | pose | ‖∇L‖ mean | max \\|u·∇L\\| (surrogate) | max \\|ΔL/Δt\\| (simulator) | TV surrogate | TV simulator | success flips (sim) |",
                  "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        lines += [f"| {r['object']} | {r['pose_row']} | {_fmt(r['grad_norm_mean'])} | {_fmt(r['surrogate_slope_max'])} | "
                  f"{_fmt(r['simulator_fd_abs_max'])} | {_fmt(r['surrogate_total_variation'])} | "
                  f"{_fmt(r['simulator_total_variation'])} | {r['simulator_success_flips']} |" for r in s["lines"]]  # fmt: skip
        med = s["median"]
        if "slope_correlation" in med:
            lines += ["", f"Over the {med['lines']} lines: total variation median {_fmt(med['surrogate_total_variation'])} "
                      f"(simulator {_fmt(med['simulator_total_variation'])}), mean {_fmt(med['surrogate_total_variation_mean'])} "
                      f"(simulator {_fmt(med['simulator_total_variation_mean'])}); median ‖∇L‖ {_fmt(med['grad_norm_mean'])}; "
                      f"the two curves' slopes along the lines: correlation {_fmt(med['slope_correlation'])}, rank correlation "
                      f"{_fmt(med.get('slope_rank_correlation'))}, same sign on {_fmt(med.get('slope_sign_agreement'))} of the lines."]  # fmt: skip
        lines.append("")
    return "\n".join(lines)
