"""The Warp tet-FEM reference: one finger's statics, dynamics and contact, and the paper's two-finger grasp.

* `FemFinger` (``finger``): the finger, built on `body` (mesh, material, forces, loads) and `statics`
  (Newton, adjoint gradient); its cantilever and curl scenarios and its explicit rollout on the ground.
* `FemContact` (``contact``) with a static `RigidObject` (``rigid``): explicit contact dynamics and the
  gradient of the mean contact force (``adjoint``); `grasp_scene` (``grasp``) is the single-finger
  grasp, `press_fem` (``press``) the press scenario's static equilibrium.
* `FemGrasp` (``gripper_grasp``): the paper's grasp, two fingers (``gripper``) on a palm driven by the
  MuJoCo scenario's controls (``schedule``), a free rigid object (``free_object``), penalty contact;
  its outcome as MuJoCo's (``grasp_outcome``: `FemGraspRun`, `paper_loss`) and the gradient of the
  authors' L_opt w.r.t. the 22 ln E (``grasp_adjoint``: `loss_gradient` of a built grasp,
  `fem_grasp_loss_and_grad` from a design, object and pose); kernels in ``grasp_kernels``.
* `FemBackend` (``backend``): the FEM behind the simulator interface (``get_backend("fem")``).
* Kernels: ``kernels`` (elasticity) and ``contact_kernels`` (tendon, contact, the explicit step); they
  import Warp, so they are loaded when a finger is built, never by importing this package.
"""

from mjcodesign.sim.fem.backend import FemBackend
from mjcodesign.sim.fem.contact import FemContact
from mjcodesign.sim.fem.finger import FemFinger
from mjcodesign.sim.fem.grasp import grasp_scene
from mjcodesign.sim.fem.grasp_adjoint import FemLossGradient, fem_grasp_loss_and_grad, loss_gradient
from mjcodesign.sim.fem.grasp_outcome import FemGraspRun, paper_loss
from mjcodesign.sim.fem.gripper_grasp import GRASP_OPTIONS, GRASP_TENSION, FemGrasp
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
    "FemGrasp",
    "FemGraspRun",
    "GRASP_OPTIONS",
    "GRASP_TENSION",
    "loss_gradient",
    "fem_grasp_loss_and_grad",
    "FemLossGradient",
    "paper_loss",
]
