"""Empty specs with the simulation options and the shared scene, finger frames, and compilation with typed errors."""

from __future__ import annotations

import mujoco
import numpy as np

from mjcodesign import models_xml
from mjcodesign.errors import DesignError
from mjcodesign.models.types import SimOptions

__all__ = ["finger_frame_quat", "new_spec", "compile_spec"]


def finger_frame_quat(side: int) -> np.ndarray:
    """Orientation of finger A (side=+1) or B (side=-1) in the palm frame, as a quaternion.

    Finger x (length) runs along palm -z; finger z (inner side) points to the palm's mid-plane.
    """
    x_f = np.array([0.0, 0.0, -1.0])
    z_f = np.array([0.0, -float(side), 0.0])
    y_f = np.cross(z_f, x_f)
    R = np.column_stack([x_f, y_f, z_f])
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    return q


def new_spec(
    name: str, options: SimOptions, *, flex: bool, scene: bool = True, quadratic: bool = False
) -> mujoco.MjSpec:
    """An empty spec with the simulation options (and the ground scene)."""
    if scene:
        spec = mujoco.MjSpec.from_file(str(models_xml.SCENE_XML))
    else:
        spec = mujoco.MjSpec()
    spec.modelname = name
    opt = spec.option
    opt.timestep = options.timestep
    # MuJoCo 4.0 integrates flex elasticity implicitly only under the 'discrete' integrator.
    opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE if flex else mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.solver = mujoco.mjtSolver.mjSOL_CG if flex else mujoco.mjtSolver.mjSOL_NEWTON
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    if flex:
        opt.iterations = options.flex_quadratic_iterations if quadratic else options.flex_iterations
    else:
        opt.iterations = options.iterations
    opt.tolerance = options.flex_tolerance if flex else options.tolerance
    if not options.gravity:
        opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_GRAVITY
    return spec


def compile_spec(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """Compile ``spec``; a MuJoCo compile error becomes :class:`DesignError`."""
    try:
        return spec.compile()
    except ValueError as exc:  # MuJoCo compile errors
        raise DesignError(f"MuJoCo could not compile the model: {exc}") from exc
