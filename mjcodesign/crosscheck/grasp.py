"""The grasp agreement study: the MuJoCo chain and the Warp FEM on a fixed, documented set of cases.

`GRASP_CASES` crosses six objects (a 40×40×60 mm box, a 20 mm × 70 mm cylinder, a 25 mm sphere and the
YCB lemon, apple and orange, at the light density) with four (design, sampler pose) pairs:
soft and semi-rigid at the sampler's best pose, ``random:0`` and ``random:1`` at its second
(`mjcodesign.poses.sample_poses`, seed 0): 24 cases. (The potted-meat can was a first choice: both its
sampler poses were 109–114 mm across the closing axis, wider than the stroke.) Each runs the same `GraspScenario` in both
simulators from the same MuJoCo scene (`mjcodesign.sim.fem.FemBackend` reads the design, pose and
object from it), with the tendon routed the same way in both: the guided waypoints (default) or the
printed finger's channels (``routing="printed"``).

`grasp_study` reports, per case and model, the outcome and three physical checks, and over the cases:

* success agreement, over all cases and over those where neither rollout diverged or broke the energy
  bound (``success_agreement_valid``; ``invalid_cases`` lists the others);
* cases whose sampler pose the scene refuses (wider than the stroke), left out and listed;
* per-output Pearson correlation of the body force (6) and displacement (3) across cases;
* median relative difference of the force (3) and of Δq, the FEM being the reference;
* for every case where they disagree on success: the phase in which the object's paths part
  (`PART_DISTANCE`) and the checks each simulator breaks: the hold force against m·g while the object
  is held (`HOLD_TOL`), the deepest finger penetration during the hold (`MAX_DEPTH`), and the energy
  bound where the simulator checks it (MuJoCo's `Failure.IMPLAUSIBLE`; the FEM's divergence);
* and for each disagreement the chain's margin (`chain_margin`): its outcome with the palm moved
  ±`MARGIN_SHIFT` along each palm axis, which tells a knife-edge case from a real parting (six chain
  rollouts, a second; the FEM's margin would cost six minutes a case and is not taken).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

__all__ = [
    "GRASP_CASES",
    "GRASP_MODELS",
    "GraspCase",
    "HOLD_TOL",
    "MARGIN_SHIFT",
    "MAX_DEPTH",
    "PART_DISTANCE",
    "SHORT_CASES",
    "STUDY_TENSION",
    "chain_margin",
    "grasp_study",
    "model_runners",
    "short_settings",
    "study_summary",
]

GRASP_MODELS = ("chain", "fem")
"""The models the grasp study compares (the flex grasp does not hold: see the benchmarks)."""
HOLD_TOL = 0.05
"""A held object's mean vertical finger force may differ from m·g by this fraction."""
MAX_DEPTH = 2e-3
"""Deepest plausible finger penetration [m] during the hold: the flexures are 2 mm thick."""
PART_DISTANCE = 5e-3
"""The object's paths in the two simulators have parted once their COMs are this far apart [m]."""
MARGIN_SHIFT = 1e-3
"""Palm shift [m] of the chain's margin on a disagreement (`chain_margin`): a pose that lands within a
millimetre is all a sampler or a robot gives, so an outcome that flips within it is on a knife edge."""
STUDY_TENSION = 4.0
"""Tendon tension of the study [N]: `mjcodesign.sim.fem.gripper_grasp.GRASP_TENSION` (its reason there),
written out so that importing this module stays free of MuJoCo (tested equal)."""
_INVALID = {"implausible", "diverged"}
"""Failure kinds of a rollout that broke a physical bound or blew up (`Failure` values)."""
_FORCE_FLOOR = 0.1
"""Median relative force difference: denominators below this fraction of m·g are raised to it."""
_DISP_FLOOR = 1e-3
"""Median relative Δq difference: denominators below this [m] are raised to it."""
_SHAPES = {
    "cylinder": lambda trimesh: trimesh.creation.cylinder(radius=0.02, height=0.07, sections=32),
    "sphere": lambda trimesh: trimesh.creation.icosphere(subdivisions=3, radius=0.025),
}
_BOX = (0.04, 0.04, 0.06)
"""Full side lengths of the study's box [m]."""


@dataclass(frozen=True)
class GraspCase:
    """One case: an object (name), the sampler's pose ``pose`` (0 = best) and a design."""

    obj: str
    pose: int
    design: str

    @property
    def label(self) -> str:
        """``object/pose/design``."""
        return f"{self.obj}/pose{self.pose}/{self.design}"


