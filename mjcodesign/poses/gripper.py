"""The rigid counterpart of the fingers as surface points, and the palm-frame geometry of the poses.

Frames. Every pose is a palm pose in the grasp scene's world (:func:`mjcodesign.scenarios.grasp.build_scene`):
the object's COM at world x = y = 0, its lowest point ``REST_GAP`` above the ground (z = 0), the
object mesh keeping its source orientation (:func:`scene_offset`). The palm frame is
:class:`mjcodesign.models.types.GripperPose`'s: ``-z`` is the approach, ``y`` the closing axis (finger A
at ``+y``), fingers hang to ``z = -L``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.models.types import PALM_HALF
from mjcodesign.objects import GraspObject
from mjcodesign.scenarios.grasp import REST_GAP, object_vertices

__all__ = ["COARSE_EDGE", "DENSE_EDGE", "RigidGripper", "palm_frame", "rotvec", "scene_offset"]

COARSE_EDGE = 0.008
"""Refinement point spacing on the finger surfaces [m]."""
DENSE_EDGE = 0.002
"""Check point spacing [m]: features thinner than this can hide between points."""


def scene_offset(obj: GraspObject) -> np.ndarray:
    """World position of the object's COM frame origin [m], as :func:`build_scene` places it."""
    return np.array([0.0, 0.0, REST_GAP - float(object_vertices(obj)[:, 2].min())])


def palm_frame(approach: np.ndarray, closing: np.ndarray) -> np.ndarray:
    """Palm rotations (P, 3, 3): z = −approach, y = closing (made orthogonal), x = y × z."""
    z = -approach / np.linalg.norm(approach, axis=1, keepdims=True)
    y = closing - np.einsum("pk,pk->p", closing, z)[:, None] * z
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    return np.stack([np.cross(y, z), y, z], axis=2)


def rotvec(v: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (P, 3) (Rodrigues)."""
    th = np.linalg.norm(v, axis=1)
    k = v / np.maximum(th, 1e-15)[:, None]
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K = K - K.transpose(0, 2, 1)
    s, c = np.sin(th)[:, None, None], np.cos(th)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * K @ K


def _surface_points(mesh, edge: float) -> np.ndarray:
    """Corners plus about one seeded surface sample per ``edge``² of a convex hull [m] (deterministic)."""
    import trimesh

    count = int(np.ceil(mesh.area / edge**2))
    samples, _ = trimesh.sample.sample_surface(mesh, count, seed=0)
    return np.vstack([mesh.vertices, samples])


def _block_points(design: FingerDesign, edge: float) -> tuple[np.ndarray, np.ndarray]:
    """Surface points of every block (finger frame) and whether each lies on a segment's inner face."""
    import trimesh

    pts, inner = [], []
    for blk in design.blocks():
        v = _surface_points(trimesh.convex.convex_hull(blk.vertices()), edge)
        on_top = v[:, 2] >= blk.height(v[:, 0]) - 1e-6
        pts.append(v)
        inner.append(on_top & (blk.kind is BlockKind.SEGMENT))
    return np.vstack(pts), np.concatenate(inner)


def _palm_points(edge: float) -> np.ndarray:
    import trimesh

    return _surface_points(trimesh.creation.box(extents=2 * PALM_HALF), edge) + [0.0, 0.0, PALM_HALF[2]]


@dataclass
class RigidGripper:
    """Surface points of the rigid counterpart in the palm frame at zero opening [m].

    Finger point (x_f, y_f, z_f) of side σ (A: +1, B: −1) sits at palm (σ y_f, σ (s + h_base − z_f), −x_f)
    for opening s (:func:`mjcodesign.models.spec.finger_frame_quat`), so an opening shifts it by σ s
    along y.
    """

    points: np.ndarray
    """All points at zero opening, shape (n, 3)."""
    side: np.ndarray
    """+1 finger A, −1 finger B, 0 palm, shape (n,)."""
    inner: np.ndarray
    """True on a segment's inner (grasping) face, shape (n,)."""

    @classmethod
    def build(cls, design: FingerDesign, edge: float) -> RigidGripper:
        """Points spaced about ``edge`` [m]; built once per (design, edge), its arrays read-only."""
        return _built(cls, design, float(edge))

    @classmethod
    def _make(cls, design: FingerDesign, edge: float) -> RigidGripper:
        q, inner = _block_points(design, edge)
        parts, sides = [], []
        for s in (1.0, -1.0):
            parts.append(np.c_[s * q[:, 1], s * (design.height_base - q[:, 2]), -q[:, 0]])
            sides.append(np.full(len(q), s))
        palm = _palm_points(edge)
        return cls(
            np.vstack(parts + [palm]),
            np.concatenate(sides + [np.zeros(len(palm))]),
            np.concatenate([inner, inner, np.zeros(len(palm), bool)]),
        )

    def world(self, R: np.ndarray, p: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Points for palm rotations (P, 3, 3), positions (P, 3), openings (P, 2): shape (P, n, 3)."""
        shift = np.where(self.side > 0, s[:, :1], 0.0) + np.where(self.side < 0, s[:, 1:], 0.0)  # (P, n)
        local = self.points[None] + (self.side * shift)[..., None] * np.array([0.0, 1.0, 0.0])
        return np.matmul(local, R.transpose(0, 2, 1)) + p[:, None, :]


@functools.lru_cache(maxsize=16)
def _built(cls, design: FingerDesign, edge: float) -> RigidGripper:
    """:meth:`RigidGripper.build`'s cache (sampling the hulls costs 0.3 s a call).

    Every refinement round and check asks for the same two point sets.
    """
    g = cls._make(design, edge)
    for a in (g.points, g.side, g.inner):
        a.flags.writeable = False
    return g
