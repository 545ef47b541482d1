"""Benchmark of the surrogate's speed on this machine: the paper's network, randomly initialised.

Cases (each the fastest of ``repeats`` timed calls after a warm-up; pairs that are compared run
alternately, so that a busy machine slows both alike):

* ``mlp_infer_b{B}``: the bare MLP (the ``nn.Sequential``) on random inputs, eval mode, samples/s;
* ``surrogate_infer_b{B}``: :meth:`Surrogate.predict` on a prepared batch (PointNet features cached
  per pose; inputs normalised, outputs de-normalised, the success score), samples/s; target ≥ 90 %
  of the bare MLP in the same run;
* ``mlp_train_step_b512``: one AdamW step of the MLP alone at batch 512;
* ``train_step_b512``: one full training step (:func:`~mjcodesign.surrogate.train.train_step`, the
  training's loss and optimiser) at batch 512 grouped by pose (``512 // 35 + 1`` unique clouds through
  the PointNet, as :func:`~mjcodesign.surrogate.data.pose_batches` makes them); ``_bf16`` the same
  step under ``--precision bf16``, timed alternately with it;
* ``pointnet_fwd_bwd_512``: the PointNet forward and backward over 512 clouds of 1024 points;
* ``loss_and_grad_46x10``: :meth:`Surrogate.loss_and_grad` over 46 objects × 10 poses against
  ``mlp_fwd_bwd_460``, the bare MLP's forward and backward on a batch of that size; target ≤ 1.5×.

Every case records the wall time and the process's CPU time (all threads). On a machine shared with
other work the wall time of one call swings with the load, so the ratios are given by both clocks
(``*_cpu``: the cost of the work itself) beside the load average. ``epoch_80k_estimate_s`` extrapolates
the steps to an 80k-sample epoch: the MLP alone, the pose-grouped step (PointNet once per unique pose
of a batch), and the PointNet recomputed for every sample.
"""

from __future__ import annotations

import os
import time

import numpy as np
import torch

from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E
from mjcodesign.errors import DesignError
from mjcodesign.surrogate import (
    GraspBatch,
    GraspNet,
    ModelConfig,
    Normalizer,
    OptimizerConfig,
    Poses,
    Surrogate,
)
from mjcodesign.surrogate.data import TrainBatch
from mjcodesign.surrogate.train import make_optimizer, train_step

__all__ = ["bench_surrogate"]

_POINTS = 1024
_OBJECTS, _POSES = 46, 10  # the paper's co-design batch: 46 objects x 10 candidate poses
_DESIGNS_PER_POSE = 35  # a paper-scale dataset: ~80k samples over ~2,300 poses
_CLOUDS = 512
_TRAIN_BATCH = 512
_INFER_BATCHES = (460, 4096)
_TARGET_INFER = 0.9  # cached inference / bare MLP throughput
_TARGET_GRAD = 1.5  # loss-and-grad time / bare MLP fwd+bwd


