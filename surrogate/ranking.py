"""Design-ranking fidelity: per held-out (object, pose), how well a predicted success probability orders its designs.

A co-design picks the best design for a pose, so what counts is the order of the designs, not the
absolute probability. For each pose of the test rows with at least :data:`MIN_DESIGNS` designs,
:func:`ranking_fidelity` takes the Spearman rank correlation, over the pose's designs, between a
predicted success probability and the measured share ``success_p``. A pose whose measured p is the
same for every design has no ranking: it is counted apart (``constant``) and left out. A prediction
that is constant over a pose's designs orders nothing: its correlation counts as 0.

**The simulator's own repeatability** (:func:`split_half`). A perturbed dataset's rollouts table holds
every draw of a cell. Each cell's usable rollouts split into even and odd draws give two independent
half-labels; their Spearman over a pose's designs is the split-half reliability r_h. The
Spearman–Brown formula gives the full label's reliability r = 2 r_h / (1 + r_h), and even a perfect
predictor of the true probability correlates with the measured label by about √r at most (classical
test theory; for rank correlations an approximation). The adaptive scheme (``K:M``) extends only the
cells whose first K rollouts disagree, so over all draws the halves of a cell that was not extended
agree by selection: that estimate (``all_draws``) is biased up. Over the first K draws of every cell
(``first_draws``) there is no selection, but the label it describes has K rollouts where the stored
one has up to M: that estimate is biased down. The ceiling is reported as the pair.

**A design-only baseline** (:func:`linear_design_effect`). A ridge regression of the label, centred
per pose, on the 22 ln E, fitted on the training rows: the one design preference shared by every
pose of the training objects, blind to the object and the grasp. A surrogate that ranks a held-out
pose's designs no better than it has learnt nothing about how a design's effect depends on the grasp.
"""

from __future__ import annotations

import numpy as np

from mjcodesign.surrogate.data import GraspData

__all__ = [
    "MIN_DESIGNS",
    "group_spearman",
    "half_labels",
    "linear_design_effect",
    "pose_groups",
    "ranking_fidelity",
    "split_half",
]

MIN_DESIGNS = 8
"""Designs a pose needs for its ranking to count: below it a rank correlation has too few pairs."""
_CONSTANT = 1e-12  # a spread of probabilities below this is one value
DESIGN_RIDGE = 10.0
"""Ridge penalty of :func:`linear_design_effect` on ln E centred at the range's middle, against
thousands of pose-centred rows: it only keeps the fit defined where few poses vary (on the real_d20
dataset the held-out ranking moved by < 0.01 between penalties 1 and 100)."""
_LN_E_MIDDLE = 15.25  # the middle of the design range [13.5, 17.0]


def _spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman correlation (average ranks for ties); 0 where ``a`` is constant, NaN where ``b`` is."""
    from scipy.stats import rankdata

    if np.ptp(b) <= _CONSTANT:
        return float("nan")
    if np.ptp(a) <= _CONSTANT:
        return 0.0
    ra, rb = rankdata(a), rankdata(b)
    return float(np.corrcoef(ra, rb)[0, 1])


def group_spearman(pred: np.ndarray, label: np.ndarray, groups: list[np.ndarray]) -> np.ndarray:
    """Per group (index array into ``pred`` and ``label``), the Spearman of ``pred`` against ``label``.

    NaN for a group whose ``label`` is constant (no ranking); 0 for one whose ``pred`` is constant.
    """
    pred, label = np.asarray(pred, dtype=float), np.asarray(label, dtype=float)
    return np.array([_spearman(pred[g], label[g]) for g in groups], dtype=float)


def pose_groups(
    data: GraspData, rows: np.ndarray, min_designs: int = MIN_DESIGNS
) -> tuple[list[np.ndarray], int]:
    """Positions in ``rows`` of each pose's samples, for poses with >= ``min_designs`` of them; and how many had fewer."""
    pose = data.pose[np.asarray(rows)]
    order = np.argsort(pose, kind="stable")
    starts = np.flatnonzero(np.diff(pose[order], prepend=-1))
    groups = np.split(order, starts[1:]) if len(order) else []
    kept = [g for g in groups if len(g) >= min_designs]
    return kept, len(groups) - len(kept)


def _summary(values: np.ndarray) -> dict:
    v = values[np.isfinite(values)]
    if not len(v):
        return {"median": None, "iqr": None, "mean": None, "positive": 0}
    q25, med, q75 = np.percentile(v, [25, 50, 75])
    return {"median": float(med), "iqr": [float(q25), float(q75)], "mean": float(v.mean()),
            "positive": int(np.sum(v > 0))}  # fmt: skip


def ranking_fidelity(
    predictions: dict[str, np.ndarray], data: GraspData, rows: np.ndarray, min_designs: int = MIN_DESIGNS
) -> dict:
    """The Spearman over designs per pose of each predicted probability in ``predictions`` (name -> (S,)).

    ``rows``: the samples the predictions are of (the test rows). Returns the counts (poses ranked,
    ``constant`` ones left out, poses with too few designs) and per prediction the median, the
    interquartile range, the mean and the number of positive correlations over the ranked poses,
    with the per-pose values.
    """
    from mjcodesign.surrogate.train import success_labels

    rows = np.asarray(rows)
    label = success_labels(data, rows)
    groups, too_few = pose_groups(data, rows, min_designs)
    per = {name: group_spearman(p, label, groups) for name, p in predictions.items()}
    ranked = np.array([bool(np.ptp(label[g]) > _CONSTANT) for g in groups], dtype=bool)
    poses = [int(data.pose[rows[g[0]]]) for g in groups]
    return {
        "min_designs": int(min_designs),
        "poses": int(ranked.sum()),
        "constant": int((~ranked).sum()),
        "too_few_designs": int(too_few),
        "models": {name: _summary(v) for name, v in per.items()},
        "per_pose": [
            {
                "pose_row": p,
                "object": str(data.objects[p]),
                "designs": len(g),
                **{name: float(per[name][i]) for name in per},
            }
            for i, (p, g) in enumerate(zip(poses, groups, strict=True))
            if ranked[i]
        ],  # fmt: skip
    }