SHORT_CASES = (GraspCase("box", 0, "semi-rigid"), GraspCase("sphere", 0, "soft"))
"""The CI version's two cases (`short_settings`)."""
SHORT_PHASES = dict(settle_s=0.004, close_s=0.03, tighten_s=0.05, lift_s=0.05, hold_s=0.03, post_hold_s=0.01)
"""Phase durations [s] of the CI version (`short_settings`): 0.18 s in all."""


def short_settings() -> dict:
    """Keyword arguments of `grasp_study` for the CI version: two cases, a short horizon, a coarse mesh.

    The phases are shortened to 0.18 s in all (a 1 cm lift, no disturbance); the FEM mesh has 10 mm
    cells and 8 mm in the flexures (396 vertices a finger, about as coarse as the authors' 432
    particles) and steps 10 µs with selective mass scaling.
    """
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.sim.fem import FemDynamics, FemOptions

    return {
        "cases": SHORT_CASES,
        "scenario": GraspScenario(
            **SHORT_PHASES, tendon=TendonForce(tension=STUDY_TENSION), lift=0.01, impulse=0.0
        ),
        "fem_options": FemOptions(h=10e-3, h_flexure=8e-3, spine_layers=2, waypoint_layers=False),
        "fem_dynamics": FemDynamics(dt=1e-5),
    }


GRASP_CASES = tuple(
    GraspCase(o, p, d)
    for o in ("box", "cylinder", "sphere", "014_lemon", "013_apple", "017_orange")
    for d, p in (("soft", 0), ("semi-rigid", 0), ("random:0", 1), ("random:1", 1))
)
"""The study's 24 cases (module docstring)."""


def grasp_study(
    cases=GRASP_CASES,
    models=GRASP_MODELS,
    *,
    scenario=None,
    fem_options=None,
    fem_dynamics=None,
    density: str = "light",
    routing: str = "guided",
    cache_dir: Path | None = None,
    on_case: Callable[[dict], None] | None = None,
) -> tuple[list[dict], dict]:
    """Run every case in every model; (one record per case, the summary of `study_summary`).

    ``scenario`` defaults to `GraspScenario` at `STUDY_TENSION`; ``fem_options``/``fem_dynamics`` mesh and step the FEM
    (defaults: `mjcodesign.sim.fem.gripper_grasp.GRASP_OPTIONS`, the paper's 2.5 µs). ``routing``
    (`mjcodesign.models.types.ROUTINGS`) is where the tendon runs on both sides: the chain's
    ``SimOptions(routing=...)`` and the FEM's ``FemOptions(routing=...)`` (`DesignError` if ``fem_options``
    names another); every record keeps it. ``on_case`` hears every record as it is finished (a long study
    can be followed and kept).
    """
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import DesignError, PoseError
    from mjcodesign.models.types import FingerModel, SimOptions
    from mjcodesign.poses import sample_poses, to_gripper_pose
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, build_scene

    for m in models:
        if m not in GRASP_MODELS:
            raise DesignError(f"the grasp study compares {GRASP_MODELS}, not {m!r}")
    chain_options = None if routing == "guided" else SimOptions(routing=routing)  # refuses an unknown one
    fem_options = _fem_routing(fem_options, routing)
    scenario = scenario or GraspScenario(tendon=TendonForce(tension=STUDY_TENSION))
    design = FingerDesign()
    objects, poses, records = {}, {}, []
    sims = model_runners(models, fem_options, fem_dynamics)
    for case in cases:
        if case.obj not in objects:
            objects[case.obj] = _load(case.obj, density, cache_dir)
            poses[case.obj] = sample_poses(objects[case.obj], 2, seed=0, design=design, cache_dir=cache_dir)
        obj = objects[case.obj]
        rec = {
            "case": case.label,
            "object": case.obj,
            "pose": case.pose,
            "design": case.design,
            "mass_kg": obj.mass,
            "lift": scenario.lift,
            "tension": scenario.tension,
            "routing": routing,
        }
        try:
            pose = to_gripper_pose(poses[case.obj], case.pose)
            stiffness = Stiffness.parse(case.design)
            scene = build_scene(obj, design, stiffness, FingerModel.CHAIN, pose, options=chain_options)
        except PoseError as exc:  # the sampler's pose does not fit the stroke: no simulator runs it
            rec["bad_pose"] = str(exc)
        else:
            for name, run in sims.items():
                rec[name] = run(scene, scenario)
            if "chain" in rec and "fem" in rec and rec["chain"]["success"] != rec["fem"]["success"]:
                rec["chain_margin"] = chain_margin(scene, scenario, nominal=rec["chain"]["success"])
        records.append(rec)
        if on_case is not None:
            on_case(rec)
    return records, study_summary(records, models)


