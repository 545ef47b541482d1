"""Co-design: the stiffness of the 22 blocks and a grasp pose per object, through the surrogate.

Import from here (``from mjcodesign.codesign import optimize``): each name has this one public path.
Torch is imported only inside the functions that run the surrogate.

- :mod:`~mjcodesign.codesign.problem`: :class:`PoseSet`, the candidate poses (:func:`load_pose_set`);
- :mod:`~mjcodesign.codesign.selection`: :class:`PoseSelection`, Algorithm 1's top-B / patience
  bookkeeping per object;
- :mod:`~mjcodesign.codesign.optimize`: :func:`optimize` (Algorithm 1), :class:`OptimizeConfig`;
- :mod:`~mjcodesign.codesign.verify`: the ground truth, designs re-simulated in MuJoCo;
- :mod:`~mjcodesign.codesign.report`, :mod:`~mjcodesign.codesign.run`: the files of a run and
  ``run_codesign`` (``mjcodesign optimize``);
- :mod:`~mjcodesign.codesign.search`, :mod:`~mjcodesign.codesign.fem_baseline`: the baselines, CMA-ES
  on MuJoCo C and descent through the Warp FEM's gradient.
"""

from mjcodesign.codesign.optimize import (
    Mode,
    Objective,
    OptimizeConfig,
    OptimizeResult,
    Step,
    log_e_of,
    optimize,
    z_of,
)
from mjcodesign.codesign.problem import PoseSet, load_pose_set, object_key
from mjcodesign.codesign.selection import Phase, PoseSelection

__all__ = [
    "Mode",
    "Objective",
    "OptimizeConfig",
    "OptimizeResult",
    "Phase",
    "PoseSelection",
    "PoseSet",
    "Step",
    "load_pose_set",
    "log_e_of",
    "object_key",
    "optimize",
    "z_of",
]
