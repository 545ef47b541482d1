"""The success-probability head: old checkpoints, the loss, its gradient, and the design-ranking measures.

Networks here are tiny and synthetic (no dataset, no simulation): the head's plumbing, not its accuracy
(docs/concepts/surrogate.md has the measured run).
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from numpy.testing import assert_array_equal

from mjcodesign.surrogate import (
    GraspBatch,
    GraspNet,
    ModelConfig,
    Normalizer,
    Poses,
    SuccessLoss,
    Surrogate,
    TrainConfig,
    load_surrogate,
    save_checkpoint,
)
from mjcodesign.surrogate.ranking import group_spearman, half_labels, ranking_fidelity
from mjcodesign.surrogate.train import grasp_loss, success_labels

_TINY = {"point_widths": (8, 16), "hidden": 16, "depth": 1, "penultimate": 8, "dropout": 0.0}
_FD_STEP = 1e-6  # [ln E] central differences of a float64 network
_TOL_FD = 1e-5  # relative: O(h²) error and round-off ~1e-10 / h


def _surrogate(head: bool, seed: int = 0) -> Surrogate:
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = GraspNet(ModelConfig(**_TINY, success_head=head))
    norm = Normalizer(
        np.full(22, 15.0), np.ones(22), 500.0, 100.0, np.zeros(9), np.ones(9), np.zeros(7), np.ones(7)
    )
    meta = {"dataset": {"density": {"low_kg_m3": 100.0, "high_kg_m3": 900.0}}}
    return Surrogate(net.eval(), norm, lift=0.03, lifted_fraction=0.5, meta=meta)


def _batch(n: int = 12, with_design: bool = True) -> GraspBatch:
    rng = np.random.default_rng(1)
    clouds = rng.normal(size=(3, 64, 3)).astype(np.float32) * 0.03
    poses = Poses(clouds, clouds.mean(axis=1), np.tile([0.0, 0.0, 1.0], (3, 1)), np.full(3, 1e-4))
    log_e = rng.uniform(13.6, 16.9, size=(n, 22)) if with_design else None
    return GraspBatch(poses, np.arange(n) % 3, rng.uniform(200.0, 800.0, n), log_e)


def test_a_head_less_record_loads_and_predicts_as_before(tmp_path):
    sur = _surrogate(head=False)
    before = sur.predict(_batch())
    save_checkpoint(tmp_path / "old", sur)
    record = json.loads((tmp_path / "old" / "config.json").read_text())
    del record["model"]["success_head"]  # a record written before the head existed
    (tmp_path / "old" / "config.json").write_text(json.dumps(record))
    back = load_surrogate(tmp_path / "old")
    assert not back.has_success_head and back.config.outputs == 10
    after = back.predict(_batch())
    for field in ("body_force", "displacement", "ground_contact", "success_score"):
        assert_array_equal(getattr(before, field), getattr(after, field), err_msg=field)
    assert after.success_p is None


def test_a_head_round_trips_and_leaves_the_ten_outputs_alone(tmp_path):
    sur = _surrogate(head=True)
    pred = sur.predict(_batch())
    assert pred.success_p.shape == (12,) and np.all((pred.success_p > 0) & (pred.success_p < 1))
    save_checkpoint(tmp_path / "new", sur)
    back = load_surrogate(tmp_path / "new")
    assert back.has_success_head and back.config == sur.config
    assert_array_equal(back.predict(_batch()).success_p, pred.success_p)
    # the head is one more row of the last layer: the same weights without it give the same 10 outputs
    plain = _surrogate(head=False)
    state = {k: v[:10] if k.startswith(f"mlp.{len(sur.model.mlp) - 1}.") else v
             for k, v in sur.model.state_dict().items()}  # fmt: skip
    plain.model.load_state_dict(state)
    assert_array_equal(plain.predict(_batch()).body_force, pred.body_force)


def test_grasp_loss_adds_the_weighted_cross_entropy_of_the_head():
    torch.manual_seed(0)
    pred, y = torch.randn(32, 11), torch.rand(32, 11)
    y[:, 9] = (y[:, 9] > 0.5).float()
    bce = torch.nn.functional.binary_cross_entropy_with_logits(pred[:, 10], y[:, 10])
    ten = grasp_loss(pred[:, :10], y[:, :10])
    torch.testing.assert_close(grasp_loss(pred, y, 2.5), ten + 2.5 * bce / 10, rtol=1e-6, atol=0)
    torch.testing.assert_close(grasp_loss(pred, y, 0.0), ten, rtol=1e-6, atol=0)
    with pytest.raises(ValueError, match="success_weight"):
        TrainConfig(success_weight=-1.0)


def test_success_gradient_equals_finite_differences():
    sur = _surrogate(head=True)
    sur.model.double()
    batch = sur.prepare(_batch(with_design=False))
    d = np.full(22, 15.2) + np.linspace(-0.5, 0.5, 22)
    g = sur.loss_and_grad(d, batch, SuccessLoss())
    fd = np.array([(sur.loss_and_grad(d + e, batch, SuccessLoss()).loss
                    - sur.loss_and_grad(d - e, batch, SuccessLoss()).loss) / (2 * _FD_STEP)
                   for e in np.eye(22) * _FD_STEP])  # fmt: skip
    assert np.linalg.norm(g.grad) > 0
    np.testing.assert_allclose(g.grad, fd, rtol=_TOL_FD, atol=_TOL_FD * np.abs(fd).max())
    p = sur.predict(GraspBatch(batch.poses, batch.pose, batch.density, np.tile(d, (len(batch), 1)))).success_p
    np.testing.assert_allclose(g.rows, 1.0 - p, rtol=1e-12)


def test_group_spearman_ranks_and_marks_what_has_no_ranking():
    label = np.array([0.0, 0.25, 0.5, 1.0, 0.3, 0.3, 0.3, 0.3, 0.0, 0.5, 1.0, 0.75])
    pred = np.array([0.1, 0.2, 0.3, 0.4, 0.1, 0.9, 0.5, 0.2, 0.5, 0.5, 0.5, 0.5])
    groups = [np.arange(4), np.arange(4, 8), np.arange(8, 12), np.arange(4)[::-1]]
    r = group_spearman(pred, label, groups)
    assert r[0] == pytest.approx(1.0) and r[3] == pytest.approx(1.0)
    assert np.isnan(r[1])  # the measured p is constant: no ranking
    assert r[2] == 0.0  # the prediction is constant: it orders nothing
    assert group_spearman(-pred, label, groups[:1])[0] == pytest.approx(-1.0)


def test_ranking_fidelity_counts_ranked_constant_and_small_poses():
    # three poses of 8 designs (one with a constant label) and one of 3 designs
    pose = np.repeat([0, 1, 2, 3], [8, 8, 8, 3])
    p = np.concatenate([np.linspace(0, 1, 8), np.full(8, 1.0), np.linspace(1, 0, 8), [0.0, 0.5, 1.0]])
    data = SimpleNamespace(pose=pose, objects=np.array(["a", "a", "b", "c"]), success_p=p, success=p >= 0.5)
    pred = np.concatenate([np.linspace(0, 1, 8), np.linspace(0, 1, 8), np.linspace(0, 1, 8), [0.0, 0.0, 0.0]])
    r = ranking_fidelity({"m": pred}, data, np.arange(len(pose)))
    assert (r["poses"], r["constant"], r["too_few_designs"]) == (2, 1, 1)
    assert r["models"]["m"]["median"] == pytest.approx(0.0)  # +1 and -1
    assert [q["pose_row"] for q in r["per_pose"]] == [0, 2] and r["models"]["m"]["positive"] == 1


def test_half_labels_split_each_cell_by_draw_parity():
    cell = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1])
    draw = np.array([0, 1, 2, 3, 0, 1, 2, 3, 4])
    success = np.array([1, 0, 1, 0, 1, 1, 0, 1, 1], dtype=bool)
    usable = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0], dtype=bool)
    even, odd = half_labels(draw, success, usable, cell, 3)
    assert_array_equal(even, [1.0, 0.5, np.nan])
    assert_array_equal(odd, [0.0, 1.0, np.nan])


def test_the_head_learns_the_soft_label_and_falls_back_to_the_0_1_success():
    p = np.array([0.0, 0.25, 0.75, 1.0])
    perturbed = SimpleNamespace(success_p=p, success=p >= 0.5)
    single = SimpleNamespace(success_p=None, success=p >= 0.5)
    rows = np.array([3, 1, 2])
    assert_array_equal(success_labels(perturbed, rows), [1.0, 0.25, 0.75])
    assert_array_equal(success_labels(single, rows), [1.0, 0.0, 1.0])
