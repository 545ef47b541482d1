"""The neural surrogate: a PointNet + MLP trained on generated grasps (the paper's "neural physics").

Importing this package imports torch (``pip install 'mjcodesign[torch]'``); nothing else in mjcodesign
does. Import from here (``from mjcodesign.surrogate import Surrogate``): each name has this one path.

- :mod:`~mjcodesign.surrogate.data`: the dataset as arrays, splits (and :func:`first_poses`, a split cut
  to the first poses of each object), normalisation, a torch ``Dataset``;
- :mod:`~mjcodesign.surrogate.model`: :class:`GraspNet` and its :class:`ModelConfig` (the paper's);
- :mod:`~mjcodesign.surrogate.train`: :func:`train` and :class:`TrainConfig`;
- :mod:`~mjcodesign.surrogate.inference`: :class:`Surrogate` (``predict``, ``loss_and_grad``);
- :mod:`~mjcodesign.surrogate.checkpoint`: :func:`save_checkpoint`, :func:`load_surrogate`;
- :mod:`~mjcodesign.surrogate.metrics`, :mod:`~mjcodesign.surrogate.smoothness`: held-out metrics,
  baselines, lines in design space;
- :mod:`~mjcodesign.surrogate.report`: :func:`train_and_report` and :func:`train_folds` (``mjcodesign train``);
- :mod:`~mjcodesign.surrogate.folds`: :class:`FoldSurrogates`, the networks of ``train --folds``;
- :mod:`~mjcodesign.surrogate.grasp`: :func:`predict_grasp` (``mjcodesign predict``);
- :mod:`~mjcodesign.surrogate.shipped`: :func:`shipped_checkpoint`, the weights that ship (if any), and
  :func:`checkpoint_or_shipped`, every command's ``--ckpt`` default.
"""

from mjcodesign.surrogate.checkpoint import (
    CHECKPOINT_FORMAT,
    CHECKPOINT_VERSION,
    dataset_config,
    load_surrogate,
    save_checkpoint,
)
from mjcodesign.surrogate.data import (
    OUTPUT_NAMES,
    SPLITS,
    GraspData,
    GraspDataset,
    Normalizer,
    Split,
    first_poses,
    fold_splits,
    load_grasp_data,
    normalize_clouds,
    split,
)
from mjcodesign.surrogate.folds import FoldSurrogates, load_any, load_folds
from mjcodesign.surrogate.grasp import predict_grasp
from mjcodesign.surrogate.inference import (
    DesignGradient,
    DesignLoss,
    GraspBatch,
    Poses,
    Prediction,
    SuccessLoss,
    Surrogate,
    success_score,
)
from mjcodesign.surrogate.model import GraspNet, ModelConfig
from mjcodesign.surrogate.report import (
    TensorBoardLog,
    checkpoint_smoothness,
    dataset_warnings,
    train_and_report,
    train_folds,
)
from mjcodesign.surrogate.shipped import checkpoint_or_shipped, shipped_checkpoint
from mjcodesign.surrogate.train import EpochLog, OptimizerConfig, TrainConfig, TrainResult, train

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "OUTPUT_NAMES",
    "SPLITS",
    "DesignGradient",
    "DesignLoss",
    "EpochLog",
    "FoldSurrogates",
    "GraspBatch",
    "GraspData",
    "GraspDataset",
    "GraspNet",
    "ModelConfig",
    "Normalizer",
    "OptimizerConfig",
    "Poses",
    "Prediction",
    "Split",
    "SuccessLoss",
    "Surrogate",
    "TensorBoardLog",
    "TrainConfig",
    "TrainResult",
    "checkpoint_or_shipped",
    "checkpoint_smoothness",
    "dataset_config",
    "dataset_warnings",
    "first_poses",
    "fold_splits",
    "load_any",
    "load_folds",
    "load_grasp_data",
    "load_surrogate",
    "normalize_clouds",
    "predict_grasp",
    "save_checkpoint",
    "shipped_checkpoint",
    "split",
    "success_score",
    "train",
    "train_and_report",
    "train_folds",
]
