"""Training the surrogate: AdamW, L1 on standardised outputs, a plateau schedule, early stopping.

As the authors' ``train.py``: AdamW at ``lr`` (the PointNet at half of it), weight decay 1e-3, batch
512, L1 loss on z-scored outputs, ``ReduceLROnPlateau(0.8)`` on the validation loss, the best
validation weights kept. Three changes: the ground contact is a logit under a binary cross-entropy (so
that the network gives a probability); a network with a success head
(:attr:`~mjcodesign.surrogate.model.ModelConfig.success_head`) adds the binary cross-entropy of its
logit against the soft label ``success_p`` (:func:`success_labels`), weighted by
:attr:`TrainConfig.success_weight`, and optionally a pairwise ranking term on that logit between the
designs of one pose (:func:`rank_loss`, :attr:`TrainConfig.rank_weight`); and a batch is grouped by pose (:func:`pose_batches`) so that
each pose's PointNet feature is computed once and shared by its samples: over 512 random samples the
PointNet would run ~460 times per step (2.6 s forward and backward on 512 clouds here), about 400 s
an epoch on 80k samples.

Deterministic for a seed on the CPU: the shuffles come from ``numpy.random.default_rng(seed)``, the
initial weights and dropout masks from ``torch.manual_seed(seed)`` inside ``torch.random.fork_rng``
(the caller's generator state is left as it was).
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from mjcodesign.errors import DesignError
from mjcodesign.surrogate.data import (
    N_OUTPUTS,
    N_REGRESSION,
    GraspData,
    GraspDataset,
    Normalizer,
    Split,
    TrainBatch,
    pose_batches,
)
from mjcodesign.surrogate.model import GraspNet, ModelConfig

_CONTACT_WEIGHT = 1.0  # the contact's cross-entropy against one L1 term of a z-scored output
SUCCESS_WEIGHT = 1.0
"""Default weight of the success head's cross-entropy in the loss, against one L1 term of a z-scored
output (the contact's weight): the head is one more output, and the regression that shares its
layers keeps its share of the gradient (docs/concepts/surrogate.md gives the measured alternatives)."""
PRECISIONS = ("fp32", "bf16")

__all__ = [
    "PRECISIONS",
    "SUCCESS_WEIGHT",
    "EpochLog",
    "OptimizerConfig",
    "TrainConfig",
    "TrainResult",
    "evaluate_loss",
    "grasp_loss",
    "make_optimizer",
    "rank_loss",
    "success_labels",
    "train",
    "training_set",
    "train_step",
]


@dataclass(frozen=True, kw_only=True)
class OptimizerConfig:
    """AdamW and its plateau schedule; defaults from the authors' ``train.py`` unless noted."""

    lr: float = 1e-3
    pointnet_lr_factor: float = 0.5
    """The PointNet's learning rate is ``lr`` times this."""
    weight_decay: float = 1e-3
    plateau_factor: float = 0.8
    plateau_patience: int = 5
    """Epochs without a better validation loss before the LR drops (the authors: 200 of 10k)."""

    def __post_init__(self) -> None:
        if not (self.lr > 0 and self.pointnet_lr_factor > 0 and self.weight_decay >= 0):
            raise DesignError("lr > 0, pointnet_lr_factor > 0 and weight_decay >= 0 required")
        if not (0 < self.plateau_factor < 1) or _bad_count(self.plateau_patience, 1):
            raise DesignError("plateau_factor in (0, 1) and an integer plateau_patience >= 1 required")


def _bad_count(v, low: int) -> bool:
    return isinstance(v, bool) or not isinstance(v, int) or v < low


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Epochs, batches, the optimiser and stopping."""

    epochs: int = 200
    """Most epochs (the authors: 10k, validated every 100, on a GPU)."""
    batch_size: int = 512
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    early_stop_patience: int = 20
    """Epochs without a better validation loss before training stops (the authors: 500 of 10k)."""
    pose_group: int = 0
    """Samples of one pose laid together in a batch (0: all of them; see :func:`pose_batches`)."""
    precision: str = "fp32"
    """``fp32``, or ``bf16``: the training forward and backward under ``torch.autocast`` in bfloat16
    (weights, optimiser state, loss and validation stay float32). On a CPU with AVX512-BF16 a paper
    network's step at batch 512 takes 88 ms against 160 ms (``bench surrogate``, alternated, 2 threads);
    see docs/benchmarks.md for what it does to the metrics."""
    seed: int = 0
    split_seed: int | None = None
    """Seed of the held-out objects' draw (None: ``seed``). Networks that differ only in ``seed`` and share
    it hold out the same objects: an ensemble, or seeds compared on the same rows."""
    success_weight: float = SUCCESS_WEIGHT
    """Weight of the success head's cross-entropy in the loss (unused by a network without a head)."""
    rank_weight: float = 0.0
    """Weight of :func:`rank_loss`, the head's pairwise ranking of one pose's designs, in the loss
    (0: none; needs a success head and batches that keep a pose's designs together)."""

    def __post_init__(self) -> None:
        for name in ("success_weight", "rank_weight"):
            w = getattr(self, name)
            if isinstance(w, bool) or not (isinstance(w, int | float) and 0 <= w < float("inf")):
                raise DesignError(f"{name} must be a finite number >= 0, got {w!r}")
        if self.rank_weight > 0 and self.success_weight <= 0:
            raise DesignError("rank_weight needs the success head (success_weight > 0)")
        if self.rank_weight > 0 and self.pose_group == 1:
            raise DesignError("rank_weight needs a pose's designs in one batch: pose_group 0 or >= 2")
        bad = [n for n, low in (("epochs", 1), ("batch_size", 2), ("early_stop_patience", 1), ("pose_group", 0),
                                ("seed", 0)) if _bad_count(getattr(self, n), low)]  # fmt: skip
        if bad:
            raise DesignError(
                f"{', '.join(bad)}: integers required (batch_size >= 2, epochs and patience >= 1)"
            )
        if self.split_seed is not None and _bad_count(self.split_seed, 0):
            raise DesignError(f"split_seed must be None or an integer >= 0, got {self.split_seed!r}")
        if not isinstance(self.optimizer, OptimizerConfig):
            raise DesignError(f"optimizer must be an OptimizerConfig, got {self.optimizer!r}")
        if self.precision not in PRECISIONS:
            raise DesignError(f"unknown precision {self.precision!r}: choose from {', '.join(PRECISIONS)}")

    @property
    def data_seed(self) -> int:
        """The seed of the object split: ``split_seed``, else ``seed``."""
        return self.seed if self.split_seed is None else self.split_seed

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class EpochLog:
    """One epoch, handed to ``on_epoch``."""

    epoch: int
    train_loss: float
    val_loss: float
    lr: float
    seconds: float
    best: bool
    """This epoch's validation loss is the best so far (its weights are kept)."""


@dataclass
class TrainResult:
    """A trained network (the best validation weights, in eval mode) and how it got there."""

    model: GraspNet
    normalizer: Normalizer
    history: list[EpochLog] = field(default_factory=list)
    best_epoch: int = 0
    best_val_loss: float = float("inf")
    stopped: str = ""
    """``early_stop`` or ``max_epochs``."""
    wall_s: float = 0.0
    train_rows: int = 0

    def summary(self) -> dict:
        """JSON-ready: epochs, best epoch and loss, the curves."""
        return {
            "epochs": len(self.history),
            "best_epoch": self.best_epoch,
            "best_val_loss": self.best_val_loss,
            "stopped": self.stopped,
            "wall_s": self.wall_s,
            "s_per_epoch": self.wall_s / max(1, len(self.history)),
            "train_rows": self.train_rows,
            "train_loss": [h.train_loss for h in self.history],
            "val_loss": [h.val_loss for h in self.history],
            "lr": [h.lr for h in self.history],
        }


def rank_loss(logit: torch.Tensor, label: torch.Tensor, pose_of: torch.Tensor) -> torch.Tensor:
    """Pairwise logistic ranking loss of ``logit`` between samples of one pose, over the label gap.

    For every ordered pair (i, j) of samples with the same ``pose_of`` and ``label[i] > label[j]`` the
    term is ``log(1 + exp(logit[j] - logit[i]))`` (RankNet), weighted by ``label[i] - label[j]``; the
    result is the weighted mean (0 when no pose of the batch has two different labels). A constant
    shift of the logits within a pose leaves it unchanged: it scores the order of a pose's designs
    only, which is what a co-design uses, not the pose's level, which the cross-entropy fits.
    """
    gap = label[:, None] - label[None, :]
    pair = (pose_of[:, None] == pose_of[None, :]) & (gap > 0)
    if not bool(pair.any()):
        return logit.sum() * 0.0
    margin = logit[:, None] - logit[None, :]
    w = gap[pair]
    return (w * nn.functional.softplus(-margin[pair])).sum() / w.sum()


def grasp_loss(
    pred: torch.Tensor,
    y: torch.Tensor,
    success_weight: float = SUCCESS_WEIGHT,
    rank_weight: float = 0.0,
    pose_of: torch.Tensor | None = None,
) -> torch.Tensor:
    """Sum of the 9 L1 terms on z-scored outputs and the contact's cross-entropy, over 10.

    With a success head (``pred`` and ``y`` of 11 columns) the sum also holds ``success_weight`` times
    the cross-entropy of the head's logit against the soft label in ``y``'s last column, and with
    ``rank_weight`` > 0 that times :func:`rank_loss` of the logit over the poses ``pose_of`` (B,).
    """
    l1 = (pred[:, :N_REGRESSION] - y[:, :N_REGRESSION]).abs().mean(dim=0).sum()
    bce = nn.functional.binary_cross_entropy_with_logits(pred[:, N_REGRESSION], y[:, N_REGRESSION])
    total = l1 + _CONTACT_WEIGHT * bce
    if pred.shape[1] > N_OUTPUTS:
        total = total + success_weight * nn.functional.binary_cross_entropy_with_logits(
            pred[:, N_OUTPUTS], y[:, N_OUTPUTS]
        )
        if rank_weight > 0:
            if pose_of is None:
                raise DesignError("the ranking term needs each sample's pose (pose_of)")
            total = total + rank_weight * rank_loss(pred[:, N_OUTPUTS], y[:, N_OUTPUTS], pose_of)
    return total / (N_REGRESSION + 1)


def success_labels(data: GraspData, rows: np.ndarray) -> np.ndarray:
    """The success head's target of the samples ``rows``, shape (S,): ``success_p``, else the 0/1 success."""
    if data.success_p is not None:
        return np.asarray(data.success_p[rows], dtype=float)
    return data.success[rows].astype(float)


def training_set(data: GraspData, rows: np.ndarray, norm: Normalizer, config: ModelConfig) -> GraspDataset:
    """The samples ``rows`` as a :class:`GraspDataset` for a network of ``config``.

    With a success head the targets get an 11th column, :func:`success_labels`.
    """
    ds = GraspDataset(data, rows, norm, frame=config.frame_inputs)
    if config.success_head:
        label = torch.from_numpy(success_labels(data, ds.rows).astype(np.float32))
        ds.y = torch.cat([ds.y, label[:, None]], dim=1)
    return ds


@torch.no_grad()
def evaluate_loss(
    model: GraspNet,
    dataset: GraspDataset,
    batch_size: int = 4096,
    success_weight: float = SUCCESS_WEIGHT,
    rank_weight: float = 0.0,
) -> float:
    """:func:`grasp_loss` over a whole set in eval mode (sample-weighted mean over batches).

    The batches are pose-contiguous, so a pose is split between two batches at most at their border.
    """
    model.eval()
    total, n = 0.0, 0
    for b in dataset.batches(batch_size):
        loss = grasp_loss(model(b.clouds, b.pose_of, b.x), b.y, success_weight, rank_weight, b.pose_of)
        total += float(loss) * len(b.y)
        n += len(b.y)
    return total / max(n, 1)


def train(
    data: GraspData,
    parts: Split,
    config: TrainConfig | None = None,
    model_config: ModelConfig | None = None,
    *,
    on_epoch: Callable[[EpochLog], None] | None = None,
    init: tuple[GraspNet, Normalizer] | None = None,
) -> TrainResult:
    """Train a :class:`GraspNet` on ``parts.train``, early-stopping on ``parts.val``.

    Normalisation statistics come from the training rows only. Returns the best validation weights.

    ``init`` (a network and its normaliser, e.g. a loaded checkpoint's ``model`` and ``normalizer``)
    continues training from those weights instead of new ones (fine-tuning): the architecture is the
    network's (``model_config`` must be None or equal to it) and its normaliser is kept, not refitted,
    since the weights read their inputs and outputs in its units. The network passed in is not changed.
    """
    cfg = config or TrainConfig()
    if init is not None:
        if model_config is not None and model_config != init[0].config:
            raise DesignError(
                "fine-tuning keeps the initial network's architecture: give no other model config"
            )
        model_config = init[0].config
    mcfg = model_config or ModelConfig()
    rng = np.random.default_rng(cfg.seed)
    rows = parts.train
    norm = Normalizer.fit(data, rows) if init is None else init[1]
    train_set = training_set(data, rows, norm, mcfg)
    val_set = training_set(data, parts.val, norm, mcfg)
    t0 = time.perf_counter()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.seed)
        model = GraspNet(mcfg) if init is None else copy.deepcopy(init[0]).float()
        result = TrainResult(model, norm, train_rows=len(rows))
        _fit(model, train_set, val_set, cfg, rng, result, on_epoch)
    result.wall_s = time.perf_counter() - t0
    return result


