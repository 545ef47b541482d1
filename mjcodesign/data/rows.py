"""Grasp poses as rows: :class:`PoseRows`, and :func:`read_poses`, the one reader of a dataset's poses table.

A pose row is what the surrogate reads of a grasp (the partial cloud, the object's COM, the world's
vertical and the object's volume, in the gripper frame) and what the simulator runs (the palm pose and
the fingers' target openings). A dataset's poses, a co-design's candidates
(:class:`mjcodesign.codesign.PoseSet`) and the surrogate's training data
(:class:`mjcodesign.surrogate.GraspData`) all hold their poses as one :class:`PoseRows`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mjcodesign.data.cloud import gripper_up
from mjcodesign.data.reader import Dataset
from mjcodesign.errors import DesignError, OutputError
from mjcodesign.models.types import GripperPose

__all__ = ["PoseRows", "StoredPoses", "read_poses"]


@dataclass(frozen=True, eq=False)
class PoseRows:
    """P grasp poses of K objects; the rows of one object are contiguous, objects in order."""

    objects: tuple[str, ...]
    """Object names, shape (K,)."""
    object_of: np.ndarray
    """Object index of each pose, shape (P,), non-decreasing."""
    clouds: np.ndarray
    """Partial point clouds in the gripper frame [m], float32, shape (P, N, 3)."""
    com: np.ndarray
    """Object COM in the gripper frame [m], shape (P, 3)."""
    palms: np.ndarray
    """Palm poses in the scene's world [m], shape (P, 4, 4)."""
    openings: np.ndarray
    """Target openings of fingers A and B [m], shape (P, 2)."""
    volume: np.ndarray
    """Object volume [m³], shape (P,) (mass = density · volume)."""

    def __post_init__(self) -> None:
        p = len(self.object_of)
        shapes = [np.shape(self.com), np.shape(self.palms), np.shape(self.openings), np.shape(self.volume)]
        if shapes != [(p, 3), (p, 4, 4), (p, 2), (p,)] or len(self.clouds) != p:
            raise DesignError(f"pose rows need one cloud, COM, palm, opening pair and volume per pose ({p})")
        if p and (np.any(np.diff(self.object_of) < 0) or self.object_of[-1] >= len(self.objects)):
            raise DesignError("pose rows must be grouped by object, in object order")

    def __len__(self) -> int:
        return len(self.object_of)

    @property
    def up(self) -> np.ndarray:
        """World vertical in the gripper frame, shape (P, 3) (:func:`~mjcodesign.data.cloud.gripper_up`)."""
        return gripper_up(self.palms)

    @property
    def names(self) -> np.ndarray:
        """Object name of each pose, shape (P,)."""
        return np.asarray(self.objects, dtype=object)[self.object_of]

    def rows(self, k: int) -> np.ndarray:
        """Pose rows of object ``k``."""
        return np.flatnonzero(self.object_of == k)

    def gripper_pose(self, row: int) -> GripperPose:
        """Pose ``row`` as the simulator takes it."""
        return GripperPose.from_matrix(self.palms[row], tuple(float(v) for v in self.openings[row]))


@dataclass(frozen=True, eq=False)
class StoredPoses:
    """A dataset's poses table: its rows, sorted by (object index, pose index), and what else it keeps."""

    rows: PoseRows
    keys: np.ndarray
    """(object_index, pose_index) of each row in the dataset, shape (P, 2)."""
    mass: np.ndarray
    """Object mass at the pose's density [kg], shape (P,)."""
    density: np.ndarray
    """Object density drawn for the pose [kg/m³], shape (P,)."""


def read_poses(ds: Dataset) -> StoredPoses:
    """Every stored pose of ``ds`` (:meth:`Dataset.poses`), in the table's order.

    Raises :class:`OutputError` for point clouds of different sizes in one dataset.
    """
    t = ds.poses()
    names = [str(n) for n in t.column("object").to_pylist()]
    objects = tuple(dict.fromkeys(names))
    k_of = {n: k for k, n in enumerate(objects)}
    clouds = t.column("point_cloud").combine_chunks()
    lengths = np.diff(np.asarray(clouds.offsets))
    if len(set(lengths.tolist())) > 1:
        raise OutputError(f"{ds.root}: point clouds of different sizes in one dataset")
    pts = np.asarray(clouds.flatten().flatten().to_numpy(zero_copy_only=False), dtype=np.float32)
    n_points = int(lengths[0]) if len(lengths) else 0
    mass, density = t.column("mass").to_numpy(), t.column("density").to_numpy()
    rows = PoseRows(
        objects,
        np.array([k_of[n] for n in names], dtype=np.int64),
        pts.reshape(len(lengths), n_points, 3),
        _fixed(t, "com_gripper", 3),
        _fixed(t, "palm_pose", 16).reshape(-1, 4, 4),
        _fixed(t, "openings", 2),
        mass / density,
    )
    keys = np.stack([t.column(k).to_numpy() for k in ("object_index", "pose_index")], axis=1)
    return StoredPoses(rows, keys.reshape(-1, 2), mass, density)


def _fixed(t, name: str, width: int) -> np.ndarray:
    """A fixed-size list column as float64, shape (rows, width)."""
    flat = t.column(name).combine_chunks().flatten().to_numpy(zero_copy_only=False)
    return np.asarray(flat, dtype=float).reshape(-1, width)
