"""The one case the authors' own simulator was run on here, in the chain and the Warp FEM.

Their result (their scripts, unmodified, run on warp 1.6.1): ``006_mustard_bottle`` at their
AnyGrasp pose 0 after their pose refinement, density 2 in their 5×-scaled scene, tendon force 100 in
their units, uniform designs:

* ln E 13.5 lifts the bottle (11 finger contacts; rise 0.124 of the finger's 0.168, their units);
* 15.0 slips (5 finger contacts, rise 0.005, ground contact);
* 16.5 never touches it (a stiff finger under a fixed tendon force does not bend far enough).

Mapped to real size as the NOTES give it: lengths 1/5 with E unchanged, so equal bending needs
T = 100 / 25 = 4 N, and equal grip-to-weight at that tension a density of 10 kg/m³; the lift 0.1676 / 5
= 33.5 mm; the disturbance `mjcodesign.scenarios.grasp.paper_impulse`. The pose is their row 0 mapped
into our scene (`mjcodesign.poses.external.anygrasp_to_world`) and refined by our refinement (theirs,
an SGD over the approach offset and the openings, is not in the shared files, but ours minimises the same
L_init and closes each finger until it touches). By default (``start="refined"``) the fingers start at
the refined openings, as theirs do, and only the tendon closes them (the close phase has nothing to
move); ``start="sweep"`` runs our own scenario instead, the carriages driven in from outside the object
to the refined openings before the tendon pulls.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["AUTHORS_RESULT", "AUTHORS_ROW", "STARTS", "authors_case", "classify"]

AUTHORS_RESULT = {13.5: "lifts", 15.0: "slips", 16.5: "no contact"}
"""Uniform ln E → what the authors' simulator did with it (module docstring)."""
AUTHORS_ROW = 0
"""The row of the authors' pose file (``006_mustard_bottle.npz``) that :data:`AUTHORS_RESULT` is for."""
_OBJECT = "006_mustard_bottle"
_TENSION = 100.0 / 25.0
"""[N] their 100 at 5× lengths, equal bending (E unchanged: T ∝ L²)."""
_DENSITY = 10.0
"""[kg/m³] their 2 at 5× lengths and T/25: equal grip to weight."""
_LIFT = 0.1676 / 5.0
"""[m] their finger base rise, 0.1676 of their units."""
STARTS = ("refined", "sweep")
"""Where the fingers start: at the refined openings (the authors'), or outside the object (ours)."""


def classify(rec: dict, lift: float) -> str:
    """``lifts`` (risen half the lift at the end), ``no contact`` (no finger touched it) or ``slips``."""
    if rec["max_finger_contacts"] == 0:
        return "no contact"
    if rec["lift_height"] >= 0.5 * lift and rec["finger_contact"]:
        return "lifts"
    return "slips"


def authors_case(
    models=("chain", "fem"),
    *,
    pose_file: Path,
    fem_options=None,
    fem_dynamics=None,
    cache_dir: Path | None = None,
    start: str = "refined",
) -> list[dict]:
    """Each uniform design of `AUTHORS_RESULT` in each model: outcome, contacts, and the class.

    ``pose_file``: the authors' ``006_mustard_bottle.npz`` (their AnyGrasp poses, ``pose_info/`` of
    their repository), whose pose :data:`AUTHORS_ROW` is the one their result is for (each row carries
    it as ``row``); :class:`PoseError` when it is missing. Raises PoseError when
    our refinement refuses the pose or our stroke cannot take it. ``start``: one of `STARTS`.
    """
    import dataclasses

    from mjcodesign.crosscheck.grasp import model_runners
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.errors import PoseError
    from mjcodesign.jobs import load_grasp_object
    from mjcodesign.models.types import FingerModel
    from mjcodesign.objects import load_mesh
    from mjcodesign.poses import to_gripper_pose
    from mjcodesign.poses.external import import_anygrasp, load_external
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, GraspScene, build_scene, start_openings

    if start not in STARTS:
        from mjcodesign.errors import DesignError

        raise DesignError(f"unknown start {start!r}; choose from {', '.join(STARTS)}")

    path = Path(pose_file)
    if not path.is_file():
        raise PoseError(f"the authors' pose file {path} is missing: give their {_OBJECT}.npz")
    obj = load_grasp_object(_OBJECT, _DENSITY, cache_dir=cache_dir)
    T = load_external(path)[AUTHORS_ROW : AUTHORS_ROW + 1]
    cands = import_anygrasp(obj, T, np.asarray(load_mesh(_OBJECT).vertices), cache_dir=cache_dir)
    if len(cands) == 0:
        raise PoseError(
            f"the authors' pose {AUTHORS_ROW} of {_OBJECT} is refused by our refinement: {cands.rejected}"
        )
    pose = to_gripper_pose(cands, 0)
    start_openings(obj, pose)  # PoseError if the object is too wide for our stroke at this pose
    scenario = GraspScenario(tendon=TendonForce(tension=_TENSION), lift=_LIFT)
    sims = model_runners(models, fem_options, fem_dynamics)
    out = []
    for log_e, theirs in AUTHORS_RESULT.items():
        scene = build_scene(obj, FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, pose)
        if start == "refined":  # the carriages start where the refinement left them, and stay
            built = dataclasses.replace(scene.built, openings=pose.openings)
            scene = GraspScene(built, scene.obj, pose, tuple(pose.openings))
        rec_row = {
            "log_e": log_e,
            "authors": theirs,
            "row": AUTHORS_ROW,
            "mass_kg": obj.mass,
            "pose": [*pose.position, *pose.quat],
            "openings": list(pose.openings),
            "start": start,
        }
        for name, run in sims.items():
            rec = run(scene, scenario)
            rec["class"] = classify(rec, scenario.lift)
            rec_row[name] = {k: v for k, v in rec.items() if k not in ("path", "starts")}
        out.append(rec_row)
    return out
