"""Held-out metrics of a set of predicted outputs, and the baselines they are measured against.

Outputs are arrays (S, 10) in physical units: body force (torque [N m] 3, force [N] 3), displacement
[m] (3), ground-contact probability. :func:`score_outputs` gives, on the test rows:

* the MAE of every output (torque in N·m, force in N, displacement in mm) and of the contact
  probability against the simulator's 0/1, with the contact's accuracy and ROC AUC;
* success classification from the outputs (:func:`~mjcodesign.surrogate.inference.success_score`):
  accuracy of score > 0, ROC AUC of the score, and a calibration: a logistic map of the score to a
  probability fitted on the validation rows (Platt), its Brier score and reliability bins on the test;
* with a predicted success probability (a network's success head, the trees' success classifier):
  ``success_head``, its ROC AUC, accuracy of p > 0.5, Brier score against the 0/1 success and against
  the measured ``success_p``, and its reliability bins (no recalibration).

Baselines on the same split: :func:`mean_baseline` (the training mean of each output) and
:func:`tree_baseline` (scikit-learn's ``HistGradientBoostingRegressor`` with an absolute-error loss
per output, and its classifier for the contact, on 22 ln E, COM, density, ``up`` and
:func:`cloud_statistics`), and for the success probability :func:`tree_success` (the classifier on
the same features, trained with the head's cross-entropy on the soft label).
"""

from __future__ import annotations

import numpy as np

from mjcodesign.surrogate.data import N_REGRESSION, OUTPUT_NAMES, GraspData
from mjcodesign.surrogate.inference import success_score

__all__ = [
    "calibrated_success",
    "cloud_statistics",
    "mean_baseline",
    "score_outputs",
    "soft_label_trees",
    "success_scores",
    "success_head_metrics",
    "tree_baseline",
    "tree_features",
    "tree_success",
]

_UNITS = {"torque": ("N m", 1.0), "force": ("N", 1.0), "displacement": ("mm", 1e3)}
_CALIBRATION_BINS = 10
_TREE_ITERATIONS = 300
_TREE_LEARNING_RATE = 0.1


def success_scores(outputs: np.ndarray, data: GraspData, rows: np.ndarray) -> np.ndarray:
    """:func:`success_score` of outputs (S, 10) of the samples ``rows``."""
    p = data.pose[rows]
    return success_score(
        outputs[:, :6],
        outputs[:, 6:9],
        outputs[:, 9],
        data.up[p],
        data.sample_mass[rows],
        data.lift,
        data.lifted_fraction,
    )


def _auc(truth: np.ndarray, score: np.ndarray) -> float | None:
    from sklearn.metrics import roc_auc_score

    return float(roc_auc_score(truth, score)) if 0 < truth.sum() < len(truth) else None


def _platt(val_score: np.ndarray, val_truth: np.ndarray):
    """A map score -> probability fitted on the validation rows (constant when they hold one class)."""
    from sklearn.linear_model import LogisticRegression

    if 0 < val_truth.sum() < len(val_truth):
        lr = LogisticRegression().fit(val_score[:, None], val_truth)
        return lambda s: lr.predict_proba(np.asarray(s)[:, None])[:, 1]
    rate = float(val_truth.mean()) if len(val_truth) else 0.5
    return lambda s: np.full(len(s), rate)


def calibrated_success(
    pred: np.ndarray, data: GraspData, rows: np.ndarray, val_pred: np.ndarray, val_rows: np.ndarray
) -> np.ndarray:
    """The success probability (S,) of outputs ``pred`` (S, 10) of ``rows``: their success score, Platt-mapped.

    The logistic map of :func:`success_scores` to the 0/1 success is fitted on the outputs ``val_pred``
    of the validation rows ``val_rows`` (never on ``rows``).
    """
    fit = _platt(success_scores(val_pred, data, val_rows), data.success[val_rows])
    return fit(success_scores(pred, data, rows))


def _reliability(prob: np.ndarray, truth: np.ndarray) -> list[dict]:
    edges = np.linspace(0.0, 1.0, _CALIBRATION_BINS + 1)
    idx = np.clip(np.searchsorted(edges, prob, side="right") - 1, 0, _CALIBRATION_BINS - 1)
    return [
        {"bin": [float(edges[b]), float(edges[b + 1])], "n": int(np.sum(idx == b)),
         "predicted": float(prob[idx == b].mean()), "observed": float(truth[idx == b].mean())}
        for b in range(_CALIBRATION_BINS)
        if np.any(idx == b)
    ]  # fmt: skip


