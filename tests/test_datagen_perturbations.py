"""``datagen --perturbations K`` and ``K:M``: cells of perturbed rollouts and their probabilistic labels.

A tiny dataset (a 50 mm box and an egad-like shape, 2 poses x 2 designs, a shortened grasp) under a
perturbation model wider than the evaluation's (palm ±10 mm and ±8°, mass ±50 %, friction ±80 %, tendon
±60 %), so that some cells vary and the adaptive extension has work to do. The rows are recomputed by
hand from the per-rollout table; the draws are the (object, pose)'s, shared by its designs, the same
whatever the worker count, and the first K of a K:M dataset are those of a K dataset.
"""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from numpy.testing import assert_array_equal

from mjcodesign.cli.main import main
from mjcodesign.data import (
    DatagenConfig,
    PoseStreams,
    generate,
    open_dataset,
    parse_density_spec,
    parse_perturbations,
    summarize,
)
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.scenarios.grasp import GraspScenario
from mjcodesign.scenarios.perturb import Perturbation, PerturbationModel

_SCENARIO = GraspScenario(impulse=0.0, tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.02)
_WIDE = PerturbationModel(palm_position_m=0.01, palm_rotation_deg=8.0, mass=0.5, friction=0.8, tendon=0.6)
_K, _M = 2, 6
_CELL_KEYS = ["object_index", "pose_index", "design_index"]


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("perturbed")


def _config(work: Path, **kw) -> DatagenConfig:
    import trimesh

    box = work / "box50.stl"
    if not box.is_file():
        trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(box)
    return DatagenConfig(
        objects=(str(box), "egad-like:1"),
        poses_per_object=2,
        designs_per_pose=2,
        density=parse_density_spec("uniform:300,500"),
        scenario=_SCENARIO,
        tension=_SCENARIO.tension,
        perturbation=_WIDE,
        **kw,
    )


def _make(work: Path, name: str, config: DatagenConfig, **kw):
    res = generate(config, work / name, cache_dir=work / "cache", **kw)
    assert res["complete"]
    # the summary's rates: rows per second and perturbed rollouts per second, over the same wall time
    comp = res["computed"]
    assert res["samples_per_s"] == pytest.approx(comp["samples"] / res["wall_s"], rel=1e-12)
    assert res["rollouts_per_s"] == pytest.approx(comp["rollouts"] / res["wall_s"], rel=1e-12)
    assert comp["rollouts"] >= config.perturbations * (comp["samples"] + comp["rejected"])
    return open_dataset(work / name)


@pytest.fixture(scope="module")
def adaptive(work):
    return _make(work, "adaptive", _config(work, perturbations=_K, perturbations_max=_M))


def _tables(ds) -> dict:
    return {
        t: ds.table(t).drop_columns(["wall_time_s"]) if t != "poses" else ds.table(t)
        for t in ("poses", "samples", "rejected", "rollouts")
    }


def _cells(rollouts) -> dict[tuple, dict]:
    d = rollouts.to_pydict()
    out: dict[tuple, dict] = {}
    for i in range(rollouts.num_rows):
        key = tuple(d[k][i] for k in _CELL_KEYS)
        cell = out.setdefault(key, {k: [] for k in d})
        for k in d:
            cell[k].append(d[k][i])
    return out