def _once(fn) -> np.ndarray:
    """(wall, CPU) seconds of one call; CPU time is this process's, all threads."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    return np.array([time.perf_counter() - w0, time.process_time() - c0])


def _fastest(fn, repeats: int) -> np.ndarray:
    """Fastest (wall, CPU) seconds of ``repeats`` calls after a warm-up, each minimum on its own."""
    fn()
    return np.min([_once(fn) for _ in range(repeats)], axis=0)


def _paired(a, b, repeats: int) -> tuple[np.ndarray, np.ndarray]:
    """Fastest (wall, CPU) seconds of ``a`` and ``b``, measured alternately."""
    a(), b()
    runs = [(_once(a), _once(b)) for _ in range(repeats)]
    return np.min([r[0] for r in runs], axis=0), np.min([r[1] for r in runs], axis=0)


def _surrogate(config: ModelConfig, rng: np.random.Generator) -> tuple[Surrogate, Poses]:
    model = GraspNet(config).eval()
    norm = Normalizer(
        log_e_mean=np.full(N_LOG_E, 0.5 * (LOG_E_MIN + LOG_E_MAX)), log_e_std=np.ones(N_LOG_E),
        density_mean=250.0, density_std=87.0,
        out_mean=np.zeros(9), out_std=np.ones(9), frame_mean=np.zeros(7), frame_std=np.ones(7),
    )  # fmt: skip
    n = _OBJECTS * _POSES
    clouds = rng.normal(size=(n, _POINTS, 3)) * 0.03
    up = rng.normal(size=(n, 3))
    poses = Poses(
        clouds.astype(np.float32),
        rng.normal(size=(n, 3)) * 0.01,
        up / np.linalg.norm(up, axis=1, keepdims=True),
        np.full(n, 1e-4),
    )
    return Surrogate(model, norm, lift=0.03, lifted_fraction=0.5), poses


def bench_surrogate(*, repeats: int = 5, seed: int = 0, model: ModelConfig | None = None) -> dict:
    """Time the cases of the module docstring; a JSON-ready dict with the targets' ratios.

    ``model``: the network (default: the paper's, which the targets are about). Runs on torch's
    current thread count (``torch.set_num_threads``, which the CLI's ``--threads`` sets).
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise DesignError(f"repeats must be an integer >= 1, got {repeats!r}")
    rng = np.random.default_rng(seed)
    config = model or ModelConfig()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        sur, poses = _surrogate(config, rng)
    mlp = sur.model.mlp
    width = config.feature_size + config.design_inputs
    cases: dict[str, dict] = {}

    def row(t: np.ndarray, samples: int) -> dict:
        wall, cpu = float(t[0]), float(t[1])
        return {"seconds": wall, "ms": 1e3 * wall, "samples_per_s": samples / wall, "cpu_ms": 1e3 * cpu,
                "samples_per_cpu_s": samples / max(cpu, 1e-9), "samples": samples}  # fmt: skip

    for b in _INFER_BATCHES:
        x = torch.randn(b, width)
        pose = rng.integers(0, len(poses), b)
        batch = sur.prepare(
            GraspBatch(poses, pose, rng.uniform(100, 400, b), rng.uniform(LOG_E_MIN, LOG_E_MAX, (b, N_LOG_E)))
        )

        def bare(x=x):
            with torch.inference_mode():
                mlp(x)

        t_mlp, t_sur = _paired(bare, lambda batch=batch: sur.predict(batch), repeats)
        cases[f"mlp_infer_b{b}"] = row(t_mlp, b)
        cases[f"surrogate_infer_b{b}"] = row(t_sur, b)
    # Training steps (train mode, AdamW), fresh copies so the benchmark's model is untouched.
    net = GraspNet(config).train()
    opt = torch.optim.AdamW(net.parameters(), lr=1e-3, weight_decay=1e-3)
    xb, yb = torch.randn(_TRAIN_BATCH, width), torch.randn(_TRAIN_BATCH, 10)

    def mlp_step():
        opt.zero_grad(set_to_none=True)
        (net.mlp(xb) - yb).abs().mean().backward()
        opt.step()

    unique = _TRAIN_BATCH // _DESIGNS_PER_POSE + 1
    tb = TrainBatch(
        torch.randn(unique, 3, _POINTS),
        torch.from_numpy(np.sort(rng.integers(0, unique, _TRAIN_BATCH))),
        torch.randn(_TRAIN_BATCH, config.design_inputs),
        torch.cat([yb[:, :9], (yb[:, 9:] > 0).float()], dim=1),
    )
    train_opt = make_optimizer(net, OptimizerConfig())  # what ``train`` steps with

    def full_step(precision="fp32"):
        train_step(net, train_opt, tb, precision)

    clouds = torch.randn(_CLOUDS, 3, _POINTS)

    def pointnet():
        net.zero_grad(set_to_none=True)
        net.encode(clouds).sum().backward()

    cases["mlp_train_step_b512"] = row(_fastest(mlp_step, repeats), _TRAIN_BATCH)
    t32, t16 = _paired(full_step, lambda: full_step("bf16"), repeats)
    cases["train_step_b512"] = row(t32, _TRAIN_BATCH)
    cases["train_step_b512_bf16"] = row(t16, _TRAIN_BATCH)
    cases["pointnet_fwd_bwd_512"] = row(_fastest(pointnet, max(1, repeats // 2)), _CLOUDS)
    # Design gradient over 46 x 10 (object, pose) rows against the bare MLP's forward and backward.
    n = _OBJECTS * _POSES
    gbatch = sur.prepare(GraspBatch(poses, np.arange(n), rng.uniform(100, 400, n)))
    design = rng.uniform(LOG_E_MIN, LOG_E_MAX, N_LOG_E)
    x460 = torch.randn(n, width, requires_grad=True)

    def bare_fwd_bwd():
        mlp.zero_grad(set_to_none=True)
        mlp(x460).sum().backward()

    t_bare, t_grad = _paired(bare_fwd_bwd, lambda: sur.loss_and_grad(design, gbatch), repeats)
    cases[f"mlp_fwd_bwd_{n}"] = row(t_bare, n)
    cases[f"loss_and_grad_{_OBJECTS}x{_POSES}"] = row(t_grad, n)
    infer = {
        b: cases[f"surrogate_infer_b{b}"]["samples_per_s"] / cases[f"mlp_infer_b{b}"]["samples_per_s"]
        for b in _INFER_BATCHES
    }
    infer_cpu = {
        b: cases[f"mlp_infer_b{b}"]["cpu_ms"] / cases[f"surrogate_infer_b{b}"]["cpu_ms"]
        for b in _INFER_BATCHES
    }
    grad, grad_cpu = float(t_grad[0] / t_bare[0]), float(t_grad[1] / t_bare[1])
    step_80k = cases["mlp_train_step_b512"]["seconds"] * 80_000 / _TRAIN_BATCH
    return {
        "model": config.as_dict(),
        "threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "repeats": repeats,
        "load_average": list(os.getloadavg()),
        "cases": {
            k: {key: v.get(key) for key in ("ms", "samples_per_s", "cpu_ms", "samples_per_cpu_s", "samples")}
            for k, v in cases.items()
        },
        "cached_inference_vs_mlp": {str(b): r for b, r in infer.items()},
        "cached_inference_vs_mlp_cpu": {str(b): r for b, r in infer_cpu.items()},
        "cached_inference_target": _TARGET_INFER,
        "cached_inference_met": all(r >= _TARGET_INFER for r in infer.values()),
        "cached_inference_met_cpu": all(r >= _TARGET_INFER for r in infer_cpu.values()),
        "loss_and_grad_vs_mlp_fwd_bwd": grad,
        "loss_and_grad_vs_mlp_fwd_bwd_cpu": grad_cpu,
        "loss_and_grad_target": _TARGET_GRAD,
        "loss_and_grad_met": grad <= _TARGET_GRAD,
        "loss_and_grad_met_cpu": grad_cpu <= _TARGET_GRAD,
        "train_step_unique_clouds": unique,
        "epoch_80k_estimate_s": {
            "mlp_only": step_80k,
            "pose_grouped": cases["train_step_b512"]["seconds"] * 80_000 / _TRAIN_BATCH,
            "pose_grouped_bf16": cases["train_step_b512_bf16"]["seconds"] * 80_000 / _TRAIN_BATCH,
            "pointnet_per_sample": step_80k + cases["pointnet_fwd_bwd_512"]["seconds"] * 80_000 / _CLOUDS,
        },
    }
