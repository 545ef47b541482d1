"""Co-design (Algorithm 1): the top-B / patience bookkeeping, a planted optimum, determinism, bad input.

The network here is a planted function behind the real :class:`~mjcodesign.surrogate.Surrogate`: a
torch module with the network's ``encode`` / ``head`` whose contact logit is a quadratic in ln E, so
``Surrogate.loss_and_grad``, the paper's loss and the optimiser all run their real code. Nothing here
simulates except the bad-input cases' argument checks.
"""

import importlib
import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from numpy.testing import assert_array_equal
from torch import nn

from mjcodesign.codesign import (
    Mode,
    Objective,
    OptimizeConfig,
    Phase,
    PoseSelection,
    PoseSet,
    log_e_of,
    optimize,
    z_of,
)
from mjcodesign.errors import DesignError
from mjcodesign.surrogate import GraspBatch, GraspNet, ModelConfig, Normalizer, Poses, SuccessLoss, Surrogate

cli_main = importlib.import_module("mjcodesign.cli.main")

# The planted landscape: row loss = 1e-3 · 1 N + 1e3 · sigmoid(q), q = A · mean_i (ln E_i − c_{k,i})² + b_p
# (DesignLoss with force 1 N along up, no displacement): minimal at ln E = c_k, with pose p ranked by b_p.
_A = 4.0
_C = (14.6, 16.0)  # [ln Pa] each object's optimum (the pattern below is added per block)
_PATTERN = 0.3 * np.sin(np.arange(22))
_B = np.array([[-2.0, -3.0, -1.0, -2.5], [-1.5, -0.5, -3.0, -2.8]])  # b_p of each object's 4 poses
# After convergence Adam at lr 0.1 has stopped within this of the planted optimum [ln Pa]; the
# joint optimum of two symmetric objects (equal best b) is the midpoint of their optima.
_TOL_OPTIMUM = 0.02
_CONFIG = OptimizeConfig(top_b=2, patience=20, max_iterations=3000, weight_decay=0.0)


class _Config:
    frame_inputs = False
    feature_size = 1


class PlantedNet(nn.Module):
    """The network's interface (``encode``, ``head``, ``pc_scale``, ``config``) over a planted quadratic.

    Inputs per row (``Surrogate._outputs``, identity normalisation): ln E (22), the COM (3) — here the
    planted constants: x = object's optimum offset, y = b_p — and z(density).
    """

    config = _Config()

    def __init__(self):
        super().__init__()
        self.pc_scale = nn.Parameter(torch.ones(1, dtype=torch.float64))

    def encode(self, clouds):
        return torch.zeros(len(clouds), 1, dtype=torch.float64)

    def head(self, features, x):
        c = x[:, 22:23] + torch.from_numpy(_PATTERN)
        q = _A * ((x[:, :22] - c) ** 2).mean(dim=1) + x[:, 23]
        zero = torch.zeros(len(x), dtype=x.dtype)
        one = torch.ones(len(x), dtype=x.dtype)
        return torch.stack([zero] * 5 + [one] + [zero] * 3 + [q], dim=1)


class _HeadConfig(_Config):
    success_head = True


class PlantedHeadNet(PlantedNet):
    """:class:`PlantedNet` with a success head whose logit is −q: p = sigmoid(−q), largest at the planted optimum."""

    config = _HeadConfig()

    def head(self, features, x):
        out = super().head(features, x)
        return torch.cat([out, -out[:, 9:10]], dim=1)


def _surrogate(net=None) -> Surrogate:
    norm = Normalizer(np.zeros(22), np.ones(22), 0.0, 1.0, np.zeros(9), np.ones(9), np.zeros(7), np.ones(7))
    return Surrogate(net or PlantedNet(), norm, lift=0.03, lifted_fraction=0.5)