def test_rows_are_the_rollouts_summed_up(adaptive):
    """Every cell row, recomputed from its rollouts: p = successes / usable, means, spreads (ddof 0)."""
    cells = _cells(adaptive.rollouts())
    rows = adaptive.samples().to_pylist() + adaptive.rejected().to_pylist()
    assert len(rows) == len(cells) == adaptive.poses().num_rows * 2
    for r in rows:
        c = cells[tuple(r[k] for k in _CELL_KEYS)]
        assert c["draw"] == list(range(len(c["draw"])))
        usable = ~np.array(c["sample_error"])
        ok = np.array(c["success"])[usable]
        force = np.array(c["body_force"])[usable]
        disp = np.array(c["displacement"])[usable]
        assert r["rollouts"] == usable.sum() and r["unusable"] == (~usable).sum()
        assert r["success_p"] == pytest.approx(ok.mean() if usable.any() else 0.0, abs=1e-15)
        assert r["success"] == (usable.any() and ok.mean() >= 0.5)
        assert (r["failure"] == "none") == r["success"]
        if usable.any():
            np.testing.assert_allclose(r["body_force"], force.mean(axis=0), rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(r["body_force_std"], force.std(axis=0), rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(r["displacement_std"], disp.std(axis=0), rtol=1e-12, atol=1e-15)
            lift = np.array(c["lift_height"])[usable]
            assert r["lift_height"] == pytest.approx(lift.mean(), rel=1e-12, abs=1e-15)
            ground = np.array(c["ground_contact"])[usable].mean()
            assert r["ground_contact_p"] == pytest.approx(ground) and r["ground_contact"] == (ground >= 0.5)
    # The wide model makes some cells vary: the labels carry probabilities, not only 0 and 1.
    p = adaptive.samples().column("success_p").to_numpy()
    assert np.any((p > 0) & (p < 1)), p


def test_only_disagreeing_cells_are_extended_and_draws_are_shared(adaptive, work):
    cells = _cells(adaptive.rollouts())
    extended = 0
    for c in cells.values():
        first = [s for s, e in zip(c["success"][:_K], c["sample_error"][:_K], strict=True) if not e]
        disagree = len(set(first)) == 2
        assert len(c["draw"]) == (_M if disagree else _K)
        extended += disagree
    assert extended >= 1
    # Common random numbers: every design of a pose meets the same draws.
    by_pose: dict[tuple, dict[int, list]] = {}
    for (o, p, _), c in cells.items():
        for j, pert in zip(c["draw"], c["perturbation"], strict=True):
            by_pose.setdefault((o, p), {}).setdefault(j, []).append(pert)
    for draws in by_pose.values():
        for same in draws.values():
            assert all(x == same[0] for x in same)
    # The first K draws of K:M are the draws of a K dataset, with the same outcomes.
    fixed = _make(work, "fixed", _config(work, perturbations=_K))
    r_fixed = fixed.rollouts().drop_columns(["wall_time_s"])
    r_first = (
        adaptive.rollouts()
        .drop_columns(["wall_time_s"])
        .filter(adaptive.rollouts().column("draw").to_numpy() < _K)
    )
    assert r_fixed.equals(r_first)
    s = summarize(adaptive)["labels"]
    assert s["draws"] == _K and s["extend_to"] == _M and s["cells"] == len(cells)
    assert s["mean_rollouts_per_cell"] == pytest.approx(adaptive.rollouts().num_rows / len(cells))
    assert s["extended_share"] == pytest.approx(extended / len(cells))
    p = adaptive.samples().column("success_p").to_numpy()
    assert s["varying_share"] == pytest.approx(np.mean((p > 0) & (p < 1)))


def test_draws_come_from_the_pose_stream():
    """The perturbation stream is a fourth child of the pose's seed: the first three are unchanged."""
    a, b = PoseStreams(0, 1, 2), PoseStreams(0, 1, 2)
    assert_array_equal(a.perturbations.random(4), b.perturbations.random(4))
    ss = np.random.SeedSequence(0, spawn_key=(1, 2))
    density, designs, cloud = (np.random.default_rng(s) for s in ss.spawn(3))
    c = PoseStreams(0, 1, 2)
    for old, new in ((density, c.density), (designs, c.designs), (cloud, c.cloud)):
        assert_array_equal(old.random(3), new.random(3))


def test_a_replicate_is_an_independent_stream_of_the_same_pose():
    """Replicate 0 is the dataset's draws; r >= 1 another stream, reproducible; the other streams unchanged."""
    assert_array_equal(
        PoseStreams(0, 1, 2).perturbations.random(4), PoseStreams(0, 1, 2, 0).perturbations.random(4)
    )
    first = PoseStreams(0, 1, 2, replicate=1).perturbations.random(4)
    assert_array_equal(first, PoseStreams(0, 1, 2, replicate=1).perturbations.random(4))
    for other in (PoseStreams(0, 1, 2), PoseStreams(0, 1, 2, replicate=2)):
        assert not np.any(np.isclose(first, other.perturbations.random(4)))
    a, b = PoseStreams(0, 1, 2), PoseStreams(0, 1, 2, replicate=3)
    for x, y in ((a.density, b.density), (a.designs, b.designs), (a.cloud, b.cloud)):
        assert_array_equal(x.random(3), y.random(3))


def test_a_shard_rerun_from_the_dataset_gives_its_rows_and_a_replicate_redraws_them(adaptive, work):
    """shard_tasks + Worker at replicate 0 recompute a shard's rollouts bit for bit; replicate 1 keeps the
    designs and the procedure (K, extended to M where they disagree) under other draws."""
    from mjcodesign.data.store import shard_tasks
    from mjcodesign.data.tasks import Worker

    config = DatagenConfig.from_dict(adaptive.manifest["config"])
    task = shard_tasks(adaptive.root, adaptive.manifest, 0, config, str(work / "cache"))[0]
    worker = Worker(nthread=1)
    (again,) = worker.run([task])
    stored = adaptive.rollouts().to_pydict()
    mine = [i for i, (o, q) in enumerate(zip(stored["object_index"], stored["pose_index"], strict=True))
            if (o, q) == (0, task.pose_index)]  # fmt: skip
    got = again.rollouts.to_pydict()
    for key in ("design_index", "draw", "perturbation", "success", "body_force"):
        assert got[key] == [stored[key][i] for i in mine], key
    (rep,) = worker.run([dataclasses.replace(task, replicate=1)])
    r = rep.rollouts.to_pydict()
    assert r["perturbation"][0] != got["perturbation"][0]
    assert rep.samples.column("log_e").to_pylist() == again.samples.column("log_e").to_pylist()
    per_cell = np.bincount(np.asarray(r["design_index"]))
    assert set(per_cell[per_cell > 0]) <= {_K, _M}


def test_two_workers_and_a_resume_give_the_same_dataset(adaptive, work):
    config = _config(work, perturbations=_K, perturbations_max=_M)
    two = _make(work, "two", config, workers=2)
    ref = _tables(adaptive)
    for name, t in _tables(two).items():
        assert t.equals(ref[name]), name
    # Interrupted after its first shard, then continued: the same rows; a damaged rollouts file is redone.
    out = work / "resumed"

    class Stop(Exception):
        pass

    def stop(event):
        if event.kind == "shard":
            raise Stop

    with pytest.raises(Stop):
        generate(config, out, cache_dir=work / "cache", on_event=stop)
    assert not open_dataset(out).manifest["complete"]
    res = generate(config, out, cache_dir=work / "cache")
    assert res["complete"] and res["computed"]["shards"] >= 1
    victim = next(out.glob("rollouts/*.parquet"))
    victim.write_bytes(victim.read_bytes()[:-100])
    res = generate(config, out, cache_dir=work / "cache")
    assert [d.split(" ")[0] for d in res["damaged_redone"]] == [f"rollouts/{victim.name}"]
    for name, t in _tables(open_dataset(out)).items():
        assert t.equals(ref[name]), name
    m = open_dataset(out).manifest
    assert m["counts"]["rollouts"] == ref["rollouts"].num_rows
    assert m["tables"]["rollouts"] == "rollouts/" and "success_p" in m["columns"]


def test_config_records_perturbations_only_above_one(work):
    one = _config(work)
    assert "perturbations" not in one.as_dict()
    # K = 1 ignores the model: a dataset made without the flag keeps its fingerprint.
    assert dataclasses.replace(one, perturbation=PerturbationModel()).fingerprint() == one.fingerprint()
    k = _config(work, perturbations=4, perturbations_max=16)
    d = k.as_dict()["perturbations"]
    assert d == {"draws": 4, "extend_to": 16, "model": _WIDE.as_dict()}
    assert DatagenConfig.from_dict(k.as_dict()) == k and DatagenConfig.from_dict(one.as_dict()) == one
    assert len({one.fingerprint(), k.fingerprint(), _config(work, perturbations=4).fingerprint()}) == 3
    assert parse_perturbations("4:16") == (4, 16) and parse_perturbations(" 1 ") == (1, None)
    for bad in ("0", "4:2", "4:4", "1:4", "x", "4:", "-2", "2:3:4"):
        with pytest.raises(DesignError):
            parse_perturbations(bad)
    with pytest.raises(UnsupportedError):
        _config(work, perturbations=4, backend="mjwarp")


def test_k1_is_the_dataset_made_without_the_flag(work, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(work / "cache"))
    base = [
        "datagen",
        "--objects",
        str(work / "box50.stl"),
        "--poses-per-object",
        "1",
        "--designs-per-pose",
        "2",
        "--scenario",
        json.dumps({"tighten_s": 0.1, "lift_s": 0.2, "hold_s": 0.1, "post_hold_s": 0.02}),
    ]
    _config(work)  # writes the box
    assert main([*base, "--out", str(work / "plain")]) == 0
    assert main([*base, "--perturbations", "1", "--out", str(work / "one")]) == 0
    capsys.readouterr()
    a, b = open_dataset(work / "plain"), open_dataset(work / "one")
    assert a.manifest["fingerprint"] == b.manifest["fingerprint"] and not b.perturbed
    for t in ("poses", "samples", "rejected"):
        assert (
            a.table(t)
            .drop_columns(["wall_time_s"] if t != "poses" else [])
            .equals(b.table(t).drop_columns(["wall_time_s"] if t != "poses" else []))
        ), t
    assert not (work / "one" / "rollouts").exists() and "success_p" not in b.manifest["columns"]
    assert (
        pq.read_schema(next((work / "one" / "samples").glob("*.parquet"))).names == a.samples().column_names
    )


@pytest.mark.parametrize(
    "value, match", [("0", ">= 1"), ("4:2", "M > K"), ("x", "K or K:M"), ("1:4", "K >= 2")]
)
def test_bad_perturbations_exit_2_with_one_line_and_no_folder(work, capsys, value, match):
    out = work / f"bad-{value.replace(':', '-')}"
    argv = ["datagen", "--objects", "egad-like:1", "--perturbations", value, "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
    assert not out.exists()


# The first draw of the default model's stream (seed 0, 012_strawberry, pose 1), as the evaluation drew it
# before the model moved into mjcodesign.scenarios.perturb: the move keeps the evaluation's draws.
_FIRST_DRAW = Perturbation(
    palm_offset=(0.0006037929178914761, -6.509675352440558e-05, -0.0014346961622980414),
    palm_rotation=(-0.006630977597265508, 0.0010148668822988133, 0.022622801659949964),
    mass_scale=0.9815811087960554,
    friction_scale=1.1665914244116573,
    tendon_scale=1.0013436646064986,
)


def test_evaluation_draws_are_kept_by_the_move():
    from mjcodesign import evaluation
    from mjcodesign.scenarios import perturb

    assert evaluation.PerturbationModel is perturb.PerturbationModel
    assert evaluation.MAX_REDRAWS == perturb.MAX_REDRAWS
    model = perturb.PerturbationModel()
    assert model.draw(model.stream(0, "012_strawberry", 1)) == _FIRST_DRAW


def test_the_surrogate_loads_and_trains_on_cell_means(adaptive):
    """Its outputs are the cells' means; its success the binary label (success_p >= 0.5)."""
    pytest.importorskip("torch")
    from mjcodesign.surrogate import ModelConfig, TrainConfig, load_grasp_data, split, train

    data = load_grasp_data(adaptive.root)
    s = adaptive.samples()
    assert len(data) == s.num_rows
    force = np.array(s.column("body_force").to_pylist())
    assert_array_equal(data.outputs[:, :6], force)
    assert_array_equal(data.success, s.column("success").to_numpy(zero_copy_only=False))
    tiny = ModelConfig(point_widths=(8, 16), hidden=16, depth=1, penultimate=8, dropout=0.0)
    result = train(data, split(data, "random", seed=0), TrainConfig(epochs=1, batch_size=4, seed=0), tiny)
    assert np.isfinite(result.history[-1].train_loss)
