"""External grasp candidates: AnyGrasp/GraspNet files, mapped into the scene's world and refined.

The authors' poses come in their camera frame; :func:`anygrasp_to_world` maps them to palm poses of
:mod:`mjcodesign.poses.gripper`'s frames and :func:`import_anygrasp` refines and ranks them like
sampled ones (:func:`mjcodesign.poses.accept.refine_and_rank`), keeping each row's index in the file
(``source_index``) and the reason for every row it drops.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import MeshError, PoseError
from mjcodesign.models.types import ROTATION_TOL
from mjcodesign.objects import GraspObject, check_seed
from mjcodesign.poses.accept import refine_and_rank
from mjcodesign.poses.candidates import Candidates, augment_poses, load_numpy
from mjcodesign.poses.grid import ObjectSDF
from mjcodesign.poses.gripper import scene_offset

__all__ = ["ANYGRASP_DEPTH", "anygrasp_to_world", "import_anygrasp", "load_external"]

ANYGRASP_DEPTH = 0.05
"""Imported grasp centres sit this far from the fingertips [m]. Measured on the semi-rigid gripper in
MuJoCo (top 4 refined AnyGrasp poses, impulse 0): 013_apple 0/4, 3/4, 3/4 and 014_lemon 0/4, 2/4, 4/4
successes at 20, 35 and 50 mm; nearer the tip the fingers squeeze above round objects' equators."""

_CAMERA_HEIGHT = 0.5  # authors' camera: 0.5 m above the ground, looking down (init_pose.py T_cb)
_R_CAMERA = np.diag([-1.0, 1.0, -1.0])  # authors' camera axes in the object (z-up) frame
# AnyGrasp/GraspNet gripper frame (x approach, y closing, z height) -> palm (x, y, z = -approach).
_R_ANYGRASP_PALM = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


def anygrasp_to_world(
    T_pose: np.ndarray, obj: GraspObject, source_vertices: np.ndarray, *, depth: float | None = None
) -> np.ndarray:
    """The authors' AnyGrasp poses (N, 4, 4) as palm poses in our scene's world (N, 4, 4).

    The authors' ``T_pose`` is the AnyGrasp gripper frame (x approach, y closing, GraspNet) in a camera
    frame 0.5 m above the ground looking down, the camera axes being (−x, y, −z) of the YCB mesh with
    the mesh's vertex mean below it (``init_pose.py``: T_cb, and ``object_loader.py``: the mesh is
    shifted by its vertex mean and lifted onto the ground). So a camera point c lies at
    ``diag(−1, 1, −1) c + (0, 0, 0.5 + min z)`` relative to the vertex mean; our scene puts the COM at
    x = y = 0. The grasp centre lies ``depth`` (default ``ANYGRASP_DEPTH``) from the fingertips along
    the finger; ``source_vertices`` are the source mesh's vertices (its frame, before centring).
    """
    depth = ANYGRASP_DEPTH if depth is None else float(depth)
    if not (0.0 <= depth <= FingerDesign().length):
        raise PoseError(f"depth must be in [0, {FingerDesign().length}] m, got {depth}")
    T_pose = np.asarray(T_pose, dtype=float)
    src = np.asarray(source_vertices, dtype=float)
    mean = src.mean(axis=0)
    lift = np.array([0.0, 0.0, _CAMERA_HEIGHT + float(src[:, 2].min() - mean[2])])
    centre = np.einsum("ij,nj->ni", _R_CAMERA, T_pose[:, :3, 3]) + lift + (mean - obj.com_offset)
    centre = centre + scene_offset(obj)
    R = _R_CAMERA @ T_pose[:, :3, :3] @ _R_ANYGRASP_PALM
    out = np.tile(np.eye(4), (len(T_pose), 1, 1))
    out[:, :3, :3] = R
    out[:, :3, 3] = centre + R[:, :, 2] * (FingerDesign().length - depth)
    return out


