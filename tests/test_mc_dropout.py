"""Monte Carlo dropout on the success head, and its uncertainty penalty in the success objective.

A tiny real :class:`~mjcodesign.surrogate.GraspNet` (float64, dropout 0.3) for the loss's algebra,
determinism and gradient; a planted network for what the penalty does to the optimum; the command
line for the refusals. docs/concepts/codesign.md has what it does on a dataset.
"""

import importlib
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from torch import nn

from mjcodesign.codesign import Objective, OptimizeConfig, PoseSet, optimize
from mjcodesign.errors import DesignError
from mjcodesign.surrogate import GraspBatch, GraspNet, ModelConfig, Normalizer, Poses, SuccessLoss, Surrogate
from mjcodesign.surrogate.inference import dropout_draws
from mjcodesign.surrogate.model import Dropout

cli_main = importlib.import_module("mjcodesign.cli.main")
pytestmark = pytest.mark.usefixtures("one_torch_thread")

_TINY = {"point_widths": (8, 16), "hidden": 32, "depth": 1, "penultimate": 16, "dropout": 0.3}
_FD_STEP = 1e-6  # [ln E] central differences of a float64 network with fixed dropout masks
_TOL_FD = 1e-5  # relative: O(h²) error and round-off ~1e-10 / h


def _norm() -> Normalizer:
    return Normalizer(
        np.full(22, 15.0), np.ones(22), 500.0, 100.0, np.zeros(9), np.ones(9), np.zeros(7), np.ones(7)
    )


def _tiny() -> Surrogate:
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(3)
        net = GraspNet(ModelConfig(**_TINY, success_head=True)).double().eval()
    return Surrogate(net, _norm(), lift=0.03, lifted_fraction=0.5)


def _batch(sur: Surrogate):
    rng = np.random.default_rng(1)
    clouds = rng.normal(size=(3, 64, 3)).astype(np.float32) * 0.03
    poses = Poses(clouds, clouds.mean(axis=1), np.tile([0.0, 0.0, 1.0], (3, 1)), np.full(3, 1e-4))
    return sur.prepare(GraspBatch(poses, np.arange(9) % 3, rng.uniform(400.0, 600.0, 9)))


_D = np.full(22, 15.2) + np.linspace(-0.5, 0.5, 22)


@pytest.mark.parametrize(
    ("fields", "match"),
    [({"samples": 1}, "samples"), ({"samples": -2}, "samples"), ({"samples": 2.5}, "samples"),
     ({"uncertainty": 1.0}, "needs Monte Carlo"), ({"samples": 4, "uncertainty": -1.0}, "finite"),
     ({"samples": 4, "uncertainty": float("inf")}, "finite")],
)  # fmt: skip
def test_success_loss_refuses_what_it_cannot_do(fields, match):
    with pytest.raises(DesignError, match=match):
        SuccessLoss(**fields)


def test_draws_are_the_same_at_every_call_and_leave_the_network_and_rng_as_they_were():
    sur, b = _tiny(), None
    b = _batch(sur)
    loss = SuccessLoss(samples=6, uncertainty=1.0, seed=5)
    state = torch.random.get_rng_state()
    first = sur.loss_and_grad(_D, b, loss)
    again = sur.loss_and_grad(_D, b, loss)
    assert torch.equal(state, torch.random.get_rng_state())
    assert not any(m.training for m in sur.model.modules())  # dropout back off, BatchNorm never on
    np.testing.assert_array_equal(first.rows, again.rows)
    np.testing.assert_array_equal(first.grad, again.grad)
    other_seed = sur.loss_and_grad(_D, b, SuccessLoss(samples=6, uncertainty=1.0, seed=6))
    deterministic = sur.loss_and_grad(_D, b, SuccessLoss())
    assert not np.allclose(first.rows, other_seed.rows) and not np.allclose(first.rows, deterministic.rows)


def test_rows_are_one_minus_the_draws_mean_plus_lambda_times_their_spread():
    sur = _tiny()
    b = _batch(sur)
    x = torch.tensor(_D, dtype=torch.float64)
    with torch.no_grad(), dropout_draws(sur.model, 5):
        p = torch.stack([sur._outputs(b, x.expand(len(b), 22))[4] for _ in range(6)]).numpy()
    assert np.ptp(p, axis=0).min() > 0  # the draws differ for every row
    for lam in (0.0, 2.0):
        rows = sur.loss_and_grad(_D, b, SuccessLoss(samples=6, uncertainty=lam, seed=5)).rows
        np.testing.assert_allclose(rows, 1.0 - p.mean(axis=0) + lam * p.std(axis=0), rtol=1e-12)


def test_penalised_gradient_equals_central_differences():
    sur = _tiny()
    b = _batch(sur)
    loss = SuccessLoss(samples=4, uncertainty=1.5, seed=0)
    g = sur.loss_and_grad(_D, b, loss)
    fd = np.array([(sur.loss_and_grad(_D + e, b, loss).loss - sur.loss_and_grad(_D - e, b, loss).loss)
                   / (2 * _FD_STEP) for e in np.eye(22) * _FD_STEP])  # fmt: skip
    assert np.linalg.norm(g.grad) > 0
    np.testing.assert_allclose(g.grad, fd, rtol=_TOL_FD, atol=_TOL_FD * np.abs(fd).max())


