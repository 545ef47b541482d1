"""Robust co-design (``optimize --robust``): one surrogate per model variant, combined row by row.

The networks are planted functions behind the real :class:`~mjcodesign.surrogate.Surrogate`: the
contact logit is a quadratic in ln E whose optimum and offset differ between the "nominal" and the
"variant" network, so the combined loss has a known optimum under each rule. The command-line tests
run the real checkpoint path and re-simulate under each variant's recorded scenario.
"""

import dataclasses
import importlib
import json

import numpy as np
import pytest
import torch
from torch import nn

from mjcodesign.codesign import Mode, OptimizeConfig, PoseSet, optimize
from mjcodesign.codesign.robust import VariantSurrogate
from mjcodesign.errors import DesignError
from mjcodesign.surrogate import DesignLoss, GraspBatch, Normalizer, Poses, SuccessLoss, Surrogate

cli_main = importlib.import_module("mjcodesign.cli.main")

# Planted row loss: 1e-3 · 1 N + 1e3 · sigmoid(q), q = A · mean_i (ln E_i − c_i)² + b + w · z_p, with
# c = the object's optimum (+ SHIFT for the variant), b the pose's offset (+ OFFSET for the variant) and
# z_p the pose's third COM coordinate, which only the variant reads (it re-ranks the poses).
_A = 4.0
_C = 15.0
_SHIFT = 0.8  # [ln Pa] the variant's optimum lies this far above the nominal's
_OFFSET = 6.0  # the variant's logit is this much higher: the worse model wherever the optimiser goes
_PATTERN = 0.3 * np.sin(np.arange(22))
# Every logit stays below zero, where sigmoid(q) tracks q and the optimiser's stop (a relative band on
# the loss) is as sharp as on the quadratic itself.
_B = np.array([-6.0, -5.6, -5.2, -4.8])  # the nominal ranks pose 0 best
_Z = np.array([0.0, 0.0, -2.0, 0.0])  # the variant, with weight 1, ranks pose 2 best (b + z: -7.2)
# Adam at lr 0.1 stops within this of a planted optimum after convergence [ln Pa] (test_codesign's)
_TOL_OPTIMUM = 0.02
_CONFIG = OptimizeConfig(top_b=2, patience=20, max_iterations=3000, weight_decay=0.0)


class _Config:
    frame_inputs = False
    feature_size = 1
    success_head = True


class _Planted(nn.Module):
    """The network's interface over the planted quadratic; ``shift``, ``offset`` and ``w`` make a variant."""

    config = _Config()

    def __init__(self, shift=0.0, offset=0.0, w=0.0):
        super().__init__()
        self.pc_scale = nn.Parameter(torch.ones(1, dtype=torch.float64))
        self.shift, self.offset, self.w = shift, offset, w

    def encode(self, clouds):
        return torch.zeros(len(clouds), 1, dtype=torch.float64)

    def head(self, features, x):
        c = x[:, 22:23] + self.shift + torch.from_numpy(_PATTERN)
        q = _A * ((x[:, :22] - c) ** 2).mean(dim=1) + x[:, 23] + self.offset + self.w * x[:, 24]
        zero = torch.zeros(len(x), dtype=x.dtype)
        one = torch.ones(len(x), dtype=x.dtype)
        return torch.stack([zero] * 5 + [one] + [zero] * 3 + [q, -q], dim=1)


def _surrogate(net) -> Surrogate:
    norm = Normalizer(np.zeros(22), np.ones(22), 0.0, 1.0, np.zeros(9), np.ones(9), np.zeros(7), np.ones(7))
    return Surrogate(net, norm, lift=0.03, lifted_fraction=0.5)


def _robust(rule, offset=_OFFSET, w=1.0):
    nominal = _surrogate(_Planted())
    variant = _surrogate(_Planted(shift=_SHIFT, offset=offset, w=w))
    return VariantSurrogate([("nominal", nominal), ("variant", variant)], rule), nominal, variant


