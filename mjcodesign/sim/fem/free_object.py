"""The grasp's free rigid object for the FEM: 6 DOF, its mesh for the fingers, its points for the ground.

`FreeObject` takes a `mjcodesign.objects.GraspObject` as the MuJoCo grasp scene does
(`mjcodesign.scenarios.grasp.compile_scene`): mass and inertia about the COM from the mesh and density,
the body frame at the COM, at rest with its lowest collision point `REST_GAP` above the ground.

* Finger contact uses the watertight mesh: a ``wp.Mesh`` in the body frame, queried at each finger
  vertex moved into that frame (`mjcodesign.sim.fem.grasp_kernels.object_query`). MuJoCo collides the
  convex pieces instead; they fill the mesh's concavities.
* Ground contact uses the convex pieces' vertices (MuJoCo's collision geometry), each a penalty point
  with the authors' per-particle constants: ke = 1e3 N/m, kd = 10 N·s/m, μ = 1.
"""

from __future__ import annotations

import numpy as np

from mjcodesign.errors import DesignError
from mjcodesign.objects import GraspObject
from mjcodesign.optional import import_warp
from mjcodesign.scenarios.grasp import REST_GAP, object_vertices

__all__ = ["FreeObject", "GROUND_CONTACT"]

GROUND_CONTACT = (1e3, 10.0, 1.0)
"""Object–ground penalty per contact point: stiffness [N/m], damping [N·s/m], Coulomb μ (the authors'
ke, kd and μ, per particle, from their simulator's code)."""
_BOX_MARGIN = 1e-6
"""Widening [m] of the body-frame bounding box that gates the mesh query (round-off of the transform)."""


class FreeObject:
    """A `GraspObject` as a free rigid body: constants, its Warp mesh and its initial state."""

    def __init__(self, obj: GraspObject, *, device: str = "cpu"):
        wp = self.wp = import_warp()
        v = np.asarray(obj.mesh.vertices, dtype=float)
        f = np.asarray(obj.mesh.faces, dtype=np.int32)
        if not (np.isfinite(obj.mass) and obj.mass > 0):
            raise DesignError(f"object {obj.name} has no positive mass")
        self.name = obj.name
        self.mass = float(obj.mass)
        """[kg]."""
        self.inertia = np.asarray(obj.inertia, dtype=float)
        """Inertia about the COM in the body frame [kg·m²], shape (3, 3)."""
        eig = np.linalg.eigvalsh(self.inertia)
        if not eig.min() > 0:
            raise DesignError(f"object {obj.name} has a singular inertia tensor")
        radius = float(np.max(np.linalg.norm(v, axis=1)))
        self.inv_mass_bound = 1.0 / self.mass + radius**2 / float(eig.min())
        """1/m + r²/I_min [1/kg]: the largest velocity change per unit impulse at any surface point."""
        self.points = object_vertices(obj)
        """Ground contact points in the body frame [m] (the convex pieces' vertices), (k, 3)."""
        self.start = np.array([0.0, 0.0, REST_GAP - float(self.points[:, 2].min())])
        """COM at t = 0 [m], as in the MuJoCo scene."""
        self.lower = v.min(axis=0) - _BOX_MARGIN
        self.upper = v.max(axis=0) + _BOX_MARGIN
        self.mesh_points = wp.array(v, dtype=wp.vec3d, device=device)
        self.mesh_faces = wp.array(f, dtype=wp.vec3i, device=device)
        self.mesh = wp.Mesh(
            points=wp.array(v, dtype=wp.vec3, device=device),
            indices=wp.array(f.ravel(), dtype=wp.int32, device=device),
        )
        self.ground_points = wp.array(self.points, dtype=wp.vec3d, device=device)