# Planted: logit = -A·mean_i (ln E_i - C)² - A0·(ln E_0 - C)² + (m - 1)·S·(ln E_0 - C - DELTA), m an
# inverted-dropout draw (mean 1), so the noise term has mean 0 and vanishes at ln E_0 = C + DELTA: the
# mean's optimum is near C (the logit near 0, where the sigmoid is nearly linear and the noise hardly
# moves the mean), the spread's zero at C + DELTA.
_A, _A0, _C, _S, _DELTA = 4.0, 1.0, 15.0, 1.0, 0.8


class _Planted(nn.Module):
    config = SimpleNamespace(frame_inputs=False, feature_size=1, success_head=True)

    def __init__(self):
        super().__init__()
        self.pc_scale = nn.Parameter(torch.ones(1, dtype=torch.float64))
        self.drop = Dropout(0.5)

    def encode(self, clouds):
        return torch.zeros(len(clouds), 1, dtype=torch.float64)

    def head(self, features, x):
        m = self.drop(torch.ones(1, dtype=x.dtype)).expand(len(x))  # one draw for every row
        q = -_A * ((x[:, :22] - _C) ** 2).mean(dim=1) - _A0 * (x[:, 0] - _C) ** 2
        q = q + (m - 1.0) * _S * (x[:, 0] - _C - _DELTA)
        zero = torch.zeros(len(x), dtype=x.dtype)
        return torch.stack([zero] * 5 + [torch.ones_like(q)] + [zero] * 3 + [-10.0 + zero, q], dim=1)


def _planted_poses() -> PoseSet:
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(64, 3))
    cloud = pts / np.linalg.norm(pts, axis=1).max()
    return PoseSet(("obj",), np.zeros(2, dtype=int), np.tile(cloud.astype(np.float32), (2, 1, 1)),
                   np.zeros((2, 3)), np.tile(np.eye(4), (2, 1, 1)), np.full((2, 2), 0.04), np.full(2, 1e-4))  # fmt: skip


def test_the_penalty_moves_the_optimum_towards_what_the_network_is_sure_of():
    norm = Normalizer(np.zeros(22), np.ones(22), 0.0, 1.0, np.zeros(9), np.ones(9), np.zeros(7), np.ones(7))
    sur = Surrogate(_Planted().eval(), norm, lift=0.03, lifted_fraction=0.5)
    cfg = {
        "objective": Objective.SUCCESS,
        "top_b": 1,
        "patience": 20,
        "max_iterations": 400,
        "weight_decay": 0.0,
    }
    runs = {lam: optimize(sur, _planted_poses(), 200.0, OptimizeConfig(**cfg, mc_samples=16, uncertainty=lam))
            for lam in (0.0, 3.0)}  # fmt: skip
    assert all(r.total_curve[-1] > 0 for r in runs.values())  # the counted loss is the draws' (not unset)
    x0 = {lam: r.designs[0][0] for lam, r in runs.items()}
    assert abs(x0[0.0] - _C) < 0.3 * _DELTA  # the mean alone stays near its optimum
    assert x0[3.0] - x0[0.0] > 0.3 * _DELTA  # the penalty pulls block 0 towards where the spread vanishes


def test_optimize_config_and_the_command_line_refuse_a_penalty_without_the_success_objective(
    capsys, tmp_path
):
    with pytest.raises(DesignError, match="objective success"):
        OptimizeConfig(mc_samples=4)
    with pytest.raises(DesignError, match="samples"):
        OptimizeConfig(objective=Objective.SUCCESS, uncertainty=1.0)
    cfg = OptimizeConfig(objective=Objective.SUCCESS, mc_samples=4, uncertainty=0.5)
    assert (cfg.as_dict()["mc_samples"], cfg.as_dict()["uncertainty"]) == (4, 0.5)
    assert cfg.success_loss() == SuccessLoss(samples=4, uncertainty=0.5)
    for extra in (["--mc-samples", "4"], ["--objective", "success", "--uncertainty", "1"],
                  ["--objective", "success", "--mc-samples", "1"]):  # fmt: skip
        out = tmp_path / "o"
        code = cli_main.main(
            ["optimize", "--objects", "013_apple", "--poses", str(tmp_path / "p"), "--out", str(out), *extra]
        )
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and err[0].startswith("error:"), (extra, err)
        assert "dropout" in err[0] or "uncertainty" in err[0], err  # refused for the flags, not the poses
        assert not out.exists()


@pytest.mark.parametrize("counted", [False, True])
def test_algorithm_1_counts_the_draws_rows_it_chooses(counted):
    # The optimiser's loss detaches the rows its pose selection leaves out; the draws' rows go through it
    from mjcodesign.codesign.optimize import _counted_loss

    sur = _tiny()
    b = _batch(sur)
    base = SuccessLoss(samples=4, uncertainty=0.5, seed=2)
    seen = []

    def choose(values):
        seen.append(values)
        return np.arange(len(values)) < (4 if counted else 0)

    full = sur.loss_and_grad(_D, b, base)
    got = sur.loss_and_grad(_D, b, _counted_loss(base, choose))
    assert len(seen) == 1
    np.testing.assert_allclose(seen[0], full.rows, rtol=1e-12)  # the selection ranks the draws' rows
    np.testing.assert_allclose(got.rows, full.rows, rtol=1e-12)
    if not counted:
        assert np.all(got.grad == 0.0)
    else:  # the gradient of the first four rows alone
        step = _FD_STEP
        fd = np.array([(sur.loss_and_grad(_D + e, b, base).rows[:4].sum() - sur.loss_and_grad(_D - e, b, base).rows[:4].sum())
                       / (2 * step) for e in np.eye(22) * step])  # fmt: skip
        np.testing.assert_allclose(got.grad, fd, rtol=_TOL_FD, atol=_TOL_FD * np.abs(fd).max())
