"""Per object: its grasp candidates and what the surrogate sees of each (cloud, COM, up, volume).

Candidates come from the sampler (best-ranked first) or, where ``anygrasp`` names a folder holding
``OBJECT.npz``, from the authors' AnyGrasp poses after this project's refinement, in the authors' own
row order (``source_index``), so that the fixed pose is the authors' first pose that survives
refinement.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.data import partial_cloud
from mjcodesign.data.cloud import gripper_up, to_gripper
from mjcodesign.errors import PoseError
from mjcodesign.models.types import GripperPose
from mjcodesign.objects import GraspObject, load_mesh
from mjcodesign.poses import import_anygrasp, load_external, sample_poses, scene_offset, to_gripper_pose

__all__ = ["ObjectCandidates", "object_candidates", "predict_candidates"]

CLOUD_POINTS = (
    1024  # the dataset's partial-cloud size (mjcodesign.data.CLOUD_POINTS); a checkpoint may say otherwise
)


@dataclass(frozen=True, eq=False)
class ObjectCandidates:
    """The first candidates of one object, and their surrogate inputs."""

    obj: GraspObject
    poses: tuple[GripperPose, ...]
    matrices: np.ndarray
    """Palm poses, shape (P, 4, 4) [m]."""
    source: str
    """``sampler`` or the AnyGrasp file's name."""
    source_index: np.ndarray
    """Row of each candidate in its source, shape (P,)."""
    clouds: np.ndarray | None = None
    """Partial clouds in the gripper frame, (P, N, 3) [m]; None until :meth:`with_clouds`."""
    com: np.ndarray | None = None
    """Object COM in the gripper frame, (P, 3) [m]."""

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def up(self) -> np.ndarray:
        """World vertical in the gripper frame, (P, 3)."""
        return gripper_up(self.matrices)

    def with_clouds(self, n_points: int, seed: int) -> ObjectCandidates:
        """The same candidates with their partial clouds (``n_points`` each) and COM.

        A pose whose box holds too few surface points is dropped (the dataset drops it too).
        """
        keep, clouds, com = [], [], []
        for i, (pose, T) in enumerate(zip(self.poses, self.matrices, strict=True)):
            rng = np.random.default_rng([seed, i])
            try:
                cloud = partial_cloud(self.obj, T, pose.openings, rng, n=n_points)
            except PoseError:
                continue
            keep.append(i)
            clouds.append(cloud.points)
            com.append(to_gripper(T, scene_offset(self.obj)[None])[0])
        if not keep:
            raise PoseError(f"{self.obj.name}: no candidate has a partial cloud inside the fingers' box")
        k = np.asarray(keep)
        return ObjectCandidates(
            self.obj,
            tuple(self.poses[i] for i in keep),
            self.matrices[k],
            self.source,
            self.source_index[k],
            np.stack(clouds),
            np.stack(com),
        )


def object_candidates(
    obj: GraspObject,
    n: int,
    *,
    seed: int = 0,
    anygrasp: str | Path | None = None,
    cache_dir: str | Path | None = None,
) -> ObjectCandidates:
    """The first ``n`` candidates of ``obj``; :class:`PoseError` when none is accepted.

    AnyGrasp's (when ``anygrasp/OBJECT.npz`` exists, in the authors' row order) or the sampler's.
    """
    path = Path(anygrasp) / f"{obj.name}.npz" if anygrasp is not None else None
    if path is not None and path.is_file():
        cands = import_anygrasp(
            obj,
            load_external(path),
            load_mesh(obj.name).vertices,
            seed=seed,
            source=path.name,
            cache_dir=cache_dir,
        )
        order = np.argsort(cands.source_index, kind="stable")
    else:
        cands = sample_poses(obj, n, seed=seed, cache_dir=cache_dir)
        order = np.arange(len(cands))
    if len(cands) == 0:
        why = ", ".join(f"{k} {v}" for k, v in sorted(cands.rejected.items(), key=lambda kv: -kv[1])[:3])
        raise PoseError(f"{obj.name}: no grasp candidate accepted ({why or 'none tried'})")
    order = order[:n]
    poses = tuple(to_gripper_pose(cands, int(i)) for i in order)
    return ObjectCandidates(
        obj,
        poses,
        np.asarray(cands.matrices)[order],
        str(cands.source),
        np.asarray(cands.source_index)[order],
    )


def predict_candidates(
    surrogate, cands: ObjectCandidates, design, rho: float
) -> tuple[np.ndarray, np.ndarray]:
    """The surrogate's (success score, success) for every candidate of one object (clouds needed).

    ``surrogate`` is a :class:`mjcodesign.surrogate.Surrogate`; ``design`` a Stiffness; ``rho`` the
    object's density [kg/m³].
    """
    from mjcodesign.surrogate import GraspBatch, Poses

    if cands.clouds is None:
        raise PoseError(f"{cands.obj.name}: the surrogate needs the candidates' clouds (with_clouds)")
    volume = cands.obj.mass / cands.obj.density
    poses = Poses(cands.clouds, cands.com, cands.up, np.full(len(cands), volume))
    p = len(cands)
    pred = surrogate.predict(
        GraspBatch(poses, np.arange(p), np.full(p, rho), np.tile(design.log_e.ravel(), (p, 1)))
    )
    return np.asarray(pred.success_score, dtype=float), np.asarray(pred.success, dtype=bool)