def _poses() -> PoseSet:
    """One object x 4 poses; a unit-sphere cloud so the normalised COM equals the COM given (c, b, z)."""
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(64, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    cloud = pts - pts.mean(axis=0)
    cloud /= np.linalg.norm(cloud, axis=1).max()
    n = len(_B)
    return PoseSet(
        ("obj",),
        np.zeros(n, dtype=int),
        np.tile(cloud.astype(np.float32), (n, 1, 1)),
        np.array([[_C, b, z] for b, z in zip(_B, _Z, strict=True)]),
        np.tile(np.eye(4), (n, 1, 1)),
        np.full((n, 2), 0.04),
        np.full(n, 1e-4),
    )


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_mean_rule_reaches_the_midpoint_and_worst_the_dominant_variant():
    # Two variants that differ only in their optimum: their losses mirror each other about the
    # midpoint, where the mean is minimal. With the offset, the variant's logit is the larger at every
    # pose from the start to both optima (OFFSET + min z > A · SHIFT² + the start's spread), so the worst
    # case is the variant's alone and its optimum is the variant's.
    assert _OFFSET + _Z.min() > _A * _SHIFT**2 + 1.0
    poses = _poses()
    mean = optimize(_robust("mean", offset=0.0, w=0.0)[0], poses, 200.0, _CONFIG)
    worst = optimize(_robust("worst")[0], poses, 200.0, _CONFIG)
    assert mean.stopped == "converged" and worst.stopped == "converged"
    np.testing.assert_allclose(mean.designs[0], _C + _SHIFT / 2 + _PATTERN, atol=_TOL_OPTIMUM)
    np.testing.assert_allclose(worst.designs[0], _C + _SHIFT + _PATTERN, atol=_TOL_OPTIMUM)
    nominal_only = optimize(_robust("worst")[1], poses, 200.0, _CONFIG)
    np.testing.assert_allclose(nominal_only.designs[0], _C + _PATTERN, atol=_TOL_OPTIMUM)


def test_pose_choice_ranks_the_combined_loss():
    # The nominal alone picks pose 0 (lowest b); under the worst case pose 2 holds best (the variant's
    # b + z is lowest there and the variant dominates).
    poses = _poses()
    assert optimize(_robust("worst")[1], poses, 200.0, _CONFIG).chosen.tolist() == [0]
    assert optimize(_robust("worst")[0], poses, 200.0, _CONFIG).chosen.tolist() == [2]


@pytest.mark.parametrize("rule", ["worst", "mean"])
@pytest.mark.parametrize("loss", [DesignLoss(), SuccessLoss()], ids=["lopt", "success"])
def test_combined_rows_and_gradient(rule, loss):
    """Rows are the max (mean) of the members' rows; the gradient equals central differences."""
    robust, nominal, variant = _robust(rule)
    poses = _poses()
    batch = GraspBatch(Poses.of(poses), np.arange(4), np.full(4, 200.0))
    d = np.full(22, 15.3) + np.linspace(-0.4, 0.4, 22)
    g = robust.loss_and_grad(d, robust.prepare(batch), loss)
    rows = np.stack([nominal.loss_and_grad(d, batch, loss).rows, variant.loss_and_grad(d, batch, loss).rows])
    np.testing.assert_allclose(g.rows, rows.max(axis=0) if rule == "worst" else rows.mean(axis=0), rtol=1e-12)
    step = 1e-6  # [ln E] central differences of a float64 function: O(h²) error, round-off ~1e-10 / h
    fd = np.array([(robust.loss_and_grad(d + e, batch, loss).loss - robust.loss_and_grad(d - e, batch, loss).loss)
                   / (2 * step) for e in np.eye(22) * step])  # fmt: skip
    assert np.linalg.norm(fd) > 0
    np.testing.assert_allclose(g.grad, fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())
    pred = robust.predict(dataclasses.replace(batch, log_e=np.tile(d, (4, 1))))
    heads = np.stack([s.predict(dataclasses.replace(batch, log_e=np.tile(d, (4, 1)))).success_p
                      for s in (nominal, variant)])  # fmt: skip
    np.testing.assert_allclose(pred.success_p, heads.min(axis=0) if rule == "worst" else heads.mean(axis=0))


def test_variant_surrogate_refuses_bad_input():
    nominal = _surrogate(_Planted())
    with pytest.raises(DesignError, match="at least one variant"):
        VariantSurrogate([("nominal", nominal)])
    with pytest.raises(DesignError, match="names must differ"):
        VariantSurrogate([("a", nominal), ("a", nominal)])
    with pytest.raises(DesignError, match="worst or mean"):
        VariantSurrogate([("a", nominal), ("b", nominal)], "median")
    headless = _surrogate(_Planted())
    headless.model.config = type("C", (), {"frame_inputs": False, "feature_size": 1, "success_head": False})()
    with pytest.raises(DesignError, match="success head"):
        VariantSurrogate([("a", nominal), ("b", headless)]).loss_and_grad(
            np.full(22, 15.0), GraspBatch(Poses.of(_poses()), [0], [200.0]), SuccessLoss()
        )
    res = optimize(
        _robust("worst")[0], _poses(), 200.0, OptimizeConfig(max_iterations=3, mode=Mode.INDIVIDUAL)
    )
    assert res.designs.shape == (1, 22)


@pytest.mark.parametrize(
    ("extra", "expect"),
    [
        (["--robust", "worst"], "--robust needs at least one --variant"),
        (["--variant", "VARIANT"], "--variant needs --robust"),
        (["--robust", "mean", "--variant", "MISSING"], "no such checkpoint folder"),
        (["--robust", "sideways", "--variant", "VARIANT"], "invalid choice"),
    ],
)
def test_cli_bad_robust_flags_exit_2_with_one_line(extra, expect, tmp_path, capsys):
    (tmp_path / "v").mkdir()
    extra = [{"VARIANT": str(tmp_path / "v"), "MISSING": str(tmp_path / "none")}.get(a, a) for a in extra]
    args = ["optimize", "--objects", "x", "--poses", str(tmp_path), "--out", str(tmp_path / "out"), *extra]
    try:
        rc = cli_main.main(args)
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and expect in err and err.strip().count("\n") == 0, err
    assert not (tmp_path / "out").exists()


def test_optimize_robust_re_simulates_under_each_variant(tiny_checkpoint, tmp_path, capsys):
    """The nominal and a friction-0.6 variant checkpoint: the ground truth runs once under each model."""
    import trimesh

    from mjcodesign.data import DatagenConfig, parse_density_spec
    from mjcodesign.objects import load_object
    from mjcodesign.poses import Candidates
    from mjcodesign.scenarios.grasp import GraspScenario, auto_pose
    from mjcodesign.surrogate import load_surrogate, save_checkpoint
    from mjcodesign.surrogate.grasp import pose_matrix

    mesh = tmp_path / "mine.stl"
    trimesh.creation.box(extents=(0.045, 0.04, 0.055)).export(mesh)
    gp = auto_pose(load_object(str(mesh), 300.0))
    Candidates(
        np.stack([pose_matrix(gp)] * 2), np.array([gp.openings] * 2), np.ones(2), np.zeros(2), np.zeros(2)
    ).save(tmp_path / "mine.npz", "mine")
    scenario = GraspScenario(impulse=0.0, tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.02)
    cfg = DatagenConfig(
        objects=(str(mesh),),
        poses_per_object=2,
        designs_per_pose=2,
        density=parse_density_spec("300"),
        scenario=scenario,
        tension=scenario.tension,
    )
    sur = load_surrogate(tiny_checkpoint)
    for name, c in {
        "nominal": cfg,
        "mu06": dataclasses.replace(cfg, scenario=dataclasses.replace(scenario, friction=0.6)),
    }.items():
        sur.meta["dataset"] = {**sur.meta.get("dataset", {}), "config": c.as_dict()}
        save_checkpoint(tmp_path / name, sur)
    args = ["optimize", "--ckpt", str(tmp_path / "nominal"), "--objects", str(mesh), "--poses",
            str(tmp_path / "mine.npz"), "--max-iterations", "20", "--robust", "worst", "--variant",
            str(tmp_path / "mu06"), "--out", str(tmp_path / "out"), "--json"]  # fmt: skip
    assert cli_main.main(args) == 0
    record = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert record["robust"] == {"rule": "worst", "variants": {"mu06": str(tmp_path / "mu06")}}
    nominal, variant = record["ground_truth"], record["ground_truth_variants"]["mu06"]
    assert nominal["simulation"]["scenario"]["friction"] is None
    assert variant["simulation"]["scenario"]["friction"] == 0.6
    assert variant["simulation"]["routing"] == "guided" and variant["rollouts"] == nominal["rollouts"] == 3
    assert [r["pose_row"] for r in variant["rows"]] == [r["pose_row"] for r in nominal["rows"]]
    saved = json.loads((tmp_path / "out" / "result.json").read_text())
    assert saved["ground_truth_variants"]["mu06"]["rates"] == variant["rates"]
