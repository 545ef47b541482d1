"""What is simulated: the grasp scenario and its outcome; the static scenarios (cantilever, curl, press)."""

from mjcodesign.scenarios.grasp import (
    DEFAULT_IMPULSE,
    REFERENCE_POSE,
    REST_GAP,
    STATE_SPEC,
    GraspScenario,
    GraspScene,
    auto_pose,
    build_scene,
    compile_scene,
    control_spec,
    object_vertices,
    paper_impulse,
    phase_controls,
    scene_at_pose,
    start_openings,
)
from mjcodesign.scenarios.outcome import Failure, Outcome, failed_outcome, outcome_from_states, outcome_steps

__all__ = [
    "DEFAULT_IMPULSE",
    "REST_GAP",
    "STATE_SPEC",
    "GraspScenario",
    "GraspScene",
    "auto_pose",
    "REFERENCE_POSE",
    "build_scene",
    "compile_scene",
    "control_spec",
    "object_vertices",
    "paper_impulse",
    "phase_controls",
    "scene_at_pose",
    "start_openings",
    "Failure",
    "Outcome",
    "failed_outcome",
    "outcome_from_states",
    "outcome_steps",
]