def make_optimizer(model: GraspNet, o: OptimizerConfig) -> torch.optim.AdamW:
    """AdamW over the network, the PointNet (and its feature scale) at ``o.pointnet_lr_factor``."""
    point = list(model.pointnet.parameters()) + [model.pc_scale]
    return torch.optim.AdamW(
        [
            {"params": point, "lr": o.lr * o.pointnet_lr_factor},
            {"params": list(model.mlp.parameters()), "lr": o.lr},
        ],
        weight_decay=o.weight_decay,
        fused=True,  # one kernel per step on the CPU (15 ms of a 210-ms step here in the foreach form)
    )


def train_step(
    model: GraspNet,
    opt: torch.optim.Optimizer,
    b: TrainBatch,
    precision: str = "fp32",
    success_weight: float = SUCCESS_WEIGHT,
    rank_weight: float = 0.0,
) -> float:
    """One optimiser step on batch ``b`` (model in train mode); returns the batch's loss.

    ``bf16``: the forward (and so the backward) under CPU autocast in bfloat16; the loss is taken in
    float32 and the weights stay float32.
    """
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bf16"):
        pred = model(b.clouds, b.pose_of, b.x)
    loss = grasp_loss(pred.float(), b.y, success_weight, rank_weight, b.pose_of)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    return loss.item()


