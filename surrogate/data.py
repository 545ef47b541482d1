"""The surrogate's data: a dataset folder as arrays, its splits, normalisation, and a torch ``Dataset``.

:func:`load_grasp_data` reads a dataset written by :func:`mjcodesign.data.generate` into
:class:`GraspData`: one row per (object, pose) with its partial point cloud, and one row per sample
(rollout) with its 22 ln E, density and the 10 outputs. Everything is in the gripper (palm) frame, as
the dataset stores it (``mjcodesign.data.schema``).

Inputs and outputs of the network:

* the cloud, centred on its mean and scaled to a unit radius (the authors' ``normalize_point_cloud``),
  with the COM moved by the same transform (:func:`normalize_clouds`);
* 22 ln E and the density, z-scored with statistics of the training split only (the authors z-score
  ln K and keep their density raw, but theirs is 1–10 and ours is 100–400 kg/m³);
* the pose's frame (:func:`frame_inputs`, z-scored): the world's vertical in the gripper frame (3),
  and the cloud's centre (3) and radius (1), which the normalisation takes out of the PointNet's input.
  The authors' data are in a y-up world frame, so gravity is implicit there; ours are in the gripper
  frame, where a top and a side grasp of the same object differ only by it, and an object's weight
  depends on its size (:attr:`~mjcodesign.surrogate.model.ModelConfig.frame_inputs`);
* outputs: body force (6) and displacement (3), z-scored (training split), and the ground contact
  flag (0/1, a logit for a binary cross-entropy).

Splits (:func:`split`): ``object`` holds out whole objects for the test (the default: objects the
network never saw) and early-stops on held-out poses of the training objects; ``random`` is the
paper's 80/20 split by sample, which leaks poses between training and test. :func:`first_poses`
cuts a split's training and validation rows to the first N poses of each object (a learning curve
over poses), its test rows left whole.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from mjcodesign.data import Dataset, PoseRows, StoredPoses, open_dataset, read_poses
from mjcodesign.design.stiffness import N_LOG_E
from mjcodesign.errors import DatasetError, DesignError, OutputError

__all__ = [
    "N_OUTPUTS",
    "N_REGRESSION",
    "OUTPUT_NAMES",
    "SPLITS",
    "GraspData",
    "GraspDataset",
    "Normalizer",
    "Split",
    "TrainBatch",
    "cloud_frame",
    "design_inputs",
    "first_poses",
    "fold_splits",
    "frame_inputs",
    "load_grasp_data",
    "normalize_clouds",
    "pose_batches",
    "pose_rank",
    "split",
    "subsample",
]

N_REGRESSION = 9
"""Regressed outputs: body force (torque 3 [N m], force 3 [N]) and displacement (3 [m])."""
N_OUTPUTS = N_REGRESSION + 1
"""All outputs: the regressed ones, then the ground contact."""
OUTPUT_NAMES = (
    "torque_x", "torque_y", "torque_z", "force_x", "force_y", "force_z",
    "displacement_x", "displacement_y", "displacement_z", "ground_contact",
)  # fmt: skip
SPLITS = ("object", "random")
_MIN_STD = 1e-6  # the authors' floor on a standard deviation
_MIN_RADIUS = 1e-6  # [m] the authors' floor on a cloud's radius


@dataclass(frozen=True, eq=False)
class GraspData:
    """A dataset's rows as arrays; P poses, S samples. Vectors in the gripper frame."""

    stored: StoredPoses
    """The poses table (:func:`mjcodesign.data.read_poses`): every stored pose, sampled or not."""
    pose: np.ndarray
    """Pose row of each sample, shape (S,)."""
    log_e: np.ndarray
    """ln(E / Pa), shape (S, 22)."""
    density: np.ndarray
    """[kg/m³], shape (S,)."""
    outputs: np.ndarray
    """Body force (6), displacement (3), ground contact (0/1), shape (S, 10)."""
    success: np.ndarray
    """The simulator's success flag, shape (S,)."""
    lift: float
    """The scenario's lift [m]."""
    lifted_fraction: float
    """Success needs a rise of this fraction of the lift (:class:`~mjcodesign.scenarios.GraspScenario`)."""
    manifest: dict
    manifest_sha256: str
    root: Path
    success_p: np.ndarray | None = None
    """Share of the cell's perturbed rollouts that succeed, shape (S,); None for one rollout per cell."""

    @property
    def poses(self) -> PoseRows:
        """The pose rows (:class:`~mjcodesign.data.PoseRows`), shape (P, ...)."""
        return self.stored.rows

    @property
    def clouds(self) -> np.ndarray:
        """Partial point clouds [m], float32, shape (P, N, 3)."""
        return self.stored.rows.clouds

    @property
    def com(self) -> np.ndarray:
        """Object COM [m], shape (P, 3)."""
        return self.stored.rows.com

    @property
    def up(self) -> np.ndarray:
        """World vertical (unit), shape (P, 3): row 2 of the palm rotation."""
        return self.stored.rows.up

    @property
    def palm(self) -> np.ndarray:
        """Palm pose in the world, shape (P, 4, 4) [m]."""
        return self.stored.rows.palms

    @property
    def openings(self) -> np.ndarray:
        """Target openings of the fingers [m], shape (P, 2)."""
        return self.stored.rows.openings

    @property
    def mass(self) -> np.ndarray:
        """Object mass at the pose's density [kg], shape (P,)."""
        return self.stored.mass

    @property
    def pose_density(self) -> np.ndarray:
        """[kg/m³], shape (P,)."""
        return self.stored.density

    @property
    def objects(self) -> np.ndarray:
        """Object name of each pose, shape (P,)."""
        return self.stored.rows.names

    @property
    def pose_keys(self) -> np.ndarray:
        """(object_index, pose_index) of each pose, shape (P, 2)."""
        return self.stored.keys

    @property
    def sample_mass(self) -> np.ndarray:
        """Object mass of each sample [kg], shape (S,) (mass scales with density)."""
        return self.mass[self.pose] * self.density / self.pose_density[self.pose]

    def __len__(self) -> int:
        return len(self.pose)


