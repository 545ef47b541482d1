"""The dataset's tables: Arrow schemas, column documentation, and building a table from columns.

Three tables, each a folder of Parquet files (one file per object or shard):

* ``poses/``: one row per (object, pose), stored once: palm pose, openings, the candidate's source,
  the partial point cloud, COM, mass and density;
* ``samples/``: one row per grasp rollout usable as a training sample;
* ``rejected/``: rollouts that are sample errors (:attr:`Failure.is_sample_error`: diverged,
  implausible, bad pose), with the same columns; they never appear in ``samples/``.

A dataset of K > 1 perturbed rollouts per (pose, design) cell (``datagen --perturbations K``) has one
``samples/`` row per cell with at least one usable rollout (:data:`SAMPLES_P`: the outputs' means over
the cell's usable rollouts in the columns above, then the success probability, the counts and the
spreads), a ``rejected/`` row per cell without one, and a fourth table, ``rollouts/``
(:data:`ROLLOUTS`), one row per rollout of every cell, usable or not.

Vectors are fixed-size lists. Frames: "world" is the grasp scene's (object COM at x = y = 0, resting on
the ground at z = 0); "gripper" is the palm frame of the pose (``-z`` approach, ``y`` closing axis).
No float column may hold NaN or inf (:func:`build_table` refuses it).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from mjcodesign.design.stiffness import N_LOG_E

__all__ = [
    "COLUMNS",
    "DOCUMENTED",
    "POSES",
    "REJECTED",
    "ROLLOUTS",
    "SAMPLES",
    "SAMPLES_P",
    "TABLES",
    "build_table",
    "empty_columns",
    "tables",
]

_F64 = pa.float64()
_F32 = pa.float32()


def _vec(n: int, t=_F64) -> pa.DataType:
    return pa.list_(t, n)


_COLUMNS: dict[str, tuple[pa.DataType, str]] = {
    "object_index": (pa.int32(), "position of the object in the manifest's object list"),
    "object": (pa.string(), "object name"),
    "pose_index": (pa.int32(), "pose of the object (0 = the sampler's best)"),
    "source": (pa.string(), "where the pose came from: 'sampler' (mjcodesign.poses.sample_poses)"),
    "candidate_index": (pa.int32(), "row of the pose in the source's ranked candidates"),
    "candidate_score": (_F64, "the source's score of the pose, in (0, 1]"),
    "palm_pose": (_vec(16), "palm pose in the world, 4x4 row-major [m]"),
    "openings": (_vec(2), "target openings of the two fingers (A, B) [m]"),
    "density": (_F64, "object density [kg/m³]"),
    "mass": (_F64, "object mass at that density [kg]"),
    "com_gripper": (_vec(3), "object COM in the gripper frame at the pose [m]"),
    "point_cloud": (
        pa.list_(_vec(3, _F32)),
        "object surface points inside the fingers' bounding box, gripper frame [m], (N, 3) float32",
    ),
    "cloud_inside": (
        pa.int32(),
        "surface samples inside the box before the draw of N (fewer: points repeat)",
    ),
    "design_index": (pa.int32(), "design of the pose"),
    "log_e": (_vec(N_LOG_E), "ln(E / Pa) of the 22 blocks, finger A base to tip, then finger B"),
    "body_force": (
        _vec(6),
        "fingers' wrench on the object, gripper frame: torque about the COM [N m] (3), force [N] (3)",
    ),
    "displacement": (
        _vec(3),
        "object displacement relative to the palm, grasp to end, gripper frame [m] (Δq)",
    ),
    "ground_contact": (pa.bool_(), "object touches the ground at the end (c_g)"),
    "finger_contact": (pa.bool_(), "a finger touches the object at the end"),
    "lift_height": (_F64, "rise of the object's COM from t = 0 to the end [m]"),
    "success": (pa.bool_(), "lifted, held, off the ground, with finger force"),
    "failure": (pa.string(), "first failure kind (mjcodesign.scenarios.Failure value), 'none' on success"),
    "failures": (pa.list_(pa.string()), "every failure kind"),
    "reason": (pa.string(), "readable reason, 'ok' on success"),
    "backend": (pa.string(), "simulator: mujoco or mjwarp"),
    "wall_time_s": (_F64, "wall time of the rollout (its batch's share) [s]"),
    "seed": (pa.int64(), "the dataset seed"),
    "success_p": (_F64, "share of the cell's usable rollouts that succeed (success = success_p >= 0.5)"),
    "rollouts": (pa.int32(), "usable rollouts of the cell (K, or M where the first K disagree)"),
    "unusable": (
        pa.int32(),
        "rollouts of the cell that are sample errors (diverged, implausible, bad pose), in no mean",
    ),
    "body_force_std": (_vec(6), "standard deviation (ddof 0) of body_force over the usable rollouts"),
    "displacement_std": (_vec(3), "standard deviation (ddof 0) of displacement over the usable rollouts [m]"),
    "lift_height_std": (_F64, "standard deviation (ddof 0) of lift_height over the usable rollouts [m]"),
    "ground_contact_p": (_F64, "share of the usable rollouts ending on the ground (ground_contact: >= 0.5)"),
    "finger_contact_p": (
        _F64,
        "share of the usable rollouts ending in finger contact (finger_contact: >= 0.5)",
    ),
    "draw": (pa.int32(), "perturbed draw of the cell, in the (object, pose)'s stream shared by its designs"),
    "perturbation": (
        _vec(9),
        "the draw: palm offset, world frame [m] (3), palm rotation vector [rad] (3), mass, friction and "
        "tendon factors [-]",
    ),
    "sample_error": (pa.bool_(), "the rollout is a sample error (diverged, implausible, bad pose)"),
}


def _schema(names: str) -> pa.Schema:
    return pa.schema([pa.field(n, _COLUMNS[n][0]) for n in names.split()])


POSES = _schema(
    "object_index object pose_index source candidate_index candidate_score palm_pose openings density mass"
    " com_gripper point_cloud cloud_inside seed"
)
"""One row per (object, pose)."""

SAMPLES = _schema(
    "object_index object pose_index design_index density log_e body_force displacement ground_contact"
    " finger_contact lift_height success failure failures reason backend wall_time_s seed"
)
"""One row per rollout; ``rejected/`` has the same columns."""
REJECTED = SAMPLES

_CELL = (
    " success_p rollouts unusable body_force_std displacement_std lift_height_std ground_contact_p"
    " finger_contact_p"
)
SAMPLES_P = _schema(" ".join(SAMPLES.names) + _CELL)
"""One row per (pose, design) cell of K > 1 rollouts: the columns of :data:`SAMPLES` (the outputs'
means over the usable rollouts), then the cell's success probability, counts and spreads."""
ROLLOUTS = _schema(
    "object_index object pose_index design_index draw perturbation body_force displacement ground_contact"
    " finger_contact lift_height success sample_error failure failures reason wall_time_s seed"
)
"""One row per perturbed rollout of a cell (K > 1), usable or not."""