def _fit(model, train_set, val_set, cfg: TrainConfig, rng, result: TrainResult, on_epoch) -> None:
    o = cfg.optimizer
    opt = make_optimizer(model, o)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(
        opt, mode="min", factor=o.plateau_factor, patience=o.plateau_patience
    )
    best_state, since_best = None, 0
    result.stopped = "max_epochs"
    for epoch in range(cfg.epochs):
        t0 = time.perf_counter()
        model.train()
        total, n = 0.0, 0
        for idx in pose_batches(train_set.pose, cfg.batch_size, rng, cfg.pose_group):
            b = train_set.__getitems__(idx)
            loss = train_step(model, opt, b, cfg.precision, cfg.success_weight, cfg.rank_weight)
            total += loss * len(idx)
            n += len(idx)
        val = evaluate_loss(model, val_set, success_weight=cfg.success_weight, rank_weight=cfg.rank_weight)
        sched.step(val)
        best = val < result.best_val_loss
        if best:
            result.best_val_loss, result.best_epoch, since_best = val, epoch, 0
            best_state = copy.deepcopy(model.state_dict())
        else:
            since_best += 1
        log = EpochLog(epoch, total / n, val, opt.param_groups[1]["lr"], time.perf_counter() - t0, best)
        result.history.append(log)
        if on_epoch is not None:
            on_epoch(log)
        if since_best >= cfg.early_stop_patience:
            result.stopped = "early_stop"
            break
    if best_state is not None:
        model.load_state_dict(best_state)
    model.eval()
