"""A static rigid object for the FEM's contact: a closed triangle mesh in the world frame."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mjcodesign.errors import DesignError

__all__ = ["RigidObject"]


@dataclass(frozen=True)
class RigidObject:
    """A static closed triangle mesh in the world frame: vertices [m] (n, 3), outward faces (m, 3)."""

    vertices: np.ndarray
    faces: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=float)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
            raise DesignError("object vertices must be a finite (n, 3) array")
        if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= len(v):
            raise DesignError("object faces must be (m, 3) indices into the vertices")
        # Outward winding: the signed volume of a closed mesh is positive.
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() <= 0:
            raise DesignError("object mesh must be closed with outward (counter-clockwise) faces")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    @classmethod
    def box(cls, center, half_extents, rotation: np.ndarray | None = None) -> RigidObject:
        """A box [m] centred at ``center`` with ``half_extents``, rotated by ``rotation`` (3×3)."""
        import trimesh

        h = np.asarray(half_extents, dtype=float)
        if not (np.isfinite(h).all() and (h > 0).all()):
            raise DesignError(f"box half extents must be positive, got {h}")
        m = trimesh.creation.box(extents=2 * h)
        R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
        return cls(m.vertices @ R.T + np.asarray(center, dtype=float), m.faces)
