"""The Warp tet-FEM reference of one finger: statics, explicit dynamics, contact and their gradients.

* `FemFinger` (``finger``): the finger, built on `body` (mesh, material, forces, loads) and `statics`
  (Newton, adjoint gradient); its cantilever and curl scenarios and its explicit rollout on the ground.
* `FemContact` (``contact``) with a static `RigidObject` (``rigid``): explicit contact dynamics and the
  gradient of the mean contact force (``adjoint``); `grasp_scene` (``grasp``) is the single-finger
  grasp, `press_fem` (``press``) the press scenario's static equilibrium.
* `FemBackend` (``backend``): the FEM behind the simulator interface (``get_backend("fem")``).
* Kernels: ``kernels`` (elasticity) and ``contact_kernels`` (tendon, contact, the explicit step); they
  import Warp, so they are loaded when a finger is built, never by importing this package.
"""

from mjcodesign.sim.fem.backend import FemBackend
from mjcodesign.sim.fem.contact import FemContact
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.grasp import grasp_scene
from mjcodesign.sim.fem.mesh import FingerMesh, mesh_finger
from mjcodesign.sim.fem.options import FemDynamics, FemOptions
from mjcodesign.sim.fem.press import press_fem
from mjcodesign.sim.fem.results import FemCantilever, FemContactRun, FemCurl, FemPress
from mjcodesign.sim.fem.rigid import RigidObject

__all__ = [
    "FemFinger",
    "FemOptions",
    "FemDynamics",
    "FemContact",
    "RigidObject",
    "grasp_scene",
    "press_fem",
    "mesh_finger",
    "FingerMesh",
    "FemBackend",
    "FemCantilever",
    "FemCurl",
    "FemPress",
    "FemContactRun",
]
