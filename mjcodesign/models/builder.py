"""Finger and gripper builders: a clamped finger, or two fingers on a palm with lift and opening servos.

Models are built with :class:`mujoco.MjSpec` (:mod:`~mjcodesign.models.spec`); each finger is a chain
(:mod:`~mjcodesign.models.chain`) or a flex (:mod:`~mjcodesign.models.flex`).
"""

from __future__ import annotations

import mujoco

from mjcodesign.design.finger import FingerDesign, Routing
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.models.chain import add_chain_finger
from mjcodesign.models.flex import add_flex_finger, apply_cell_young
from mjcodesign.models.spec import compile_spec, finger_frame_quat, new_spec
from mjcodesign.models.types import (
    CONTYPE_FINGER,
    CONTYPE_WORLD,
    LIFT_KP,
    MAX_OPENING,
    PALM_HALF,
    PRINTED_FLEXURE_HINGES,
    Built,
    FingerHandle,
    FingerModel,
    GripperPose,
    SimOptions,
    TendonMode,
    tendon_exit_site,
)

__all__ = [
    "build_finger",
    "build_gripper",
    "set_openings",
    "make_data",
    "apply_cell_moduli",
    "FLEXURE_HINGES_GRASP_REFUSAL",
]

FLEXURE_HINGES_GRASP_REFUSAL = (
    "the printed chain with several free hinges per flexure is validated below buckling only (buckling tension "
    "and curl against the FEM); past buckling a flexure's hinges fold into an S that nothing stops (the "
    "chain's links never touch each other, and the stops hold the flexure's sum): soft at 10 N turned "
    "flexure 1's two hinges to +2.9 and -2.5 rad and never came to rest; grasp with them tied "
    "(tied_flexures=True, the printed routing's default)"
)
"""Why :func:`build_gripper` refuses the printed routing with ``hinges_per_block`` > 1 free hinges."""


def _grasp_refusal(options: SimOptions) -> str | None:
    """Why a gripper of the chain ``options`` describe cannot grasp, in one line; None if it can.

    Several free hinges per flexure fold into an S (:data:`FLEXURE_HINGES_GRASP_REFUSAL`); tied ones grasp
    as :data:`PRINTED_FLEXURE_HINGES`, the count the grasps were checked with and the one whose single
    middle link per flexure the batched design rewrite (``mjcodesign.sim.mujoco_c``) covers.
    """
    if options.routing != "printed" or options.hinges_per_block == 1:
        return None
    if not options.tied_flexures:
        return FLEXURE_HINGES_GRASP_REFUSAL
    if options.hinges_per_block != PRINTED_FLEXURE_HINGES:
        return (
            f"the printed chain grasps with {PRINTED_FLEXURE_HINGES} tied hinges per flexure (checked in "
            f"grasps, with one middle link per flexure that a batch's design rewrite covers), not "
            f"{options.hinges_per_block}"
        )
    return None


def _add_tendon(spec: mujoco.MjSpec, handle: FingerHandle, exit_site: str, options: SimOptions) -> None:
    """Native tendon(s) pulled by force motors.

    Spatial from the base exit through every site of the finger's chain (its waypoints, or the printed
    routing's channel sites), or, for a guided chain with ``tendon_lever="constant"``, fixed on its hinges
    with the straight finger's levers.
    """
    fixed = (
        handle.model is FingerModel.CHAIN
        and options.routing == "guided"
        and options.tendon_lever == "constant"
    )
    chains = handle.site_chains or [handle.waypoint_sites]
    for j, chain in enumerate(chains):
        suffix = "" if len(chains) == 1 else f"_{j}"
        ten = spec.add_tendon(name=f"{handle.prefix}tendon{suffix}")
        if fixed:
            for joint, lever in zip(handle.joints, handle.joint_levers, strict=True):
                ten.wrap_joint(joint, lever)
        else:
            ten.wrap_site(exit_site)
            for s in chain:
                ten.wrap_site(s)
        act = spec.add_actuator(name=f"{handle.prefix}tension{suffix}", target=ten.name)
        act.trntype = mujoco.mjtTrn.mjTRN_TENDON
        # Negative gear: a positive control is a tension [N] that shortens the tendon.
        act.gear[0] = -1.0
        act.ctrllimited = True
        act.ctrlrange = [0.0, options.max_tension]
        handle.tendons.append(ten.name)
        handle.actuators.append(act.name)


def _add_finger(spec, parent, design, young, model, prefix, tendon_mode, options) -> FingerHandle:
    if options.routing == "printed" and (model.is_flex or tendon_mode is not TendonMode.NATIVE):
        raise UnsupportedError(
            f"the printed routing is the chain's native tendon; not {model.value} with {tendon_mode.value}"
        )
    if options.routing == "printed" and design.routing is not Routing.UNIFORM_PRESSURE:
        # The printed channels sit where the printed finger has them (the uniform-pressure law), whatever
        # height law the design names: refused rather than silently routed by another law.
        raise UnsupportedError(
            f"the printed routing runs through the printed finger's measured channels; a "
            f"{design.routing.value} design has none (give it SimOptions(routing='guided'))"
        )
    if model is FingerModel.CHAIN:
        handle = add_chain_finger(spec, parent, design, young, prefix, options)
    else:
        handle = add_flex_finger(
            spec, parent, design, young, prefix, options, quadratic=model is FingerModel.FLEX_QUADRATIC
        )
    exit_site = parent.add_site(
        name=f"{prefix}tendon_exit", pos=tendon_exit_site(design), size=[0.001, 0, 0], group=3
    )
    if tendon_mode is TendonMode.NATIVE:
        _add_tendon(spec, handle, exit_site.name, options)
    return handle