def _poses(objects=(0, 1)) -> PoseSet:
    """Two objects x 4 poses; a unit-sphere cloud so the normalised COM equals the COM given."""
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(64, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    rows = [(k, _C[k], b) for k in objects for b in _B[k]]
    n = len(rows)
    cloud = pts - pts.mean(axis=0)
    cloud /= np.linalg.norm(cloud, axis=1).max()
    palms = np.tile(np.eye(4), (n, 1, 1))  # up = +z: the planted 1 N force is along up
    return PoseSet(
        tuple(f"obj{k}" for k in objects),
        np.repeat(np.arange(len(objects)), len(_B[0])),
        np.tile(cloud.astype(np.float32), (n, 1, 1)),
        np.array([[c, b, 0.0] for _, c, b in rows]),
        palms,
        np.full((n, 2), 0.04),
        np.full(n, 1e-4),
    )


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_selection_follows_algorithm_1_step_by_step():
    s = PoseSelection(4, top_b=2, patience=3, tol=1e-3)
    # iteration 1: the two lowest are poses 2 and 3; a first set counts as a change (counter 0)
    assert_array_equal(s.select([4.0, 3.0, 2.0, 1.0]), [2, 3])
    assert (s.phase, s.unchanged) == (Phase.TOP_B, 0)
    # iteration 2: same set (order within it does not matter), counter 1
    assert_array_equal(s.select([4.0, 3.0, 1.0, 2.0]), [2, 3])
    assert s.unchanged == 1
    # iteration 3: the set changes to {0, 2}: the counter resets (the authors' global counter would not)
    assert_array_equal(s.select([1.0, 3.0, 2.0, 4.0]), [0, 2])
    assert s.unchanged == 0
    # iterations 4, 5: unchanged, counter 1, 2; still top-B
    for expected in (1, 2):
        assert_array_equal(s.select([1.0, 3.0, 0.5, 4.0]), [0, 2])
        assert (s.unchanged, s.phase) == (expected, Phase.TOP_B)
    # iteration 6: the 3rd unchanged iteration fixes the set; only its best (pose 2 now) counts
    assert_array_equal(s.select([1.0, 3.0, 0.5, 4.0]), [2])
    assert (s.phase, s.best_pose, s.best_loss) == (Phase.TOP_1, 2, 0.5)
    # top-1: pose 2 stays chosen even when another pose becomes lower
    assert_array_equal(s.select([0.1, 0.0, 0.4, 4.0]), [2])
    assert (s.best_loss, s.stalled) == (0.4, 0)  # fell by more than tol: new reference
    # a rise out of the tol band also resets (Adam's overshoot is not convergence)
    s.select([0.1, 0.0, 0.41, 4.0])
    assert (s.best_loss, s.stalled) == (0.41, 0)
    # changes within tol (relative) do not reset: after `patience` of them the object has converged
    for i, v in enumerate((0.40999, 0.4101, 0.40985)):
        s.select([0.1, 0.0, v, 4.0])
        assert s.stalled == i + 1
    assert s.converged and s.chosen([0.0, 0.0, 9.0, 0.0]) == 2


def test_selection_ties_and_bad_input():
    s = PoseSelection(3, top_b=2, patience=1)
    assert_array_equal(s.select([1.0, 1.0, 1.0]), [0, 1])  # ties: lower index first
    assert_array_equal(s.select([1.0, 1.0, 1.0]), [0])  # fixed at once (patience 1), best = first of equal
    with pytest.raises(Exception, match="finite"):
        PoseSelection(2, 1, 1).select([np.nan, 1.0])
    with pytest.raises(Exception, match=">= 1"):
        PoseSelection(2, 0, 1)


def test_z_and_log_e_are_inverse_and_printable():
    z = np.linspace(-30, 30, 61)
    assert np.all((log_e_of(z) >= 13.5) & (log_e_of(z) <= 17.0))
    x = np.linspace(13.6, 16.9, 12)
    np.testing.assert_allclose(log_e_of(z_of(x)), x, rtol=0, atol=1e-12)


def test_first_iteration_counts_the_b_lowest_poses():
    sur, poses = _surrogate(), _poses()
    res = optimize(sur, poses, 200.0, OptimizeConfig(top_b=2, max_iterations=2))  # designs: after one step
    batch = GraspBatch(
        Poses(poses.clouds, poses.com, poses.up, poses.volume), np.arange(8), np.full(8, 200.0)
    )
    x0 = np.full(22, 15.6)
    rows = sur.loss_and_grad(x0, batch).rows
    for k in range(2):
        r = rows[poses.rows(k)]
        assert res.curves[0, k] == pytest.approx(np.sort(r)[:2].sum(), rel=1e-12)
    # the first AdamW step moves every z against the gradient of the counted rows only
    top = np.concatenate([poses.rows(k)[np.argsort(rows[poses.rows(k)])[:2]] for k in range(2)])
    sub = GraspBatch(batch.poses, top, np.full(len(top), 200.0))
    g = sur.loss_and_grad(x0, sub).grad
    assert_array_equal(np.sign(z_of(res.designs[0]) - z_of(x0)), -np.sign(g))


def test_planted_optimum_individual_and_joint():
    sur, poses = _surrogate(), _poses()
    ind = optimize(sur, poses, 200.0, OptimizeConfig(**{**_CONFIG.as_dict(), "mode": Mode.INDIVIDUAL}))
    assert ind.stopped == "converged" and all(p == "converged" for p in ind.phases)
    for k in range(2):
        np.testing.assert_allclose(ind.designs[k], _C[k] + _PATTERN, atol=_TOL_OPTIMUM)
        assert ind.chosen[k] == poses.rows(k)[np.argmin(_B[k])]  # the pose of lowest b_p
    joint = optimize(sur, poses, 200.0, _CONFIG)
    assert joint.stopped == "converged" and joint.designs.shape == (1, 22)
    np.testing.assert_allclose(joint.designs[0], np.mean(_C) + _PATTERN, atol=_TOL_OPTIMUM)
    assert list(joint.chosen) == list(ind.chosen)
    assert joint.total_curve[-1] < joint.total_curve[0]


def test_success_objective_reaches_the_planted_optimum_and_counts_1_minus_p():
    sur, poses = _surrogate(PlantedHeadNet()), _poses()
    cfg = OptimizeConfig(**{**_CONFIG.as_dict(), "mode": Mode.INDIVIDUAL, "objective": Objective.SUCCESS})
    res = optimize(sur, poses, 200.0, cfg)
    assert res.config["objective"] == "success" and all(p == "converged" for p in res.phases)
    for k in range(2):
        np.testing.assert_allclose(res.designs[k], _C[k] + _PATTERN, atol=_TOL_OPTIMUM)
        assert res.chosen[k] == poses.rows(k)[np.argmin(_B[k])]
    # The counted loss at the end is 1 − p of each object's chosen pose, p = sigmoid(−q) at the optimum
    # (q = b_p there): the mean predicted success probability is 1 − mean(counted).
    best = np.array([_B[k].min() for k in range(2)])
    np.testing.assert_allclose(res.curves[-1], 1.0 - 1.0 / (1.0 + np.exp(best)), rtol=1e-3)


def test_success_gradient_through_the_optimiser_equals_finite_differences():
    """d Σ(1 − p) / d ln E of the counted rows, as the optimiser gets it, against central differences."""
    sur, poses = _surrogate(PlantedHeadNet()), _poses()
    batch = sur.prepare(GraspBatch(Poses.of(poses), np.arange(8), np.full(8, 200.0)))
    d = np.full(22, 15.2) + np.linspace(-0.5, 0.5, 22)
    g = sur.loss_and_grad(d, batch, SuccessLoss())
    step = 1e-6  # [ln E] central differences of a float64 function: O(h²) error, round-off ~1e-10 / h
    fd = np.array([(sur.loss_and_grad(d + e, batch, SuccessLoss()).loss
                    - sur.loss_and_grad(d - e, batch, SuccessLoss()).loss) / (2 * step)
                   for e in np.eye(22) * step])  # fmt: skip
    assert np.linalg.norm(fd) > 0
    np.testing.assert_allclose(g.grad, fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())
    # object 0's four poses; the planted constants (c, b) reach the net as the normalised COM it is given
    com = batch.features.com.numpy().astype(float)[:4]
    q = _A * ((d[None] - com[:, :1] - _PATTERN) ** 2).mean(axis=1) + com[:, 1]
    np.testing.assert_allclose(g.rows[:4], 1.0 - 1.0 / (1.0 + np.exp(q)), rtol=1e-12)


def test_success_objective_needs_a_success_head():
    with pytest.raises(DesignError, match="success head"):
        optimize(_surrogate(), _poses(), 200.0, OptimizeConfig(objective="success", max_iterations=2))
    with pytest.raises(DesignError, match="success head"):
        _surrogate().loss_and_grad(
            np.full(22, 15.0), GraspBatch(Poses.of(_poses()), [0], [200.0]), SuccessLoss()
        )
    with pytest.raises(DesignError, match="unknown objective"):
        OptimizeConfig(objective="fastest")


def test_deterministic():
    sur, poses = _surrogate(), _poses()
    cfg = OptimizeConfig(top_b=2, patience=5, max_iterations=200)
    a, b = optimize(sur, poses, 150.0, cfg), optimize(sur, poses, 150.0, cfg)
    assert_array_equal(a.designs, b.designs)
    assert_array_equal(a.curves, b.curves)
    assert_array_equal(a.chosen, b.chosen)


def _run(*args, tmp_path):
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", "optimize", *args],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )


@pytest.fixture(scope="module")
def candidates(tmp_path_factory):
    """A candidate file of one box (the top-down auto pose, twice)."""
    import trimesh

    from mjcodesign.objects import load_object
    from mjcodesign.poses import Candidates
    from mjcodesign.scenarios.grasp import auto_pose
    from mjcodesign.surrogate.grasp import pose_matrix

    d = tmp_path_factory.mktemp("codesign")
    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(d / "box.stl")
    gp = auto_pose(load_object(str(d / "box.stl"), 100.0))
    T = np.stack([pose_matrix(gp)] * 2)
    Candidates(T, np.array([gp.openings] * 2), np.ones(2), np.zeros(2), np.zeros(2)).save(
        d / "box.npz", str(d / "box.stl")
    )
    return d


@pytest.mark.parametrize(
    "case, expect",
    [
        ("per_object_0", "--poses-per-object"),
        ("schema", "another schema"),
        ("no_poses", "no poses for"),
        ("no_head", "success head"),
        ("objective", "--objective"),
    ],  # fmt: skip
)
def test_cli_bad_input_exits_2_with_one_line(case, expect, candidates, tmp_path):
    from mjcodesign.surrogate import GraspNet, ModelConfig, save_checkpoint

    ckpt = tmp_path / "ckpt"
    if case == "schema":
        ckpt.mkdir()
        record = {"format": "mjcodesign-surrogate", "version": 999, "outputs": []}
        (ckpt / "config.json").write_text(json.dumps(record))
    else:  # a valid checkpoint of a tiny network (untrained: these cases stop before it runs)
        norm = _surrogate().normalizer
        net = GraspNet(ModelConfig(point_widths=(4,), hidden=4, depth=1, penultimate=4, dropout=0.0,
                                   success_head=case != "no_head"))  # fmt: skip
        save_checkpoint(ckpt, Surrogate(net, norm, lift=0.03, lifted_fraction=0.5))
    args = ["--ckpt", str(ckpt), "--objects", "box", "--poses", str(candidates / "box.npz"),
            "--out", str(tmp_path / "out"), "--json"]  # fmt: skip
    if case == "per_object_0":
        args += ["--poses-per-object", "0"]
    if case == "no_poses":
        args[3] = "box,025_mug"
    if case in ("no_head", "objective"):
        args += ["--objective", "success" if case == "no_head" else "fastest"]
    r = _run(*args, tmp_path=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1 and expect in r.stderr, r.stderr
    assert r.stdout == "" and not (tmp_path / "out").exists()


def test_simulated_loss_is_the_paper_loss_and_unusable_rollouts_fail():
    from mjcodesign.codesign.search import simulated_losses
    from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome

    up = np.array([[0.0, 0.0, 1.0]] * 3)
    held = Outcome(True, (0, 0, 0, 0.1, 0.0, 2.0), (0.0, 0.0, 0.004), False, "ok")
    dropped = Outcome(False, (0, 0, 0, 0, 0, -0.5), (0.0, 0.0, -0.02), True, "x", (Failure.GROUND_CONTACT,))
    diverged = failed_outcome(Failure.DIVERGED, "x")  # zeros: would look perfect if scored as is
    rows = simulated_losses([held, dropped, diverged], up)
    # 1e-3 Σ|f, Δq| + 1e3 (relu(−up·f) + relu(−up·Δq) + c_g)
    np.testing.assert_allclose(rows[0], 1e-3 * (2.1 + 0.004), rtol=1e-12)
    np.testing.assert_allclose(rows[1], 1e-3 * (0.5 + 0.02) + 1e3 * (0.5 + 0.02 + 1.0), rtol=1e-12)
    assert rows[2] == 1e3


def test_ground_truth_runs_under_the_dataset_s_scenario(tmp_path):
    """A position-mode dataset's checkpoint re-simulates in position mode, with the dataset's phases.

    A tiny dataset (one box, two poses, four designs each) with the servo drive; a checkpoint trained
    on it with the real training path; the verification reads the scenario back from the checkpoint.
    """
    import dataclasses

    import trimesh

    from mjcodesign.codesign import load_pose_set
    from mjcodesign.codesign.verify import verify
    from mjcodesign.data import DatagenConfig, generate, parse_density_spec
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.jobs import GraspJob, load_grasp_object, run_jobs
    from mjcodesign.scenarios.drive import TendonPosition
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.sim import MujocoBackend
    from mjcodesign.surrogate import (
        ModelConfig,
        TrainConfig,
        dataset_config,
        load_surrogate,
        train_and_report,
    )

    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(tmp_path / "box.stl")
    drive = TendonPosition(ticks=900.0)
    scenario = GraspScenario(impulse=0.0, tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.02, lift=0.025)
    cfg = DatagenConfig(
        objects=(str(tmp_path / "box.stl"),),
        poses_per_object=2,
        designs_per_pose=4,
        density=parse_density_spec("200"),
        tendon=drive,
        scenario=scenario,
    )
    cache = tmp_path / "cache"
    assert generate(cfg, tmp_path / "ds", workers=1, cache_dir=cache)["complete"]
    tiny = ModelConfig(point_widths=(4,), hidden=4, depth=1, penultimate=4, dropout=0.0)
    train_and_report(
        tmp_path / "ds",
        tmp_path / "ckpt",
        split_mode="random",
        config=TrainConfig(epochs=1, batch_size=4),
        model_config=tiny,
        efficiency=0.0,
        smoothness_poses=0,
    )
    sur = load_surrogate(tmp_path / "ckpt")
    assert dataset_config(sur) == cfg
    poses = load_pose_set(tmp_path / "ds")
    truth = verify(sur, {"optimised": (poses, None, None)}, 200.0, cache_dir=cache)
    sim = truth["simulation"]
    assert sim["source"] == "checkpoint" and sim["model"] == "chain" and sim["tendon"] == "position:900"
    assert sim["scenario"] == json.loads(json.dumps(dataclasses.asdict(cfg.scenario)))
    assert sim["scenario"]["lift"] == 0.025 and sim["scenario"]["tendon"]["ticks"] == 900.0
    # Each row is the rollout of that design at that pose under the dataset's scenario.
    obj = load_grasp_object(cfg.objects[0], 200.0, cache_dir=cache)
    for row in truth["rows"]:
        job = GraspJob(
            obj=obj,
            pose=poses.gripper_pose(row["pose_row"]),
            design=Stiffness.preset(row["design"]),
            scenario=cfg.scenario,
            density=200.0,
        )
        (out,) = run_jobs([job], MujocoBackend(nthread=1))
        assert (row["simulated_success"], row["reason"]) == (bool(out.success), out.reason)


@pytest.fixture(scope="module")
def own_mesh(tmp_path_factory):
    """A generated mesh and its candidate file, which names the object by its stem (as `poses --out` does)."""
    import trimesh

    from mjcodesign.objects import load_object
    from mjcodesign.poses import Candidates
    from mjcodesign.scenarios.grasp import auto_pose
    from mjcodesign.surrogate.grasp import pose_matrix

    d = tmp_path_factory.mktemp("own_mesh")
    (d / "meshes").mkdir()
    mesh = d / "meshes" / "mine.stl"
    trimesh.creation.box(extents=(0.045, 0.04, 0.055)).export(mesh)
    gp = auto_pose(load_object(str(mesh), 300.0))
    Candidates(
        np.stack([pose_matrix(gp)] * 2), np.array([gp.openings] * 2), np.ones(2), np.zeros(2), np.zeros(2)
    ).save(d / "mine.npz", "mine")
    return d


def test_objects_take_mesh_files_and_folders(own_mesh):
    from mjcodesign.cli.optimize import _objects
    from mjcodesign.data import resolve_objects
    from mjcodesign.errors import MeshError

    mesh = own_mesh / "meshes" / "mine.stl"
    for text in (str(mesh), str(own_mesh / "meshes")):
        names, meshes = _objects(text, resolve_objects)
        assert names == ("mine",) and meshes == {"mine": str(mesh.resolve())}
    assert _objects("box", resolve_objects) == (("box",), {})
    with pytest.raises(MeshError, match="not found"):
        _objects(str(own_mesh / "nothing.stl"), resolve_objects)


def test_optimize_re_simulates_a_generated_mesh(own_mesh, tiny_checkpoint, tmp_path):
    """The candidates name the object "mine" (no such YCB object): the re-simulation loads --objects' mesh."""
    args = ["--ckpt", str(tiny_checkpoint), "--objects", str(own_mesh / "meshes" / "mine.stl"),
            "--poses", str(own_mesh / "mine.npz"), "--density", "300", "--max-iterations", "20",
            "--out", str(tmp_path / "out"), "--json"]  # fmt: skip
    r = _run(*args, tmp_path=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    truth = json.loads(r.stdout.splitlines()[-1])["ground_truth"]
    assert {(row["object"], row["design"]) for row in truth["rows"]} == {
        ("mine", "optimised"),
        ("mine", "soft"),
        ("mine", "semi-rigid"),
    }
    assert all(row["reason"] for row in truth["rows"]) and truth["rollouts"] == 3
    # Without the mesh the candidates' name alone cannot be loaded: one line says to give the file.
    args[3] = "mine"
    r = _run(*args[:-3], "--out", str(tmp_path / "out2"), "--json", tmp_path=tmp_path)
    assert (
        r.returncode == 2 and "give its mesh file in --objects" in r.stderr and r.stderr.count("\n") == 1
    ), r.stderr
    assert not (tmp_path / "out2").exists()


def test_verify_under_the_success_loss_predicts_with_the_success_head(tiny_checkpoint):
    # The success objective's ground truth predicts with the head (p > 0.5), not the outputs' score;
    # with a head every row carries the head's probability at its pose and design, whatever the loss.
    from mjcodesign.codesign import load_pose_set
    from mjcodesign.codesign.verify import verify
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.surrogate import load_surrogate

    tiny = load_surrogate(tiny_checkpoint)  # trained without a head: its net is swapped for one with
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        net = GraspNet(
            ModelConfig(
                point_widths=(8, 16), hidden=16, depth=2, penultimate=8, dropout=0.0, success_head=True
            )
        )
    sur = Surrogate(
        net, tiny.normalizer, lift=tiny.lift, lifted_fraction=tiny.lifted_fraction, meta=tiny.meta
    )
    assert sur.has_success_head
    work = tiny_checkpoint.parent
    poses = load_pose_set(work / "ds")
    sets = {"presets": (poses, None, None)}
    by_score = verify(sur, sets, 250.0, cache_dir=work / "cache")
    by_head = verify(sur, sets, 250.0, cache_dir=work / "cache", loss=SuccessLoss())
    assert (by_score["predicted_by"], by_head["predicted_by"]) == ("score", "success head")
    for truth in (by_score, by_head):
        for row in truth["rows"]:
            design = Stiffness.preset(row["design"]).log_e.reshape(1, -1)
            batch = GraspBatch(Poses.of(poses), np.array([row["pose_row"]]), np.array([250.0]), design)
            pred = sur.predict(batch)
            assert row["predicted_success_p"] == pytest.approx(float(pred.success_p[0]), rel=1e-5)
            by = row["predicted_success_p"] > 0.5 if truth is by_head else bool(pred.success[0])
            assert row["predicted_success"] == by
    for rate in by_head["rates"]:
        sel = [r for r in by_head["rows"] if r["design"] == rate["design"]]
        assert rate["predicted_success_p"] == pytest.approx(np.mean([r["predicted_success_p"] for r in sel]))