def success_head_metrics(prob: np.ndarray, data: GraspData, rows: np.ndarray) -> dict:
    """Metrics of a predicted success probability ``prob`` (S,) of the samples ``rows``.

    Against the 0/1 success: ROC AUC, accuracy of p > 0.5, Brier score, reliability bins; and the
    Brier score against the measured share ``success_p`` (the 0/1 success for one rollout per cell).
    """
    from mjcodesign.surrogate.train import success_labels

    prob = np.asarray(prob, dtype=float)
    truth = data.success[rows]
    return {
        "accuracy": float(np.mean((prob > 0.5) == truth)),
        "roc_auc": _auc(truth, prob),
        "brier": float(np.mean((prob - truth) ** 2)),
        "brier_p": float(np.mean((prob - success_labels(data, rows)) ** 2)),
        "predicted_rate": float(np.mean(prob > 0.5)),
        "calibration": _reliability(prob, truth.astype(float)),
    }


def score_outputs(
    pred: np.ndarray,
    data: GraspData,
    rows: np.ndarray,
    val_pred: np.ndarray,
    val_rows: np.ndarray,
    success_p: np.ndarray | None = None,
) -> dict:
    """Metrics of predicted outputs ``pred`` (S, 10) of the test ``rows`` (module docstring).

    ``val_pred`` of the ``val_rows`` fit the success calibration. ``success_p`` (S,): a predicted
    success probability of the same rows, scored as ``success_head`` (:func:`success_head_metrics`).
    """
    true = data.outputs[rows]
    mae = {}
    for i, name in enumerate(OUTPUT_NAMES[:N_REGRESSION]):
        unit, scale = _UNITS[name.split("_")[0]]
        mae[f"{name} [{unit}]"] = float(np.mean(np.abs(pred[:, i] - true[:, i])) * scale)
    contact = true[:, 9].astype(bool)
    score = success_scores(pred, data, rows)
    truth = data.success[rows]
    prob = calibrated_success(pred, data, rows, val_pred, val_rows)
    return {
        "samples": int(len(rows)),
        "mae": mae,
        "contact": {
            "mae": float(np.mean(np.abs(pred[:, 9] - true[:, 9]))),
            "accuracy": float(np.mean((pred[:, 9] > 0.5) == contact)),
            "roc_auc": _auc(contact, pred[:, 9]),
            "rate": float(contact.mean()),
        },
        "success": {
            "accuracy": float(np.mean((score > 0) == truth)),
            "roc_auc": _auc(truth, score),
            "rate": float(truth.mean()),
            "predicted_rate": float(np.mean(score > 0)),
            "brier": float(np.mean((prob - truth) ** 2)),
            "calibration": _reliability(prob, truth.astype(float)),
        },
        **({"success_head": success_head_metrics(success_p, data, rows)} if success_p is not None else {}),
    }


