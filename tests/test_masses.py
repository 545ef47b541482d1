"""Real object masses: the published YCB table, an object at a mass, and ``--mass`` on the commands."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mjcodesign.errors import MeshError
from mjcodesign.objects import (
    YCB_IN_DOMAIN,
    YCB_OOD,
    at_mass,
    box_object,
    mass_table,
    parse_mass,
    published_mass,
    real_density,
)

# Masses as the YCB object list prints them [g] (ycbbenchmarks.com, object-list-Sheet1.pdf, column
# "Mass"), written here by hand from the list so that a mistyped table fails.
_SHEET_G = {
    "013_apple": 68,
    "006_mustard_bottle": 603,
    "010_potted_meat_can": 370,
    "012_strawberry": 18,
    "056_tennis_ball": 58,
    "065-j_cups": 38,
    "044_flat_screwdriver": 98.4,
}


def test_every_ycb_object_of_both_splits_has_a_mass_or_a_reason():
    rows = mass_table()["objects"]
    assert set(YCB_IN_DOMAIN) | set(YCB_OOD) <= set(rows)
    for name in YCB_IN_DOMAIN + YCB_OOD:
        row = rows[name]
        if row["mass_kg"] is None:
            assert row.get("note"), name  # the table says why there is none
        else:
            assert 0.001 < row["mass_kg"] < 2.0, name


def test_table_header_cites_its_source():
    t = mass_table()
    assert t["unit"] == "kg"
    assert "ycbbenchmarks.com" in t["source"] and "object-list-Sheet1.pdf" in t["source"]
    assert "10.1109/MRA.2015.2448951" in t["source"]


@pytest.mark.parametrize("name", sorted(_SHEET_G))
def test_published_mass_matches_the_list(name):
    m = published_mass(name)
    assert m.mass == pytest.approx(_SHEET_G[name] / 1000.0, abs=1e-9)
    assert "object-list-Sheet1.pdf" in m.source


@pytest.mark.parametrize(
    "name", ["063-a_marbles", "072-a_toy_airplane", "073-c_lego_duplo", "egad-like:3", "cup.stl", "nope"]
)
def test_no_published_mass_is_refused_not_invented(name):
    with pytest.raises(MeshError) as exc:
        published_mass(name)
    assert "\n" not in str(exc.value)


def test_parse_mass():
    assert parse_mass(None) is None and parse_mass("density") is None
    assert parse_mass("real") == "real"
    assert parse_mass("0.25") == 0.25
    for bad in ("heavy", "-1", "0", "nan", "1e3"):
        with pytest.raises(MeshError):
            parse_mass(bad)


def test_at_mass_scales_density_and_inertia_of_the_same_mesh():
    box = box_object((0.04, 0.05, 0.06), 100.0)
    heavy = at_mass(box, 0.3)
    volume = 0.04 * 0.05 * 0.06
    assert heavy.mass == pytest.approx(0.3)
    assert heavy.density == pytest.approx(0.3 / volume)  # uniform: rho = m / V
    assert real_density(box, 0.3) == pytest.approx(heavy.density)
    # A uniform box: I_xx = m (b² + c²) / 12.
    assert heavy.inertia[0, 0] == pytest.approx(0.3 * (0.05**2 + 0.06**2) / 12.0, rel=1e-9)
    np.testing.assert_allclose(heavy.inertia, box.inertia * heavy.mass / box.mass, rtol=1e-12)
    assert heavy.hulls is box.hulls and heavy.mesh is box.mesh


def test_load_grasp_object_at_its_real_mass():
    from mjcodesign.cli.common import user_cache_dir
    from mjcodesign.jobs import load_grasp_object

    cache = user_cache_dir()  # CoACD's cache, shared with the other tests
    obj = load_grasp_object("013_apple", "light", mass="real", cache_dir=cache)
    assert obj.mass == pytest.approx(0.068)
    light = load_grasp_object("013_apple", "light", cache_dir=cache)
    assert obj.density == pytest.approx(0.068 / (light.mass / light.density))
    given = load_grasp_object("egad-like:0", mass=0.05, cache_dir=cache)
    assert given.mass == pytest.approx(0.05)
    with pytest.raises(MeshError, match="no published mass"):
        load_grasp_object("egad-like:0", mass="real", cache_dir=cache)


def test_grasp_cli_uses_the_published_mass(capsys):
    from mjcodesign.cli.main import main

    assert main(["grasp", "--object", "013_apple", "--mass", "real", "--design", "soft", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mass_kg"] == pytest.approx(0.068)
    assert out["mass_mode"] == "real"
    assert "object-list-Sheet1.pdf" in out["mass_source"]


def test_grasp_cli_refuses_an_object_without_a_published_mass(capsys):
    from mjcodesign.cli.main import main

    assert main(["grasp", "--object", "063-a_marbles", "--mass", "real", "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no published mass" in err


def test_datagen_places_every_object_at_its_published_mass(tmp_path):
    from mjcodesign.cli.common import user_cache_dir
    from mjcodesign.data import DatagenConfig, generate, open_dataset, parse_density_spec

    cfg = DatagenConfig(
        objects=("013_apple", "012_strawberry"),
        poses_per_object=1,
        designs_per_pose=2,
        density=parse_density_spec("light"),
        mass="real",
    )
    generate(cfg, tmp_path / "ds", workers=1, cache_dir=user_cache_dir())
    ds = open_dataset(tmp_path / "ds")
    assert ds.manifest["config"]["mass"]["mode"] == "real"
    assert "object-list-Sheet1.pdf" in ds.manifest["config"]["mass"]["source"]
    poses = ds.poses().to_pydict()
    for name, mass in zip(poses["object"], poses["mass"], strict=True):
        assert mass == pytest.approx(_SHEET_G[name] / 1000.0, rel=1e-9)
    assert DatagenConfig.from_dict(ds.manifest["config"]) == cfg


def test_datagen_refuses_real_masses_it_does_not_have():
    from mjcodesign.data import DatagenConfig, parse_density_spec

    with pytest.raises(MeshError, match="063-a_marbles"):
        DatagenConfig(
            objects=("013_apple", "063-a_marbles"),
            poses_per_object=1,
            designs_per_pose=1,
            density=parse_density_spec("light"),
            mass="real",
        )


def test_density_datasets_keep_their_fingerprint():
    # A density-mode config hashes what it hashed before masses had a mode: the manifest's "mass" entry,
    # the unset scenario options and the unset tied_flexures (added since) are left out of the fingerprint.
    import dataclasses
    import hashlib

    from mjcodesign.data import DatagenConfig, parse_density_spec
    from mjcodesign.data.config import SCHEMA_VERSION
    from mjcodesign.models.types import SimOptions

    cfg = DatagenConfig(objects=("013_apple",), poses_per_object=1, designs_per_pose=1, density=parse_density_spec("light"))
    d = cfg.as_dict()
    assert d["mass"] == {"mode": "density"}
    old = {k: v for k, v in d.items() if k != "mass"}
    old["scenario"] = {k: v for k, v in dataclasses.asdict(cfg.scenario).items() if k not in ("delta_v", "friction")}
    old["sim_options"] = {k: v for k, v in dataclasses.asdict(SimOptions()).items() if k != "tied_flexures"}
    text = json.dumps({"schema_version": SCHEMA_VERSION, **old}, sort_keys=True)
    assert cfg.fingerprint() == hashlib.sha256(text.encode()).hexdigest()


def _two_ycb_pose_set():
    """Two YCB objects x 2 rows with known volumes [m³] (what a dataset's mass / density gives)."""
    from mjcodesign.codesign import PoseSet

    n = 4
    return PoseSet(
        ("013_apple", "012_strawberry"),
        np.array([0, 0, 1, 1]),
        np.zeros((n, 8, 3), dtype=np.float32),
        np.zeros((n, 3)),
        np.tile(np.eye(4), (n, 1, 1)),
        np.full((n, 2), 0.04),
        np.array([2.5e-4, 2.5e-4, 4.8e-5, 4.8e-5]),
    )


def test_codesign_densities_per_object_from_the_published_masses():
    from mjcodesign.codesign.problem import real_densities, row_densities
    from mjcodesign.errors import DesignError

    poses = _two_ycb_pose_set()
    rho = real_densities(poses)
    assert rho == {"013_apple": pytest.approx(0.068 / 2.5e-4), "012_strawberry": pytest.approx(0.018 / 4.8e-5)}
    np.testing.assert_allclose(row_densities(poses, rho), [272.0, 272.0, 375.0, 375.0])
    np.testing.assert_array_equal(row_densities(poses, 100.0), [100.0] * 4)
    with pytest.raises(DesignError, match="012_strawberry"):
        row_densities(poses, {"013_apple": 300.0})


def test_optimize_feeds_each_object_its_own_density():
    from mjcodesign.codesign import OptimizeConfig, optimize

    sur = _RecordingSurrogate()
    poses = _two_ycb_pose_set()
    rho = {"013_apple": 272.0, "012_strawberry": 375.0}
    optimize(sur, poses, rho, OptimizeConfig(max_iterations=1))
    (batch,) = sur.batches  # joint mode: one batch of every row
    np.testing.assert_array_equal(batch.density, [272.0, 272.0, 375.0, 375.0])


class _RecordingSurrogate:
    """Records the batches Algorithm 1 prepares; a flat loss (zero gradient) for every row."""

    def __init__(self):
        self.batches = []

    def prepare(self, batch):
        self.batches.append(batch)
        return batch

    def loss_and_grad(self, log_e, batch, loss=None):
        from types import SimpleNamespace

        n = len(batch.pose)
        return SimpleNamespace(rows=np.ones(n), grad=np.zeros(22), total=float(n))


def test_mass_by_rule_names_what_each_rule_gives():
    from mjcodesign.objects import mass_by_rule

    assert mass_by_rule("013_apple", "real").mass == pytest.approx(0.068)
    assert mass_by_rule("013_apple", "auto").mass == pytest.approx(0.068)
    assert mass_by_rule("063-a_marbles", "auto") is None and mass_by_rule("013_apple", "density") is None
    with pytest.raises(MeshError, match="no published mass"):
        mass_by_rule("063-a_marbles", "real")
    with pytest.raises(MeshError, match="mass rule"):
        mass_by_rule("013_apple", "heavy")
