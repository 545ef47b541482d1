"""Batched headless data generation, and the dataset it writes and reads back.

Import from here (``from mjcodesign.data import generate``): each name has this one public path.

- :mod:`~mjcodesign.data.config`: :class:`DatagenConfig` (what decides the rows) and its parsers;
- :mod:`~mjcodesign.data.sampling`: seeds keyed by (object, pose), the design samplers;
- :mod:`~mjcodesign.data.cloud`: the partial point cloud in the fingers' bounding box;
- :mod:`~mjcodesign.data.schema`: the tables' Arrow schemas and column meanings;
- :mod:`~mjcodesign.data.tasks`: preparing an object, running a shard (:class:`Worker`);
- :mod:`~mjcodesign.data.cells`: cells of K perturbed rollouts (``--perturbations``) and their labels;
- :mod:`~mjcodesign.data.executors`: in-process, process-pool and Ray execution;
- :mod:`~mjcodesign.data.store`: the dataset folder, its manifest and crash-safe writes;
- :mod:`~mjcodesign.data.generate`: :func:`generate`, the resumable driver;
- :mod:`~mjcodesign.data.reader`: :func:`open_dataset` and :func:`summarize` (no torch);
- :mod:`~mjcodesign.data.rows`: :class:`PoseRows`, the type of pose rows, and :func:`read_poses`.
"""

from mjcodesign.data.cloud import PartialCloud, fingers_box, gripper_up, partial_cloud
from mjcodesign.data.config import (
    BACKENDS,
    CLOUD_POINTS,
    SAMPLERS,
    SCHEMA_VERSION,
    DatagenConfig,
    DensitySpec,
    parse_density_spec,
    parse_perturbations,
    parse_tendon,
    resolve_objects,
)
from mjcodesign.data.generate import Event, generate
from mjcodesign.data.reader import (
    DESIGN_GROUPS,
    Dataset,
    design_group,
    label_spread,
    open_dataset,
    plot_success,
    summarize,
)
from mjcodesign.data.rows import PoseRows, StoredPoses, read_poses
from mjcodesign.data.sampling import PoseStreams, object_pose_seed, sample_designs
from mjcodesign.data.schema import COLUMNS, POSES, REJECTED, ROLLOUTS, SAMPLES, SAMPLES_P
from mjcodesign.data.store import MANIFEST, DatasetDir, project_version
from mjcodesign.data.tasks import ObjectTask, ShardTask, Worker, shard_key

__all__ = [
    "BACKENDS",
    "CLOUD_POINTS",
    "COLUMNS",
    "DESIGN_GROUPS",
    "MANIFEST",
    "POSES",
    "REJECTED",
    "ROLLOUTS",
    "SAMPLERS",
    "SAMPLES",
    "SAMPLES_P",
    "SCHEMA_VERSION",
    "Dataset",
    "DatasetDir",
    "DatagenConfig",
    "DensitySpec",
    "Event",
    "ObjectTask",
    "PartialCloud",
    "PoseRows",
    "PoseStreams",
    "ShardTask",
    "StoredPoses",
    "Worker",
    "design_group",
    "fingers_box",
    "generate",
    "gripper_up",
    "label_spread",
    "object_pose_seed",
    "open_dataset",
    "parse_density_spec",
    "parse_perturbations",
    "parse_tendon",
    "partial_cloud",
    "plot_success",
    "project_version",
    "read_poses",
    "resolve_objects",
    "sample_designs",
    "shard_key",
    "summarize",
]