def _fem_routing(fem_options, routing: str):
    """The FEM's options for the study's ``routing``: ``fem_options`` as given, or the grasp's default mesh."""
    from mjcodesign.errors import DesignError

    if fem_options is None:
        if routing == "guided":
            return None  # the FEM backend's default, `GRASP_OPTIONS`
        from mjcodesign.sim.fem.gripper_grasp import GRASP_OPTIONS

        return replace(GRASP_OPTIONS, routing=routing)
    if fem_options.routing != routing:
        raise DesignError(
            f"the study runs the {routing} routing on both sides; its FEM options name {fem_options.routing!r}"
        )
    return fem_options


def chain_margin(scene, scenario, shift: float = MARGIN_SHIFT, *, nominal: bool | None = None) -> dict:
    """The chain's outcome with the palm moved ±``shift`` [m] along each palm axis (six rollouts).

    ``same``: how many of the six keep the unmoved pose's success (``nominal``, rolled out here when not
    given); ``rises_m``: each one's object rise at the end [m], in the order +x, −x, +y, −y, +z, −z of the
    palm frame. A disagreement whose chain outcome flips within a millimetre is on a knife edge in the
    chain itself (module docstring).
    """
    import dataclasses

    from mjcodesign.scenarios.grasp import build_scene
    from mjcodesign.sim.fem.gripper import quat_matrix
    from mjcodesign.sim.mujoco_c import MujocoBackend

    pose = scene.pose
    R = quat_matrix(pose.quat)
    if nominal is None:
        nominal = MujocoBackend(nthread=1).run(scene, scenario).success
    nominal = bool(nominal)
    b = scene.built
    successes, rises = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            moved = dataclasses.replace(
                pose, position=tuple(np.asarray(pose.position) + sign * shift * R[:, axis])
            )
            other = build_scene(scene.obj, b.design, b.stiffness, b.finger_model, moved, options=b.options)
            out = MujocoBackend(nthread=1).run(other, scenario)
            successes.append(bool(out.success))
            rises.append(float(out.lift_height))
    return {
        "shift_m": shift,
        "success": nominal,
        "same": int(sum(s == nominal for s in successes)),
        "of": len(successes),
        "rises_m": rises,
    }


def model_runners(models, fem_options=None, fem_dynamics=None) -> dict[str, Callable]:
    """Per model, a function (scene, scenario) -> its record of the grasp.

    A record holds the outcome's fields, the COM path per MuJoCo step, the hold penetration and the
    finger contact counts.
    """
    out = {}
    if "chain" in models:
        out["chain"] = _chain_record
    if "fem" in models:
        from mjcodesign.sim.fem import FemBackend

        fem = FemBackend(dynamics=fem_dynamics, grasp_options=fem_options)
        out["fem"] = lambda scene, scenario: _fem_record(fem, scene, scenario)
    return out


def _load(name: str, density: str, cache_dir):
    """The study's object ``name`` at ``density``, decomposed (`mjcodesign.jobs.load_grasp_object`)."""
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.objects import box_object, convex_decomposition, parse_density

    if name == "box":
        return box_object(_BOX, parse_density(density))
    if name not in _SHAPES:
        return load_grasp_object(name, density, cache_dir=cache_dir)
    import trimesh

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}.stl"
        _SHAPES[name](trimesh).export(path)
        obj = load_grasp_object(path, density, cache_dir=cache_dir)
    convex_decomposition(obj, cache_dir=cache_dir)
    return obj


# -- one model's record -------------------------------------------------------------------------------
def _outcome_fields(out, R: np.ndarray, mass: float) -> dict:
    """The outcome's fields and the world-vertical hold force over m·g."""
    f = np.asarray(out.body_force)
    return {
        "success": bool(out.success),
        "failures": [k.value for k in out.failures],
        "reason": out.reason,
        "body_force": f.tolist(),
        "displacement": list(out.displacement),
        "lift_height": float(out.lift_height),
        "ground_contact": bool(out.ground_contact),
        "finger_contact": bool(out.finger_contact),
        "hold_force_ratio": float((R @ f[3:])[2] / (mass * 9.81)),
        "wall_time_s": float(out.wall_time_s),
    }