def linear_design_effect(
    data: GraspData, train_rows: np.ndarray, rows: np.ndarray, ridge: float = DESIGN_RIDGE
) -> np.ndarray:
    """The design-only ranking baseline (module docstring) fitted on ``train_rows``, scored on ``rows``.

    Returns a score per row of ``rows`` (S,) whose order within a pose is the fitted preference; its
    level means nothing (the fit is of pose-centred labels).
    """
    from mjcodesign.surrogate.train import success_labels

    train_rows = np.asarray(train_rows)
    label = success_labels(data, train_rows)
    pose = data.pose[train_rows]
    _, inverse, counts = np.unique(pose, return_inverse=True, return_counts=True)
    centred = label - np.bincount(inverse, weights=label)[inverse] / counts[inverse]
    x = data.log_e[train_rows] - _LN_E_MIDDLE
    coef = np.linalg.solve(x.T @ x + ridge * np.eye(x.shape[1]), x.T @ centred)
    return (data.log_e[np.asarray(rows)] - _LN_E_MIDDLE) @ coef


def half_labels(draw: np.ndarray, success: np.ndarray, usable: np.ndarray, cell: np.ndarray, n_cells: int):
    """Per cell, the share of successes among its usable even draws and among its usable odd draws.

    ``draw``, ``success``, ``usable`` and ``cell`` (0..n_cells-1) are per rollout (leave a draw out
    with ``usable`` False). Returns two arrays (n_cells,), NaN where a half holds no usable rollout.
    """
    out = []
    for parity in (0, 1):
        m = usable & (np.asarray(draw) % 2 == parity)
        wins = np.bincount(cell[m], weights=np.asarray(success, dtype=float)[m], minlength=n_cells)
        count = np.bincount(cell[m], minlength=n_cells).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            out.append(np.where(count > 0, wins / np.maximum(count, 1.0), np.nan))
    return out[0], out[1]


def split_half(data: GraspData, rows: np.ndarray, min_designs: int = MIN_DESIGNS) -> dict:
    """The labels' split-half ranking reliability over the poses :func:`ranking_fidelity` ranks (module docstring).

    Returns ``computable`` False (with the reason) for a dataset without a rollouts table.
    """
    from mjcodesign.data import open_dataset
    from mjcodesign.surrogate.train import success_labels

    ds = open_dataset(data.root)
    if not ds.perturbed:
        return {"computable": False, "reason": "one rollout per cell: the dataset has no rollouts table"}
    first = int(ds.manifest["config"]["perturbations"]["draws"])
    s, r = ds.samples(), ds.rollouts()
    keys = ("object_index", "pose_index", "design_index")
    cell_of = {k: i for i, k in enumerate(zip(*(s.column(k).to_pylist() for k in keys), strict=True))}
    cells = [cell_of.get(k, -1) for k in zip(*(r.column(k).to_pylist() for k in keys), strict=True)]
    cell = np.array(cells, dtype=np.int64)
    known = cell >= 0
    usable = known & ~r.column("sample_error").to_numpy(zero_copy_only=False).astype(bool)
    draw, success = r.column("draw").to_numpy(), r.column("success").to_numpy(zero_copy_only=False)
    rows = np.asarray(rows)
    label = success_labels(data, rows)
    groups, _ = pose_groups(data, rows, min_designs)
    groups = [g for g in groups if np.ptp(label[g]) > _CONSTANT]
    out = {"computable": True, "poses": len(groups), "draws": first}
    for name, keep in (("all_draws", usable), ("first_draws", usable & (draw < first))):
        even, odd = half_labels(draw, success, keep, np.where(known, cell, 0), len(data))
        out[name] = _reliability_of(even[rows], odd[rows], groups)
    ceilings = [out[k]["ceiling"] for k in ("first_draws", "all_draws")]
    out["ceiling"] = None if None in ceilings else ceilings
    out["method"] = (
        "even vs odd draws of each cell, over all draws (biased up by the adaptive extension) and over "
        "the first K draws (biased down: K rollouts, not M); Spearman-Brown on the median split-half "
        "Spearman; ceiling = sqrt(reliability)"
    )
    return out


def _reliability_of(a: np.ndarray, b: np.ndarray, groups: list[np.ndarray]) -> dict:
    """Split-half Spearman per group of half-labels ``a`` and ``b``, and the ceiling it implies."""
    values = []
    for g in groups:
        ok = g[np.isfinite(a[g]) & np.isfinite(b[g])]
        v = _spearman(a[ok], b[ok]) if len(ok) >= 2 else float("nan")
        values.append(0.0 if np.isnan(v) else v)  # a constant half ranks nothing
    summary = _summary(np.array(values, dtype=float))
    r_half = summary["median"]
    full = None if r_half is None or r_half <= 0 else 2 * r_half / (1 + r_half)
    return {"split_half_spearman": summary, "full_label_reliability": full,
            "ceiling": None if full is None else float(np.sqrt(full))}  # fmt: skip