def _fixed(column, width: int) -> np.ndarray:
    flat = column.combine_chunks().flatten().to_numpy(zero_copy_only=False)
    return np.asarray(flat, dtype=float).reshape(-1, width)


def load_grasp_data(source: str | Path | Dataset, *, perturbed: bool = False) -> GraspData:
    """The samples and poses of a dataset folder (or an open :class:`~mjcodesign.data.Dataset`).

    Raises :class:`OutputError` when it is not a dataset or holds no sample; with ``perturbed``,
    :class:`DatasetError` when its cells are one rollout each (no ``success_p``).
    """
    ds = source if isinstance(source, Dataset) else open_dataset(source)
    if perturbed and not ds.perturbed:
        raise DatasetError(
            f"{ds.root}: one rollout per cell; this needs a perturbed dataset (datagen --perturbations)"
        )
    mpath = ds.root / "manifest.json"
    sha = hashlib.sha256(mpath.read_bytes()).hexdigest()
    samples = ds.samples()
    if samples.num_rows == 0:
        raise OutputError(f"{ds.root}: the dataset holds no sample")
    stored = read_poses(ds)
    row_of = {(int(o), int(p)): i for i, (o, p) in enumerate(stored.keys)}
    s_keys = zip(
        samples.column("object_index").to_numpy(), samples.column("pose_index").to_numpy(), strict=True
    )
    try:
        pose = np.array([row_of[(int(o), int(p))] for o, p in s_keys], dtype=np.int64)
    except KeyError as exc:
        raise OutputError(f"{ds.root}: a sample's pose {exc} is not in the poses table") from None
    contact = samples.column("ground_contact").to_numpy(zero_copy_only=False).astype(float)
    outputs = np.concatenate(
        [
            _fixed(samples.column("body_force"), 6),
            _fixed(samples.column("displacement"), 3),
            contact[:, None],
        ],
        axis=1,
    )
    scenario = ds.manifest["config"]["scenario"]
    return GraspData(
        stored=stored,
        pose=pose,
        log_e=_fixed(samples.column("log_e"), N_LOG_E),
        density=samples.column("density").to_numpy(),
        outputs=outputs,
        success=samples.column("success").to_numpy(zero_copy_only=False).astype(bool),
        lift=float(scenario["lift"]),
        lifted_fraction=float(scenario["lifted_fraction"]),
        manifest=ds.manifest,
        manifest_sha256=sha,
        root=ds.root,
        success_p=samples.column("success_p").to_numpy() if "success_p" in samples.column_names else None,
    )