def _read_array(path: Path) -> np.ndarray:
    """The raw array of a grasp file (any shape); :class:`PoseError` with one line if it cannot be read."""
    if path.suffix in (".npz", ".npy"):
        data = load_numpy(path, "grasp file")
        if path.suffix == ".npz" or isinstance(data, np.lib.npyio.NpzFile):
            if not isinstance(data, np.lib.npyio.NpzFile):
                raise PoseError(f"{path}: not a grasp file (an .npy array named .npz)")
            with data:
                if "T_pose" not in data.files:
                    keys = ", ".join(data.files) or "none"
                    raise PoseError(f"{path}: not a grasp file (no T_pose array; keys: {keys})")
                data = data["T_pose"]
        try:
            return np.asarray(data, dtype=float)
        except (TypeError, ValueError) as exc:
            raise PoseError(f"{path}: not a grasp file (its array is not numeric)") from exc
    try:
        return np.atleast_2d(np.loadtxt(path, dtype=float, delimiter="," if path.suffix == ".csv" else None))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise PoseError(f"{path}: not a grasp file (not rows of numbers: {type(exc).__name__})") from exc


def load_external(path: str | Path) -> np.ndarray:
    """Grasp matrices (N, 4, 4) from an AnyGrasp/GraspNet file, in its camera frame.

    Reads ``.npz`` (key ``T_pose``, N×4×4), ``.npy`` (4×4, N×4×4 or N×17) or text (N×17 rows or 16
    floats a row). GraspNet's 17 floats are score, width, height, depth, rotation (9, row-major),
    translation (3), object id.
    """
    path = Path(path)
    if not path.is_file():
        raise PoseError(f"grasp file not found: {path}")
    a = _read_array(path)
    if a.shape == (4, 4):
        a = a[None]
    if a.ndim == 2 and a.shape[1] == 17:
        T = np.tile(np.eye(4), (len(a), 1, 1))
        T[:, :3, :3] = a[:, 4:13].reshape(-1, 3, 3)
        T[:, :3, 3] = a[:, 13:16]
        a = T
    elif a.ndim == 2 and a.shape[1] == 16:
        a = a.reshape(-1, 4, 4)
    if a.ndim != 3 or a.shape[1:] != (4, 4) or len(a) == 0:
        raise PoseError(f"{path}: expected N×4×4 matrices or N×17 GraspNet rows, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise PoseError(f"{path}: grasp file contains NaN or inf")
    R = a[:, :3, :3]
    if np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max() > ROTATION_TOL:
        raise PoseError(f"{path}: rotation blocks are not orthonormal")
    return a


def import_anygrasp(
    obj: GraspObject,
    T_pose: np.ndarray,
    source_vertices: np.ndarray,
    *,
    seed: int = 0,
    augment: int = 0,
    depth: float | None = None,
    source: str = "anygrasp",
    cache_dir: str | Path | None = None,
    fit_depth: bool = False,
) -> Candidates:
    """AnyGrasp poses mapped (:func:`anygrasp_to_world`), optionally augmented, refined and ranked.

    ``source_index`` of each candidate is its row in ``T_pose``; ``source`` names the file (``source``).
    ``cache_dir`` keeps the object's signed-distance grid (:class:`~mjcodesign.poses.grid.ObjectSDF`).
    ``fit_depth``: each pose first moves along its approach from ``depth``'s start to the depth
    :func:`~mjcodesign.poses.refine.approach_depth` sets.
    """
    if len(source_vertices) == 0:
        raise MeshError("source mesh has no vertices")
    seed = check_seed(seed, error=PoseError)
    T = anygrasp_to_world(T_pose, obj, source_vertices, depth=depth)
    T = augment_poses(T, augment, np.random.default_rng(seed))
    rows = np.repeat(np.arange(len(T_pose)), augment + 1)
    copies = np.tile(np.arange(augment + 1), len(T_pose))
    return refine_and_rank(
        obj,
        T,
        np.ones(len(T)),
        FingerDesign(),
        {},
        source_index=rows,
        copy_index=copies,
        source=source,
        sdf=ObjectSDF(obj.mesh, cache_dir=cache_dir),
        fit_depth=fit_depth,
    )
