"""The pairwise ranking term of the success head and the design-only ranking baseline.

Synthetic tensors and tables only: the term's algebra and gradient, the config's guards, and the
baseline's fit; docs/concepts/surrogate.md has what they do on a dataset.
"""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from mjcodesign.errors import DesignError
from mjcodesign.surrogate import TrainConfig
from mjcodesign.surrogate.ranking import group_spearman, linear_design_effect
from mjcodesign.surrogate.train import N_OUTPUTS, grasp_loss, rank_loss

_TOL = 1e-6  # float64 sums of a few terms


def _by_hand(logit, label, pose):
    num = den = 0.0
    for i in range(len(logit)):
        for j in range(len(logit)):
            if pose[i] == pose[j] and label[i] > label[j]:
                w = label[i] - label[j]
                num += w * np.log1p(np.exp(logit[j] - logit[i]))
                den += w
    return num / den


def test_rank_loss_is_the_gap_weighted_ranknet_mean_within_poses():
    rng = np.random.default_rng(0)
    logit = rng.normal(size=9)
    label = np.array([0.0, 0.5, 1.0, 0.25, 0.25, 0.75, 0.9, 0.1, 0.9])
    pose = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2])
    got = rank_loss(*(torch.tensor(a) for a in (logit, label, pose)))
    assert float(got) == pytest.approx(_by_hand(logit, label, pose), rel=_TOL)
    # pairs across poses do not count: a shift of one pose's logits changes nothing
    shifted = logit + np.repeat([5.0, -3.0, 0.5], 3)
    assert float(rank_loss(*(torch.tensor(a) for a in (shifted, label, pose)))) == pytest.approx(
        float(got), rel=_TOL
    )


def test_rank_loss_falls_as_the_order_within_a_pose_gets_right():
    label = torch.tensor([0.0, 0.5, 1.0, 0.0, 0.5, 1.0], dtype=torch.float64)
    pose = torch.tensor([0, 0, 0, 1, 1, 1])
    right = torch.tensor([-1.0, 0.0, 1.0, -1.0, 0.0, 1.0], dtype=torch.float64)
    assert (
        float(rank_loss(-right, label, pose))
        > float(rank_loss(0 * right, label, pose))
        > float(rank_loss(right, label, pose))
    )
    logit = torch.zeros(6, dtype=torch.float64, requires_grad=True)
    rank_loss(logit, label, pose).backward()
    g = logit.grad.numpy()  # descent raises the better designs' logits
    assert g[2] < 0 < g[0] and g[5] < 0 < g[3]


def test_rank_loss_without_pairs_is_zero_and_keeps_the_graph():
    logit = torch.zeros(4, requires_grad=True)
    out = rank_loss(logit, torch.tensor([0.5, 0.5, 1.0, 0.0]), torch.tensor([0, 0, 1, 2]))
    assert float(out.detach()) == 0.0
    out.backward()  # a batch without a ranked pose still steps
    assert torch.equal(logit.grad, torch.zeros(4))


def test_grasp_loss_adds_the_weighted_rank_term_to_the_head_only():
    rng = np.random.default_rng(1)
    pred = torch.tensor(rng.normal(size=(6, N_OUTPUTS + 1)))
    y = torch.tensor(rng.uniform(0, 1, size=(6, N_OUTPUTS + 1)))
    pose = torch.tensor([0, 0, 0, 1, 1, 1])
    base = grasp_loss(pred, y, 1.0)
    term = rank_loss(pred[:, N_OUTPUTS], y[:, N_OUTPUTS], pose)
    torch.testing.assert_close(grasp_loss(pred, y, 1.0, 2.0, pose), base + 2.0 * term / 10, rtol=_TOL, atol=0)
    with pytest.raises(DesignError, match="pose"):
        grasp_loss(pred, y, 1.0, 2.0)
    # a network without a head has nothing to rank: the term is left out
    torch.testing.assert_close(grasp_loss(pred[:, :N_OUTPUTS], y[:, :N_OUTPUTS], 1.0, 2.0, pose),
                               grasp_loss(pred[:, :N_OUTPUTS], y[:, :N_OUTPUTS]))  # fmt: skip


@pytest.mark.parametrize(
    ("fields", "match"),
    [({"rank_weight": -1.0}, "rank_weight"), ({"rank_weight": float("nan")}, "rank_weight"),
     ({"rank_weight": 1.0, "success_weight": 0.0}, "success head"),
     ({"rank_weight": 1.0, "pose_group": 1}, "pose_group")],
)  # fmt: skip
def test_train_config_refuses_a_rank_weight_it_cannot_use(fields, match):
    with pytest.raises(DesignError, match=match):
        TrainConfig(**fields)
    assert TrainConfig(rank_weight=0.5).as_dict()["rank_weight"] == 0.5


def test_linear_design_effect_recovers_a_shared_preference_whatever_the_pose_levels():
    rng = np.random.default_rng(2)
    n_pose, designs = 120, 8
    pose = np.repeat(np.arange(n_pose), designs)
    log_e = rng.uniform(13.5, 17.0, size=(len(pose), 22))
    preference = np.zeros(22)
    preference[[1, 3, 5]] = [0.2, -0.1, 0.05]  # three flexures of finger A matter
    level = rng.uniform(0.2, 0.8, n_pose)[pose]  # every pose at its own level
    p = level + (log_e - 15.25) @ preference
    data = SimpleNamespace(pose=pose, log_e=log_e, success_p=p, success=p >= 0.5)
    train, test = np.flatnonzero(pose < 110), np.flatnonzero(pose >= 110)
    score = linear_design_effect(data, train, test)
    groups = [np.flatnonzero(pose[test] == k) for k in range(110, 120)]
    rho = group_spearman(score, p[test], groups)
    assert np.all(rho > 0.95)
    # fitted to the opposite preference, it ranks the first one backwards
    data.success_p = level - (log_e - 15.25) @ preference
    assert np.all(group_spearman(linear_design_effect(data, train, test), p[test], groups) < -0.95)


def test_the_split_seed_holds_the_split_while_the_seed_changes_the_network():
    assert TrainConfig(seed=3).data_seed == 3
    assert TrainConfig(seed=3, split_seed=0).data_seed == 0 and TrainConfig(seed=3, split_seed=0).seed == 3
    assert TrainConfig(seed=1, split_seed=0).as_dict()["split_seed"] == 0
    for bad in (-1, 1.5, True):
        with pytest.raises(DesignError, match="split_seed"):
            TrainConfig(split_seed=bad)