def cloud_frame(clouds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (P, 3) [m] and radius (P,) [m] of clouds (P, N, 3): their mean, the largest distance to it."""
    c = np.asarray(clouds, dtype=np.float64)
    centre = c.mean(axis=1)
    radius = np.maximum(np.linalg.norm(c - centre[:, None], axis=2).max(axis=1), _MIN_RADIUS)
    return centre, radius


def normalize_clouds(clouds: np.ndarray, com: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Clouds (P, N, 3) centred on their mean and scaled to unit radius; the COM (P, 3) moved alike.

    As the authors' ``normalize_point_cloud``: ``(x - mean) / max |x - mean|`` per cloud, the same
    centre and scale applied to the COM. Returns float32 arrays of the input shapes.
    """
    centre, radius = cloud_frame(clouds)
    pts = (np.asarray(clouds, dtype=np.float64) - centre[:, None]) / radius[:, None, None]
    com_n = (np.asarray(com, dtype=np.float64) - centre) / radius[:, None]
    return pts.astype(np.float32), com_n.astype(np.float32)


def frame_inputs(clouds: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The pose's frame (P, 7): world vertical (3), cloud centre (3) [m] and radius (1) [m], gripper frame."""
    centre, radius = cloud_frame(clouds)
    return np.concatenate([np.asarray(up, dtype=float), centre, radius[:, None]], axis=1)


@dataclass(frozen=True)
class Split:
    """Sample indices of the training, validation (early stopping) and test rows."""

    mode: str
    train: np.ndarray
    val: np.ndarray
    test: np.ndarray
    test_objects: tuple[str, ...] = ()
    """Objects held out for the test (``object`` mode)."""

    def as_dict(self) -> dict:
        """Sizes and held-out objects, JSON-ready."""
        return {
            "mode": self.mode,
            "train": len(self.train),
            "val": len(self.val),
            "test": len(self.test),
            "test_objects": list(self.test_objects),
        }


def split(
    data: GraspData,
    mode: str = "object",
    *,
    test_fraction: float = 0.2,
    val_fraction: float = 0.1,
    seed: int = 0,
) -> Split:
    """Training, validation and test rows of ``data``.

    ``object``: ``ceil(test_fraction · objects)`` objects (a seeded draw) are the test; of the other
    objects' poses, ``val_fraction`` (a seeded draw, whole poses) are the validation. ``random``: the
    paper's split, ``test_fraction`` of the samples at random, then ``val_fraction`` of the rest.
    Raises :class:`DesignError` when a part would be empty.
    """
    if mode not in SPLITS:
        raise DesignError(f"unknown split {mode!r}: choose from {', '.join(SPLITS)}")
    if not (0 < test_fraction < 1 and 0 < val_fraction < 1):
        raise DesignError("test and validation fractions must be in (0, 1)")
    rng = np.random.default_rng(seed)
    if mode == "object":
        names = np.array(sorted(set(data.objects[data.pose])), dtype=object)
        if len(names) < 2:
            raise DesignError(f"an object split needs two objects or more, the dataset has {len(names)}")
        n_test = min(len(names) - 1, max(1, math.ceil(test_fraction * len(names))))
        return _hold_out(data, mode, tuple(rng.permutation(names)[:n_test]), rng, val_fraction)
    perm = rng.permutation(len(data))
    n_test = int(round(test_fraction * len(data)))
    test, rest = perm[:n_test], perm[n_test:]
    n_val = int(round(val_fraction * len(rest)))
    return _checked(Split(mode, np.sort(rest[n_val:]), np.sort(rest[:n_val]), np.sort(test)))


def _checked(parts: Split) -> Split:
    if min(len(parts.train), len(parts.val), len(parts.test)) == 0:
        raise DesignError(
            f"the {parts.mode} split leaves a part empty "
            f"(train {len(parts.train)}, val {len(parts.val)}, test {len(parts.test)})"
        )
    return parts


def _hold_out(data: GraspData, mode: str, held, rng: np.random.Generator, val_fraction: float) -> Split:
    """The samples of objects ``held`` as the test; ``val_fraction`` of the other poses (seeded) as validation."""
    test_pose = np.isin(data.objects, held)
    train_poses = np.flatnonzero(~test_pose & np.isin(np.arange(len(data.objects)), data.pose))
    n_val = max(1, int(round(val_fraction * len(train_poses))))
    val_pose = np.zeros(len(data.objects), dtype=bool)
    val_pose[rng.permutation(train_poses)[:n_val]] = True
    s_test, s_val = test_pose[data.pose], val_pose[data.pose]
    train = np.flatnonzero(~s_test & ~s_val)
    return _checked(Split(mode, train, np.flatnonzero(s_val), np.flatnonzero(s_test), tuple(sorted(held))))


def fold_splits(
    data: GraspData, fold_of: Mapping[str, int], *, val_fraction: float = 0.1, seed: int = 0
) -> list[Split]:
    """One object-level split per fold: fold k's objects are its test, so each object is held out once.

    ``fold_of`` maps every object of ``data`` to its fold (0..K-1; objects it names that the dataset
    lacks are ignored); a fold holding none of the dataset's objects is left out. Each fold's
    validation rows are ``val_fraction`` of its training objects' poses (seeded by ``seed`` and the
    fold). Raises :class:`DesignError` for an object without a fold or fewer than two non-empty folds.
    """
    if not 0 < val_fraction < 1:
        raise DesignError("the validation fraction must be in (0, 1)")
    names = sorted(set(data.objects[data.pose]))
    missing = [n for n in names if n not in fold_of]
    if missing:
        raise DesignError(f"no fold for the dataset's object(s) {', '.join(missing[:5])}")
    folds = sorted({int(fold_of[n]) for n in names})
    if len(folds) < 2:
        raise DesignError(
            f"K-fold training needs objects in two folds or more, the dataset fills {len(folds)}"
        )
    return [
        _hold_out(
            data,
            f"fold{k}",
            tuple(n for n in names if int(fold_of[n]) == k),
            np.random.default_rng([seed, k]),
            val_fraction,
        )
        for k in folds
    ]


def subsample(parts: Split, fraction: float, *, seed: int = 0) -> Split:
    """``parts`` with ``fraction`` of its training rows (a seeded draw of samples), the rest unchanged."""
    if not 0 < fraction <= 1:
        raise DesignError(f"a data fraction is in (0, 1], got {fraction}")
    keep = max(1, int(round(fraction * len(parts.train))))
    rows = np.random.default_rng(seed).choice(parts.train, size=keep, replace=False)
    return dataclasses.replace(parts, train=np.sort(rows))


def pose_rank(data: GraspData) -> np.ndarray:
    """Each pose's place among its object's poses with samples, in ``pose_index`` order, shape (P,).

    0 is the object's first sampled pose; a pose without samples (a failed or rejected shard) is -1.
    """
    keys = data.pose_keys
    sampled = np.zeros(len(keys), dtype=bool)
    sampled[data.pose] = True
    rows = np.flatnonzero(sampled)
    rows = rows[np.lexsort((keys[rows, 1], keys[rows, 0]))]
    obj = keys[rows, 0]
    starts = np.flatnonzero(np.diff(obj, prepend=-1))
    first = np.repeat(starts, np.diff(np.append(starts, len(rows))))
    rank = np.full(len(keys), -1, dtype=np.int64)
    rank[rows] = np.arange(len(rows)) - first
    return rank


def first_poses(data: GraspData, parts: Split, n: int) -> Split:
    """``parts`` with its training and validation rows cut to the first ``n`` poses of each object.

    The poses of an object count in :func:`pose_rank` order (``pose_index``, poses with samples only);
    every sample (design) of a kept pose is kept, and an object of ``n`` poses or fewer keeps all of
    them. The split (its held-out objects, its validation poses) is drawn before the cut, so it is the
    same for every ``n``, and a smaller ``n``'s rows are a subset of a larger one's. The test rows are
    left whole, so that networks trained on different ``n`` are scored on the same held-out rows.
    :class:`DesignError` for ``n`` not an integer >= 1, or no training or no validation row left (a
    small ``n`` may keep none of the validation poses).
    """
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise DesignError(f"poses per object must be an integer >= 1, got {n!r}")
    keep = pose_rank(data)[data.pose] < n
    cut = dataclasses.replace(parts, train=parts.train[keep[parts.train]], val=parts.val[keep[parts.val]])
    empty = [name for name in ("train", "val") if len(getattr(cut, name)) == 0]
    if empty:
        raise DesignError(
            f"the first {n} poses of each object hold no {' and no '.join(empty)} row of the {parts.mode} "
            f"split (of {len(parts.train)} training and {len(parts.val)} validation rows): more poses per "
            "object, or another seed"
        )
    return cut


@dataclass(frozen=True, eq=False)
class Normalizer:
    """Statistics of the training split: ln E and density z-scores, z-scores of the 9 regressed outputs."""

    log_e_mean: np.ndarray
    log_e_std: np.ndarray
    density_mean: float
    density_std: float
    out_mean: np.ndarray
    """Of body force (6) and displacement (3), physical units."""
    out_std: np.ndarray
    frame_mean: np.ndarray
    """Of :func:`frame_inputs` (7)."""
    frame_std: np.ndarray

    @classmethod
    def fit(cls, data: GraspData, rows: np.ndarray) -> Normalizer:
        """Statistics of the samples ``rows`` (the training split)."""
        y = data.outputs[rows, :N_REGRESSION]
        frame = frame_inputs(data.clouds, data.up)[data.pose[rows]]
        return cls(
            log_e_mean=data.log_e[rows].mean(axis=0),
            log_e_std=np.maximum(data.log_e[rows].std(axis=0), _MIN_STD),
            density_mean=float(data.density[rows].mean()),
            density_std=float(max(data.density[rows].std(), _MIN_STD)),
            out_mean=y.mean(axis=0),
            out_std=np.maximum(y.std(axis=0), _MIN_STD),
            frame_mean=frame.mean(axis=0),
            frame_std=np.maximum(frame.std(axis=0), _MIN_STD),
        )

    def as_dict(self) -> dict:
        """JSON-ready (lists of floats)."""
        return {k: np.asarray(v).tolist() for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, d: dict) -> Normalizer:
        """Inverse of :meth:`as_dict`."""
        return cls(
            log_e_mean=np.asarray(d["log_e_mean"], dtype=float),
            log_e_std=np.asarray(d["log_e_std"], dtype=float),
            density_mean=float(d["density_mean"]),
            density_std=float(d["density_std"]),
            out_mean=np.asarray(d["out_mean"], dtype=float),
            out_std=np.asarray(d["out_std"], dtype=float),
            frame_mean=np.asarray(d["frame_mean"], dtype=float),
            frame_std=np.asarray(d["frame_std"], dtype=float),
        )

    def targets(self, outputs: np.ndarray) -> np.ndarray:
        """Training targets (S, 10): z-scored body force and displacement, contact 0/1."""
        y = np.array(outputs, dtype=float)
        y[:, :N_REGRESSION] = (y[:, :N_REGRESSION] - self.out_mean) / self.out_std
        return y.astype(np.float32)


def design_inputs(norm: Normalizer, com_n, frame, log_e, density, use_frame: bool) -> np.ndarray:
    """Per-sample inputs besides the cloud feature: z(ln E) 22, COM 3, z(density) 1[, z(frame) 7], float32."""
    cols = [
        (np.asarray(log_e, dtype=float) - norm.log_e_mean) / norm.log_e_std,
        np.asarray(com_n, dtype=float),
        ((np.asarray(density, dtype=float) - norm.density_mean) / norm.density_std)[:, None],
    ]
    if use_frame:
        cols.append((np.asarray(frame, dtype=float) - norm.frame_mean) / norm.frame_std)
    return np.concatenate(cols, axis=1).astype(np.float32)


@dataclass(frozen=True, eq=False)
class TrainBatch:
    """A training batch: the U unique poses' clouds and B samples pointing into them."""

    clouds: torch.Tensor
    """Normalised clouds, shape (U, 3, N)."""
    pose_of: torch.Tensor
    """Row of ``clouds`` for each sample, shape (B,), int64."""
    x: torch.Tensor
    """Inputs besides the cloud, shape (B, D)."""
    y: torch.Tensor
    """Targets (:meth:`Normalizer.targets`), shape (B, 10)."""


class GraspDataset(torch.utils.data.Dataset):
    """Samples ``rows`` of ``data`` as network inputs; a batch computes each pose's cloud once.

    ``dataset[i]`` is one sample's :class:`TrainBatch`; ``dataset.__getitems__(idx)`` (what a
    ``DataLoader`` with a batch sampler calls) gathers the unique poses of ``idx`` once.
    """

    def __init__(self, data: GraspData, rows: np.ndarray, norm: Normalizer, *, frame: bool = True):
        self.rows = np.asarray(rows, dtype=np.int64)
        clouds, com_n = normalize_clouds(data.clouds, data.com)
        self.clouds = torch.from_numpy(np.ascontiguousarray(clouds.transpose(0, 2, 1)))
        p = data.pose[self.rows]
        self.pose = p
        fr = frame_inputs(data.clouds, data.up)[p]
        x = design_inputs(norm, com_n[p], fr, data.log_e[self.rows], data.density[self.rows], frame)
        self.x = torch.from_numpy(x)
        self.y = torch.from_numpy(norm.targets(data.outputs[self.rows]))

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int) -> TrainBatch:
        return self.__getitems__([i])

    def __getitems__(self, idx) -> TrainBatch:
        idx = np.asarray(idx, dtype=np.int64)
        unique, inverse = np.unique(self.pose[idx], return_inverse=True)
        t = torch.from_numpy(idx)
        return TrainBatch(
            self.clouds[torch.from_numpy(unique)], torch.from_numpy(inverse.ravel()), self.x[t], self.y[t]
        )

    def batches(self, batch_size: int) -> list[TrainBatch]:
        """The whole set in pose-contiguous batches (for evaluation)."""
        order = np.argsort(self.pose, kind="stable")
        return [self.__getitems__(order[i : i + batch_size]) for i in range(0, len(order), batch_size)]


def pose_batches(
    pose: np.ndarray, batch_size: int, rng: np.random.Generator, group: int = 0
) -> list[np.ndarray]:
    """One epoch's batches of sample positions, grouped by pose so that a batch holds few poses.

    Each pose's samples (shuffled) are cut into chunks of ``group`` (0: the whole pose), the chunks
    are shuffled and laid end to end, and the sequence is cut into batches of ``batch_size``; a last
    batch shorter than half of it joins the one before (BatchNorm needs more than one sample).
    """
    pose = np.asarray(pose)
    by_pose = np.argsort(pose, kind="stable")
    starts = np.flatnonzero(np.diff(pose[by_pose], prepend=-1))
    chunks = []
    for members in np.split(by_pose, starts[1:]):
        members = rng.permutation(members)
        size = group if group > 0 else len(members)
        chunks.extend(members[i : i + size] for i in range(0, len(members), size))
    order = np.concatenate([chunks[i] for i in rng.permutation(len(chunks))])
    batches = [order[i : i + batch_size] for i in range(0, len(order), batch_size)]
    if len(batches) > 1 and len(batches[-1]) < batch_size // 2:
        last = batches.pop()
        batches[-1] = np.concatenate([batches[-1], last])
    return batches