def mean_baseline(data: GraspData, train_rows: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The training mean of every output (contact: the training contact rate), for ``rows``."""
    return np.repeat(data.outputs[train_rows].mean(axis=0)[None], len(rows), axis=0)


def cloud_statistics(clouds: np.ndarray) -> np.ndarray:
    """Simple per-cloud features [m], shape (P, 16).

    Centroid (3), extent along the gripper axes (3), principal standard deviations (3), the first two
    principal axes (6, sign fixed so that the largest component is positive) and the radius (1).
    """
    c = np.asarray(clouds, dtype=float)
    centre = c.mean(axis=1)
    d = c - centre[:, None]
    extent = c.max(axis=1) - c.min(axis=1)
    cov = np.einsum("pni,pnj->pij", d, d) / c.shape[1]
    w, v = np.linalg.eigh(cov)  # ascending
    axes = v[:, :, ::-1][:, :, :2]  # (P, 3, 2), largest first
    sign = np.sign(np.take_along_axis(axes, np.abs(axes).argmax(axis=1)[:, None], axis=1))
    axes = (axes * np.where(sign == 0, 1.0, sign)).transpose(0, 2, 1).reshape(len(c), 6)
    radius = np.linalg.norm(d, axis=2).max(axis=1)
    return np.concatenate([centre, extent, np.sqrt(np.maximum(w[:, ::-1], 0)), axes, radius[:, None]], axis=1)


def tree_features(data: GraspData, rows: np.ndarray, stats: np.ndarray | None = None) -> np.ndarray:
    """Inputs of the tree baseline for ``rows``: 22 ln E, COM, density, up and the cloud statistics."""
    stats = cloud_statistics(data.clouds) if stats is None else stats
    p = data.pose[rows]
    return np.concatenate(
        [data.log_e[rows], data.com[p], data.density[rows, None], data.up[p], stats[p]], axis=1
    )


def tree_baseline(
    data: GraspData, train_rows: np.ndarray, rows_list: list[np.ndarray], seed: int = 0
) -> list[np.ndarray]:
    """Gradient-boosted trees fitted on ``train_rows``; their outputs (S, 10) for each of ``rows_list``."""
    from sklearn.ensemble import HistGradientBoostingClassifier, HistGradientBoostingRegressor

    stats = cloud_statistics(data.clouds)
    x_train = tree_features(data, train_rows, stats)
    xs = [tree_features(data, r, stats) for r in rows_list]
    outs = [np.zeros((len(r), N_REGRESSION + 1)) for r in rows_list]
    kw = {"max_iter": _TREE_ITERATIONS, "learning_rate": _TREE_LEARNING_RATE, "random_state": seed}
    for i in range(N_REGRESSION):
        m = HistGradientBoostingRegressor(loss="absolute_error", **kw).fit(
            x_train, data.outputs[train_rows, i]
        )
        for out, x in zip(outs, xs, strict=True):
            out[:, i] = m.predict(x)
    contact = data.outputs[train_rows, N_REGRESSION].astype(int)
    if 0 < contact.sum() < len(contact):
        clf = HistGradientBoostingClassifier(**kw).fit(x_train, contact)
        for out, x in zip(outs, xs, strict=True):
            out[:, N_REGRESSION] = clf.predict_proba(x)[:, 1]
    else:
        for out in outs:
            out[:, N_REGRESSION] = float(contact.mean())
    return outs


def tree_success(
    data: GraspData, train_rows: np.ndarray, rows_list: list[np.ndarray], seed: int = 0
) -> list[np.ndarray]:
    """Gradient-boosted trees' success probability (S,) for each of ``rows_list``, fitted on ``train_rows``.

    scikit-learn's ``HistGradientBoostingClassifier`` on :func:`tree_features`, trained on the soft label
    (:func:`~mjcodesign.surrogate.train.success_labels`) with the head's cross-entropy: each training
    row enters as a success of weight p and a failure of weight 1 − p.
    """
    from mjcodesign.surrogate.train import success_labels

    stats = cloud_statistics(data.clouds)
    x = tree_features(data, train_rows, stats)
    xs = [tree_features(data, r, stats) for r in rows_list]
    return soft_label_trees(x, success_labels(data, train_rows), xs, seed)


def soft_label_trees(x: np.ndarray, p: np.ndarray, xs: list[np.ndarray], seed: int = 0) -> list[np.ndarray]:
    """Success probability for each of ``xs`` from trees fitted on inputs ``x`` (S, F) and soft labels ``p`` (S,).

    Each training row enters as a success of weight p and a failure of weight 1 − p (the head's
    cross-entropy); a constant label gives its mean everywhere.
    """
    from sklearn.ensemble import HistGradientBoostingClassifier

    if not 0 < p.sum() < len(p):
        return [np.full(len(xr), float(p.mean())) for xr in xs]
    y = np.concatenate([np.ones(len(p), dtype=int), np.zeros(len(p), dtype=int)])
    w = np.concatenate([p, 1.0 - p])
    keep = w > 0
    kw = {"max_iter": _TREE_ITERATIONS, "learning_rate": _TREE_LEARNING_RATE, "random_state": seed}
    clf = HistGradientBoostingClassifier(**kw).fit(
        np.concatenate([x, x])[keep], y[keep], sample_weight=w[keep]
    )
    return [clf.predict_proba(xr)[:, 1] for xr in xs]
