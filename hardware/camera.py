"""Point clouds in the robot base frame: from files, or from a RealSense camera when installed.

A camera gives points in its own frame; the calibration file gives the camera-to-base transform
``T_base_camera`` (4x4, [m]) so that ``p_base = T_base_camera @ p_camera``. Cropping to the
gripper's bounding box at a grasp pose gives the partial point cloud that the surrogate reads.

Gripper frame (franky's end-effector frame at the soft fingertips): z is the approach direction,
y is the closing direction of the Franka Hand, x is across the finger width.

``pyrealsense2`` is optional (extra ``realsense``) and imported lazily in `RealSenseCamera`.
"""

from __future__ import annotations

import json
import struct
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.errors import HardwareError, PoseError

from .arm import FRANKA_HAND_MAX_WIDTH, check_transform

__all__ = [
    "ARRAY_FILE_ERRORS",
    "FileCamera",
    "GripperGeometry",
    "RealSenseCamera",
    "crop_to_gripper",
    "load_calibration",
    "load_point_cloud",
    "save_point_cloud",
]

ARRAY_FILE_ERRORS = (OSError, ValueError, EOFError, struct.error, zipfile.BadZipFile)
"""What ``np.load`` and the PLY reader raise on an unreadable file: EOFError for an empty one,
BadZipFile for a damaged ``.npz``, ValueError for anything else that is not an array."""