TABLES = {"poses": POSES, "samples": SAMPLES, "rejected": REJECTED}
"""Table (folder) name -> schema, one rollout per cell."""


def tables(perturbed: bool) -> dict[str, pa.Schema]:
    """Table (folder) name -> schema: :data:`TABLES`, or with K > 1 rollouts per cell its four tables."""
    if not perturbed:
        return TABLES
    return {"poses": POSES, "samples": SAMPLES_P, "rejected": SAMPLES_P, "rollouts": ROLLOUTS}


DOCUMENTED = {
    "poses/": POSES,
    "samples/ and rejected/": SAMPLES,
    "samples/ and rejected/ with --perturbations K > 1 (after the columns above)": _schema(_CELL.strip()),
    "rollouts/ (--perturbations K > 1)": ROLLOUTS,
}
"""The tables as the docs list them (heading -> schema)."""

COLUMNS = {name: doc for name, (_, doc) in _COLUMNS.items()}
"""Meaning and unit of every column (also written into the manifest)."""


def empty_columns(schema: pa.Schema) -> dict[str, list]:
    """A dict of empty lists, one per column of ``schema``, to append rows to."""
    return {name: [] for name in schema.names}


def build_table(columns: dict, schema: pa.Schema) -> pa.Table:
    """A table of ``schema`` from per-column lists or arrays; ValueError if a float is NaN or inf.

    A vector column may be a numpy array of shape (rows, n) (fixed-size lists), and a list of vectors
    one of shape (rows, k, n).
    """
    if set(columns) != set(schema.names):
        raise ValueError(f"columns {sorted(set(columns) ^ set(schema.names))} do not match the schema")
    arrays = []
    for f in schema:
        arr = _to_arrow(columns[f.name], f.type)
        flat = arr
        while pa.types.is_list(flat.type) or pa.types.is_fixed_size_list(flat.type):
            flat = flat.flatten()
        if pa.types.is_floating(flat.type) and len(flat):
            if not np.all(np.isfinite(flat.to_numpy(zero_copy_only=False))):
                raise ValueError(f"column {f.name} holds NaN or inf")
        arrays.append(arr)
    return pa.Table.from_arrays(arrays, schema=schema)


def _to_arrow(values, t: pa.DataType) -> pa.Array:
    if not isinstance(values, np.ndarray) or values.ndim < 2:
        return pa.array(values, type=t)
    rows = len(values)
    if pa.types.is_fixed_size_list(t):
        flat = pa.array(values.reshape(rows * t.list_size), type=t.value_type)
        return pa.FixedSizeListArray.from_arrays(flat, type=t)
    inner_t = t.value_type  # a list of fixed-size vectors: (rows, k, n)
    k = values.shape[1]
    inner = pa.FixedSizeListArray.from_arrays(
        pa.array(values.reshape(-1), type=inner_t.value_type), type=inner_t
    )
    offsets = pa.array(np.arange(rows + 1, dtype=np.int32) * k, type=pa.int32())
    return pa.ListArray.from_arrays(offsets, inner, type=t)