def _model_spec(
    kind, design, stiffness, model: FingerModel, options: SimOptions, scene: bool
) -> mujoco.MjSpec:
    if stiffness.n_blocks != design.n_blocks:
        raise DesignError(f"stiffness has {stiffness.n_blocks} blocks per finger, design {design.n_blocks}")
    quadratic = model is FingerModel.FLEX_QUADRATIC
    return new_spec(f"{kind}_{model.value}", options, flex=model.is_flex, scene=scene, quadratic=quadratic)


def build_finger(
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel,
    *,
    tendon_mode: TendonMode = TendonMode.NATIVE,
    options: SimOptions | None = None,
    finger: int = 0,
    scene: bool = False,
) -> Built:
    """One finger clamped at its base, lying along world +x and bending towards world +z."""
    options = options or SimOptions()
    model = FingerModel(model)
    spec = _model_spec("finger", design, stiffness, model, options, scene)
    base = spec.worldbody.add_body(name="A_base", pos=[0, 0, 0.2 if scene else 0.0])
    handle = _add_finger(spec, base, design, stiffness.finger(finger), model, "A_", tendon_mode, options)
    m = compile_spec(spec)
    apply_cell_moduli(m, [handle])
    return Built(spec, m, [handle], design, stiffness, model, tendon_mode, options)


def build_gripper(
    design: FingerDesign,
    stiffness: Stiffness,
    model: FingerModel,
    *,
    pose: GripperPose | None = None,
    tendon_mode: TendonMode = TendonMode.NATIVE,
    options: SimOptions | None = None,
    scene: bool = True,
) -> Built:
    """Two opposed fingers on a palm: lift slide (world z), palm at ``pose``, prismatic openings."""
    options = options or SimOptions()
    model = FingerModel(model)
    refusal = _grasp_refusal(options)
    if refusal is not None:
        raise UnsupportedError(refusal)
    pose = pose or GripperPose()
    spec = _model_spec("gripper", design, stiffness, model, options, scene)
    # The arm holds the palm: gravity-compensate the palm and carriages, not the soft fingers.
    mount = spec.worldbody.add_body(name="mount", pos=list(pose.position), gravcomp=1.0)
    mount.add_joint(name="lift", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1], damping=50.0)
    palm = mount.add_body(name="palm", quat=list(pose.quat), gravcomp=1.0)
    palm.add_geom(
        name="palm",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=PALM_HALF,
        pos=[0, 0, PALM_HALF[2]],
        mass=0.5,
        rgba=[0.25, 0.25, 0.28, 1],
        contype=CONTYPE_FINGER,
        conaffinity=CONTYPE_WORLD,
    )
    lift = spec.add_actuator(name="lift", target="lift")
    lift.trntype = mujoco.mjtTrn.mjTRN_JOINT
    lift.set_to_position(kp=LIFT_KP, dampratio=1.0)
    lift.ctrlrange = [-0.5, 0.5]
    lift.ctrllimited = True
    handles = []
    for i, (side, letter) in enumerate(((1, "A"), (-1, "B"))):
        carriage = palm.add_body(name=f"{letter}_carriage", gravcomp=1.0)
        carriage.add_joint(
            name=f"{letter}_slide",
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0, side, 0],
            range=[0, MAX_OPENING],
            damping=20.0,
        )
        carriage.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.012, 0.004, 0.006],
            mass=0.05,
            contype=0,
            conaffinity=0,
            rgba=[0.3, 0.3, 0.3, 1],
        )
        base = carriage.add_body(
            name=f"{letter}_base", pos=[0, side * design.height_base, 0], quat=finger_frame_quat(side)
        )
        handles.append(
            _add_finger(spec, base, design, stiffness.finger(i), model, f"{letter}_", tendon_mode, options)
        )
        act = spec.add_actuator(name=f"{letter}_opening", target=f"{letter}_slide")
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=500.0, dampratio=1.0)
        act.ctrlrange = [0, MAX_OPENING]
        act.ctrllimited = True
    m = compile_spec(spec)
    apply_cell_moduli(m, handles)
    built = Built(spec, m, handles, design, stiffness, model, tendon_mode, options)
    built.openings = tuple(pose.openings)
    return built


def set_openings(built: Built, openings, data: mujoco.MjData, *, qpos: bool = False) -> None:
    """Command the two openings [m] (position actuators); with ``qpos`` also place the fingers there."""
    m = built.model
    for letter, s in zip("AB", openings, strict=True):
        if qpos:
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{letter}_slide")
            data.qpos[m.jnt_qposadr[jid]] = s
        data.ctrl[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{letter}_opening")] = s


def make_data(built: Built) -> mujoco.MjData:
    """Fresh MjData; for a gripper, fingers placed at the pose's openings."""
    d = mujoco.MjData(built.model)
    if built.openings is not None:
        set_openings(built, built.openings, d, qpos=True)
    mujoco.mj_forward(built.model, d)
    return d


def apply_cell_moduli(m: mujoco.MjModel, handles: list[FingerHandle]) -> None:
    """Write each flex finger's per-block moduli into its compiled cells (chain fingers need nothing)."""
    for h in handles:
        if h.model.is_flex:
            apply_cell_young(m, h)