_PLY_TYPES = {
    "char": "i1",
    "uchar": "u1",
    "int8": "i1",
    "uint8": "u1",
    "short": "i2",
    "ushort": "u2",
    "int16": "i2",
    "uint16": "u2",
    "int": "i4",
    "uint": "u4",
    "int32": "i4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_CALIB_KEYS = ("T_base_camera", "T", "extrinsics")
_REALSENSE_TIMEOUT_MS = 5000  # wait for one depth frame
_REALSENSE_MAX_DEPTH_M = 2.0  # D435 depth beyond 2 m is too noisy for grasping


@dataclass(frozen=True)
class GripperGeometry:
    """Soft-finger and Franka Hand dimensions [m].

    The finger geometry is owned by the core package; these defaults are the paper's fingers.
    """

    finger_length: float = 0.136
    finger_width: float = 0.020
    finger_height: float = 0.014
    hand_max_width: float = FRANKA_HAND_MAX_WIDTH

    def __post_init__(self) -> None:
        for name in ("finger_length", "finger_width", "finger_height", "hand_max_width"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise PoseError(f"gripper {name} must be positive, got {value}")

    def box(self, s1: float, s2: float) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corners of the fingers' bounding box in the gripper frame [m].

        `s1` and `s2` are the openings of the two fingers: the distances from the gripper
        origin to each finger's inner face along +y and -y.
        """
        lo = np.array([-self.finger_width / 2, -s2 - self.finger_height, -self.finger_length])
        hi = np.array([self.finger_width / 2, s1 + self.finger_height, 0.0])
        return lo, hi


def crop_to_gripper(
    points: np.ndarray,
    pose: np.ndarray,
    geometry: GripperGeometry,
    s1: float,
    s2: float,
) -> np.ndarray:
    """Points of the base-frame cloud (N, 3) inside the gripper box at `pose` (4, 4) [m].

    Returns them in the gripper frame, shape (M, 3).
    """
    T = check_transform(pose)
    local = (np.asarray(points, dtype=float) - T[:3, 3]) @ T[:3, :3]
    lo, hi = geometry.box(s1, s2)
    inside = np.all((local >= lo) & (local <= hi), axis=1)
    return local[inside]


def transform_points(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Apply the 4x4 transform `T` to points (N, 3) [m]."""
    return np.asarray(points, dtype=float) @ T[:3, :3].T + T[:3, 3]


def _check_points(points: np.ndarray, path: Path) -> np.ndarray:
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise HardwareError(f"{path}: point cloud must have shape (N, 3), got {pts.shape}")
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        raise HardwareError(f"{path}: point cloud has no finite points")
    return pts


def _read_ply(path: Path) -> np.ndarray:
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise HardwareError(f"{path}: not a PLY file")
    body_start = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii", "replace").splitlines()
    fmt, count, props, in_vertex = "", 0, [], False
    for line in header:
        words = line.split()
        if not words:
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            in_vertex = words[1] == "vertex"
            if in_vertex:
                count = int(words[2])
        elif words[0] == "property" and in_vertex:
            if words[1] == "list":
                raise HardwareError(f"{path}: list properties on vertices are not supported")
            if words[1] not in _PLY_TYPES:
                raise HardwareError(f"{path}: unknown PLY type {words[1]}")
            props.append((words[2], _PLY_TYPES[words[1]]))
    names = [n for n, _ in props]
    if not {"x", "y", "z"} <= set(names):
        raise HardwareError(f"{path}: PLY vertices lack x, y or z")
    if fmt == "ascii":
        text = data[body_start:].decode("ascii", "replace").split()
        table = np.array(text[: count * len(props)], dtype=float).reshape(count, len(props))
        return table[:, [names.index(c) for c in "xyz"]]
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None:
        raise HardwareError(f"{path}: unsupported PLY format {fmt!r}")
    dtype = np.dtype([(n, order + t) for n, t in props])
    # Vertices come first in every PLY that a depth camera or Open3D writes.
    table = np.frombuffer(data, dtype=dtype, count=count, offset=body_start)
    return np.stack([table[c].astype(float) for c in "xyz"], axis=1)


def load_point_cloud(path: str | Path) -> np.ndarray:
    """Read a point cloud (N, 3) [m] from PLY (ascii or binary), NPZ (key ``points``) or NPY."""
    path = Path(path)
    if not path.is_file():
        raise HardwareError(f"point cloud file not found: {path}")
    suffix = path.suffix.lower()
    try:
        if suffix == ".ply":
            pts = _read_ply(path)
        elif suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        elif suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                if "points" not in z:
                    raise HardwareError(f"{path}: no array named 'points' (has {list(z.keys())})")
                pts = z["points"]
        else:
            raise HardwareError(f"{path}: unknown point cloud format (use .ply, .npz or .npy)")
    except ARRAY_FILE_ERRORS as exc:
        raise HardwareError(f"{path}: cannot read point cloud: {_reason(exc)}") from None
    return _check_points(pts, path)


def _reason(exc: BaseException) -> str:
    """One line for a read error: its message's first line, else its type (an empty file's EOFError)."""
    text = str(exc).strip()
    return text.splitlines()[0][:200] if text else type(exc).__name__


def save_point_cloud(path: str | Path, points: np.ndarray) -> None:
    """Write points (N, 3) [m] as binary little-endian PLY, or NPZ/NPY by suffix."""
    path = Path(path)
    pts = np.ascontiguousarray(points, dtype="<f4")
    if path.suffix.lower() == ".npz":
        np.savez(path, points=points)
    elif path.suffix.lower() == ".npy":
        np.save(path, points)
    else:
        header = (
            "ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(pts)}\n"
            "property float x\nproperty float y\nproperty float z\nend_header\n"
        )
        path.write_bytes(header.encode("ascii") + pts.tobytes())


def load_calibration(path: str | Path) -> np.ndarray:
    """Read the camera-to-base transform ``T_base_camera`` (4, 4) [m].

    Accepted: ``.npy`` (the matrix), ``.npz`` (key ``T_base_camera``), or ``.json``
    (``{"T_base_camera": [[...], ...]}``).
    """
    path = Path(path)
    if not path.is_file():
        raise HardwareError(f"calibration file not found: {path}")
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(path.read_text())
            matrix = next((doc[k] for k in _CALIB_KEYS if k in doc), None)
        elif path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                matrix = next((z[k] for k in _CALIB_KEYS if k in z), None)
        else:
            matrix = np.load(path, allow_pickle=False)
    except ARRAY_FILE_ERRORS as exc:
        raise HardwareError(f"{path}: cannot read calibration: {_reason(exc)}") from None
    if matrix is None:
        raise HardwareError(f"{path}: no key among {_CALIB_KEYS}")
    try:
        return check_transform(matrix, f"calibration {path.name}")
    except PoseError as exc:
        raise HardwareError(str(exc)) from None


class FileCamera:
    """A 'camera' that reads a recorded cloud and maps it to the base frame."""

    def __init__(self, path: str | Path, calibration: np.ndarray | None = None) -> None:
        self.path = Path(path)
        self.T_base_camera = np.eye(4) if calibration is None else check_transform(calibration)

    def capture(self) -> np.ndarray:
        """Points in the base frame, shape (N, 3) [m]."""
        return transform_points(load_point_cloud(self.path), self.T_base_camera)


class RealSenseCamera:
    """Intel RealSense (D435) depth camera through pyrealsense2 (optional extra)."""

    def __init__(self, calibration: np.ndarray, serial: str | None = None) -> None:
        self.T_base_camera = check_transform(calibration)
        self.serial = serial

    def capture(self) -> np.ndarray:
        """One depth frame as points in the base frame, shape (N, 3) [m]."""
        try:
            import pyrealsense2 as rs
        except ImportError:
            raise HardwareError(
                "pyrealsense2 is not installed (install the 'realsense' extra) "
                "or give a recorded point cloud file"
            ) from None
        pipeline, config = rs.pipeline(), rs.config()
        if self.serial:
            config.enable_device(self.serial)
        config.enable_stream(rs.stream.depth)
        try:
            pipeline.start(config)
            try:
                frames = pipeline.wait_for_frames(_REALSENSE_TIMEOUT_MS)
                depth = frames.get_depth_frame()
                verts = np.asarray(rs.pointcloud().calculate(depth).get_vertices())
            finally:
                pipeline.stop()
        except RuntimeError as exc:
            raise HardwareError(f"RealSense capture failed: {exc}") from None
        pts = verts.view(np.float32).reshape(-1, 3).astype(float)
        keep = (pts[:, 2] > 0) & (pts[:, 2] < _REALSENSE_MAX_DEPTH_M)
        return transform_points(pts[keep], self.T_base_camera)