def _chain_record(scene, scenario) -> dict:
    """The chain's outcome, its object path (COM per MuJoCo step) and hold penetration (replayed)."""
    import mujoco

    from mjcodesign.sim.mujoco_c import MujocoBackend

    keep = _Keep()
    out = MujocoBackend(nthread=1).run(scene, scenario, observer=keep)
    r = keep.kept
    m = scene.model
    adr = 1 + m.jnt_qposadr[m.body_jntadr[scene.object_body]]  # state = (time, qpos, ...)
    path = np.vstack([r.x0[adr : adr + 3], r.states[:, adr : adr + 3]])
    d = mujoco.MjData(m)
    counts, depth = [], 0.0
    hold = set(_hold_indices(r.starts, len(r.states)))
    for t, x in enumerate(r.states):
        mujoco.mj_setState(m, d, x, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        mujoco.mj_fwdPosition(m, d)
        n, deepest = _finger_contacts(scene, d)
        counts.append(n)
        depth = max(depth, deepest) if t in hold else depth
    rec = _outcome_fields(out, _palm_rotation(scene), scene.obj.mass)
    rec.update(
        # how the chain's hinges get their stiffness: beam theory, or the FEM calibration where it exists
        stiffness_model=getattr(scene.built.options, "stiffness_model", "beam"),
        path=path,
        starts=dict(r.starts),
        max_depth_m=depth,
        max_finger_contacts=max(counts, default=0),
        finger_contacts_end=counts[-1] if counts else 0,
    )
    return rec


def _fem_record(fem, scene, scenario) -> dict:
    """The FEM's outcome, its object path (COM per MuJoCo step) and hold penetration."""
    run = fem.grasp_run(scene, scenario)
    fr = run.frames
    rec = _outcome_fields(run.outcome, _palm_rotation(scene), scene.obj.mass)
    hold = [t + 1 for t in _hold_indices(run.starts, len(fr.time) - 1)]
    rec.update(
        path=fr.pos,
        starts=dict(run.starts),
        max_depth_m=float(np.max(fr.max_depth[hold], initial=0.0)) if hold else 0.0,
        max_finger_contacts=int(fr.n_inside.max(initial=0)),
        finger_contacts_end=int(np.count_nonzero(run.final_depth > 0)),
        n_vertices=run.n_vertices,
        added_mass_fraction=run.added_mass_fraction,
        vertex_substeps_per_s=run.vertex_substeps_per_s,
    )
    return rec


class _Keep:
    """An observer that keeps the last rollout (the study reads its states)."""

    kept = None

    def rollout(self, rollout) -> None:
        """Keep ``rollout``."""
        self.kept = rollout

    def snapshot(self, snapshot) -> None:
        """Shapes are not part of the study."""

    def close(self) -> None:
        """Nothing to flush."""


def _hold_indices(starts: dict, n: int) -> list[int]:
    """States (index into a rollout's states) in the second half of the first hold."""
    h0, h1 = starts["hold"], starts["impulse"]
    return [t for t in range(h0 + (h1 - h0) // 2, h1 - 1) if t < n]


def _finger_contacts(scene, d) -> tuple[int, float]:
    """(finger–object contacts, the deepest one's depth [m]) in MuJoCo data ``d`` (chain fingers)."""
    m = scene.model
    ob = scene.object_body
    n, depth = 0, 0.0
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        other = b2 if b1 == ob else b1 if b2 == ob else -1
        if other >= 0 and scene.finger_mask[other]:
            n += 1
            depth = max(depth, -float(c.dist))
    return n, depth


def _palm_rotation(scene) -> np.ndarray:
    from mjcodesign.sim.fem.gripper import quat_matrix

    return quat_matrix(scene.pose.quat)


# -- the summary --------------------------------------------------------------------------------------
def study_summary(records: list[dict], models=GRASP_MODELS) -> dict:
    """Agreement over the records of `grasp_study` (module docstring); empty without both models.

    Cases whose sampler pose the scene refuses (``bad_pose``) are left out and listed.
    """
    bad = [r["case"] for r in records if "bad_pose" in r]
    records = [r for r in records if "bad_pose" not in r]
    if not {"chain", "fem"} <= set(models) or not records:
        return {"bad_poses": bad} if bad else {}
    a = [r["chain"] for r in records]
    b = [r["fem"] for r in records]
    outputs = [f"f{i}" for i in range(6)] + [f"dq{i}" for i in range(3)]
    xa = np.array([x["body_force"] + x["displacement"] for x in a])
    xb = np.array([x["body_force"] + x["displacement"] for x in b])
    mg = np.array([r["mass_kg"] * 9.81 for r in records])
    df = np.linalg.norm(xa[:, 3:6] - xb[:, 3:6], axis=1) / np.maximum(
        np.linalg.norm(xb[:, 3:6], axis=1), _FORCE_FLOOR * mg
    )
    dq = np.linalg.norm(xa[:, 6:] - xb[:, 6:], axis=1) / np.maximum(
        np.linalg.norm(xb[:, 6:], axis=1), _DISP_FLOOR
    )
    agree = [x["success"] == y["success"] for x, y in zip(a, b, strict=True)]
    # A diverged or implausible rollout is a failure, but no reference: its agreement is also given
    # without such cases.
    invalid = [bool(_INVALID & (set(x["failures"]) | set(y["failures"]))) for x, y in zip(a, b, strict=True)]
    valid_agree = [ok for ok, bad_run in zip(agree, invalid, strict=True) if not bad_run]
    return {
        "cases": len(records),
        "bad_poses": bad,
        "success_agreement": float(np.mean(agree)),
        "invalid_cases": [r["case"] for r, bad_run in zip(records, invalid, strict=True) if bad_run],
        "success_agreement_valid": float(np.mean(valid_agree)) if valid_agree else None,
        "success": {"chain": int(sum(x["success"] for x in a)), "fem": int(sum(y["success"] for y in b))},
        "correlation": {k: _pearson(xa[:, i], xb[:, i]) for i, k in enumerate(outputs)},
        "median_rel_diff": {"force": float(np.median(df)), "displacement": float(np.median(dq))},
        "disagreements": [_explain(r) for r, ok in zip(records, agree, strict=True) if not ok],
        "checks": {
            m: [_checks(r[m], r["lift"]) | {"case": r["case"]} for r in records] for m in ("chain", "fem")
        },
    }


def _pearson(x: np.ndarray, y: np.ndarray) -> float | None:
    """Pearson r, or None when either side is constant."""
    if np.std(x) == 0 or np.std(y) == 0:
        return None
    return float(np.corrcoef(x, y)[0, 1])


def _checks(rec: dict, lift: float) -> dict:
    """Which physical checks a model's record breaks: hold force, penetration, energy/divergence."""
    held = _held(rec, lift)
    return {
        "held": held,
        "hold_force": bool(held and abs(rec["hold_force_ratio"] - 1.0) > HOLD_TOL),
        "penetration": bool(rec["max_depth_m"] > MAX_DEPTH),
        "energy": bool(_INVALID & set(rec["failures"])),
    }


def _held(rec: dict, lift: float) -> bool:
    """The object has risen by half the lift ``lift`` [m] at every hold sample."""
    path, starts = np.asarray(rec["path"]), rec["starts"]
    idx = [t + 1 for t in _hold_indices(starts, len(path) - 1)]
    return bool(idx) and bool(np.all(path[idx, 2] - path[0, 2] > 0.5 * lift))


def _explain(r: dict) -> dict:
    """Where a disagreement starts (phase) and which checks each simulator breaks."""
    a, b = r["chain"], r["fem"]
    pa, pb = np.asarray(a["path"]), np.asarray(b["path"])
    n = min(len(pa), len(pb))
    apart = np.flatnonzero(np.linalg.norm(pa[:n] - pb[:n], axis=1) > PART_DISTANCE)
    phase = None
    if apart.size:
        step = int(apart[0]) - 1
        phase = max(
            (k for k, v in a["starts"].items() if k != "end" and v <= step), key=lambda k: a["starts"][k]
        )
    return {
        "case": r["case"],
        "chain": a["reason"],
        "fem": b["reason"],
        "chain_margin": r.get("chain_margin"),
        "parts_in": phase,
        "breaks": {
            m: [k for k, v in _checks(r[m], r["lift"]).items() if k != "held" and v] for m in ("chain", "fem")
        },
    }
