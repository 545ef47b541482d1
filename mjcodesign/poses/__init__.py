"""Grasp candidates: an antipodal sampler, AnyGrasp/GraspNet import, and the rigid-counterpart refinement.

Import from here (``from mjcodesign.poses import sample_poses``): each name has this one public path.

- :mod:`~mjcodesign.poses.gripper`: the palm frame and the fingers' rigid counterpart as points;
- :mod:`~mjcodesign.poses.sdf`: signed distance to the object mesh (Warp, imported lazily);
- :mod:`~mjcodesign.poses.refine`: the paper's L_init refinement of a pose's offset and openings;
- :mod:`~mjcodesign.poses.grid`: that distance on a grid, interpolated in numpy, cached on disk;
- :mod:`~mjcodesign.poses.candidates`: :class:`Candidates`, their file and provenance;
- :mod:`~mjcodesign.poses.accept`: the checks every pose passes, and refine-and-rank;
- :mod:`~mjcodesign.poses.sampler`: the antipodal sampler;
- :mod:`~mjcodesign.poses.external`: AnyGrasp/GraspNet files in the authors' camera frame.
"""

from mjcodesign.poses.accept import OPEN_CLEARANCE, Rejection, refine_and_rank, start_check
from mjcodesign.poses.candidates import (
    FILE_FORMAT,
    MAX_PENETRATION,
    NOISE_ROTATION,
    NOISE_TRANSLATION,
    Candidates,
    approach_spread_deg,
    augment_poses,
    load_numpy,
    read_candidates,
    to_gripper_pose,
)
from mjcodesign.poses.external import ANYGRASP_DEPTH, anygrasp_to_world, import_anygrasp, load_external
from mjcodesign.poses.gripper import COARSE_EDGE, DENSE_EDGE, RigidGripper, palm_frame, rotvec, scene_offset
from mjcodesign.poses.refine import (
    DEPTH_CLEARANCE,
    LOSS_THRESHOLD,
    MAX_FINGER_GAP,
    T_RANGE,
    W_D,
    W_P,
    W_T,
    Refined,
    approach_depth,
    refine,
)
from mjcodesign.poses.sampler import FRICTION, SamplerOptions, antipodal_pairs, ray_pairs, sample_poses
from mjcodesign.poses.sdf import MeshSDF

__all__ = [
    "ANYGRASP_DEPTH",
    "COARSE_EDGE",
    "DEPTH_CLEARANCE",
    "FILE_FORMAT",
    "DENSE_EDGE",
    "FRICTION",
    "LOSS_THRESHOLD",
    "MAX_FINGER_GAP",
    "MAX_PENETRATION",
    "NOISE_ROTATION",
    "NOISE_TRANSLATION",
    "OPEN_CLEARANCE",
    "T_RANGE",
    "W_D",
    "W_P",
    "W_T",
    "Candidates",
    "MeshSDF",
    "Refined",
    "RigidGripper",
    "SamplerOptions",
    "Rejection",
    "antipodal_pairs",
    "approach_depth",
    "anygrasp_to_world",
    "approach_spread_deg",
    "augment_poses",
    "import_anygrasp",
    "load_numpy",
    "load_external",
    "palm_frame",
    "read_candidates",
    "refine",
    "refine_and_rank",
    "ray_pairs",
    "rotvec",
    "sample_poses",
    "scene_offset",
    "start_check",
    "to_gripper_pose",
]
