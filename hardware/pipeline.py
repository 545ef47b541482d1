"""The hardware grasp: point cloud, candidate poses, selection, plan, and execution.

1. Load (or capture) the point cloud in the base frame.
2. Take candidate poses: a file of 4x4 matrices, or ``auto``, a top-down pose above the cloud.
3. Select the valid candidate whose gripper box holds the most points.
4. Plan every motion, check every target against the workspace and the tendon limits, and
   only then execute: open the hand, approach from above, close the hand to the opening, pull the
   tendons, lift, and report whether the object is still held.

A pose is the gripper frame at the soft fingertips (see `camera.GripperGeometry`): z approaches,
y closes. The openings (s1, s2) are the distances from the pose origin to the two fingers' inner
faces; the Franka Hand is symmetric, so the hand centre is offset by (s1 - s2)/2 along y and its
width is s1 + s2.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from mjcodesign.errors import HardwareError, MjcodesignError, PoseError

from .arm import Workspace, check_transform
from .camera import ARRAY_FILE_ERRORS, GripperGeometry, crop_to_gripper
from .tendon import PAPER_PULL_TICKS, MotorPull, TendonConfig

__all__ = [
    "Arm",
    "Candidate",
    "GraspPlan",
    "GraspReport",
    "GraspSettings",
    "Step",
    "Tendons",
    "auto_candidate",
    "execute",
    "load_candidates",
    "paper_lift",
    "plan_grasp",
    "select_candidate",
]

APPROACH_M = 0.10  # pre-grasp stand-off along the approach axis [m]
# Auto opening = object width minus this: the hand closes onto the object with its force (in
# franky-sim's PD-controlled hand the margin sets the squeeze).
AUTO_SQUEEZE_M = 0.02  # [m]
AUTO_TIP_CLEARANCE_M = 0.015  # auto pose keeps the fingertips this far above the cloud bottom
HELD_MARGIN_M = 0.003  # held if the hand stays this much wider than commanded after the lift
_POSE_KEYS = ("poses", "T_pose")
_YAW_STEP_DEG = 1.0  # resolution of the auto pose's yaw search [deg]


def paper_lift() -> float:
    """The paper's hardware lift [m], :data:`mjcodesign.scenarios.grasp.PAPER_HARDWARE_LIFT`.

    Read when first asked for: the scenarios import MuJoCo, which ``import mjcodesign.hardware`` does not.
    """
    from mjcodesign.scenarios.grasp import PAPER_HARDWARE_LIFT

    return PAPER_HARDWARE_LIFT


class Arm(Protocol):
    """What the pipeline needs from an arm (see `arm.FrankaArm`)."""

    def move_to(self, target: np.ndarray, what: str = ...) -> None: ...  # noqa: D102
    def lift(self, height: float) -> None: ...  # noqa: D102
    def set_width(self, width: float) -> None: ...  # noqa: D102
    def grasp(self, width: float) -> None: ...  # noqa: D102
    def width(self) -> float: ...  # noqa: D102
    def pose(self) -> np.ndarray: ...  # noqa: D102


class Tendons(Protocol):
    """What the pipeline needs from the tendon motors (see `tendon.TendonMotors`)."""

    def pull_report(self, ticks: int) -> Mapping[int, MotorPull]: ...  # noqa: D102


@dataclass(frozen=True)
class Candidate:
    """A grasp pose (4, 4) in the base frame [m] and the finger openings s1, s2 [m]."""

    pose: np.ndarray
    s1: float
    s2: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "pose", check_transform(self.pose))
        if not (np.isfinite(self.s1) and np.isfinite(self.s2) and self.s1 >= 0 and self.s2 >= 0):
            raise PoseError(f"openings must be non-negative, got s1={self.s1}, s2={self.s2}")


@dataclass(frozen=True)
class GraspSettings:
    """Grasp parameters and limits.

    Args:
        workspace: Box that every arm target must stay in.
        geometry: Finger and hand dimensions.
        approach_m: Pre-grasp stand-off along the approach axis [m].
        lift_m: Lift height along world z [m] (default: the paper's, :func:`paper_lift`).
        tendon_ticks: Tendon pull from slack [tick of 4096 per turn].
    """

    workspace: Workspace = Workspace()
    geometry: GripperGeometry = GripperGeometry()
    approach_m: float = APPROACH_M
    lift_m: float = field(default_factory=paper_lift)
    tendon_ticks: int = PAPER_PULL_TICKS

    def __post_init__(self) -> None:
        if not 0 <= self.approach_m <= 0.5 or not 0 < self.lift_m <= 0.5:
            raise PoseError("approach and lift distances must be in [0, 0.5] m")


@dataclass(frozen=True)
class Step:
    """One planned action; `target` is a base-frame pose (4, 4) or None."""

    action: str
    detail: str
    target: np.ndarray | None = None


@dataclass(frozen=True)
class GraspPlan:
    """Everything a grasp will do, checked before any motion."""

    candidate: Candidate
    index: int
    hand_pose: np.ndarray
    pre_pose: np.ndarray
    lift_pose: np.ndarray
    open_width: float
    width: float
    tendon_ticks: int
    lift_m: float
    n_points: int
    steps: tuple[Step, ...]
    ranking: tuple[dict, ...] = ()
    """Every candidate considered: its index, whether it is feasible (else the reason), its points in the
    gripper box and, when the surrogate scored it, its prediction (:func:`~mjcodesign.hardware.surrogate_select.score_candidates`)."""

    def lines(self) -> list[str]:
        """Human-readable plan, one line per step."""
        head = f"candidate {self.index}: {self.n_points} cloud points in the gripper box"
        score = next((r.get("success_score") for r in self.ranking if r["index"] == self.index), None)
        if score is not None:
            head += f", surrogate success score {score:.3f} (best of {len(self.ranking)} candidates)"
        return [head] + [f"{k}. {s.action}: {s.detail}" for k, s in enumerate(self.steps, 1)]


@dataclass
class GraspReport:
    """Outcome of an executed grasp."""

    ok: bool
    held: bool
    lift_m: float
    tendon_ticks: int
    width_m: float
    steps: list[dict] = field(default_factory=list)
    candidates: list[dict] = field(default_factory=list)
    """The plan's ranking (:attr:`GraspPlan.ranking`); empty when only one candidate was planned."""
    selected: int | None = None
    pulls: list[dict] = field(default_factory=list)
    """How each tendon motor's pull ended (:meth:`~mjcodesign.hardware.tendon.MotorPull.as_dict`): goal
    and final displacement [tick], whether it stalled, its current [mA] and estimated tension [N]."""

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        out = {
            "ok": self.ok,
            "held": self.held,
            "lift_m": round(self.lift_m, 5),
            "tendon_ticks": self.tendon_ticks,
            "width_m": round(self.width_m, 5),
            "steps": self.steps,
            "pulls": self.pulls,
        }
        if self.candidates:
            out.update(candidates=self.candidates, selected=self.selected)
        return out


def _xyz(T: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.3f}" for v in T[:3, 3]) + ") m"


def load_candidates(path: str | Path, geometry: GripperGeometry) -> list[Candidate]:
    """Read candidate poses from ``.npy`` (N, 4, 4) / (4, 4) or ``.npz`` [m].

    An ``.npz`` holds ``poses`` or ``T_pose``, and optionally ``openings`` (N, 2) [m]. Without
    openings the hand opens fully.
    """
    path = Path(path)
    if not path.is_file():
        raise PoseError(f"pose file not found: {path}")
    openings = None
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                key = next((k for k in _POSE_KEYS if k in z), None)
                if key is None:
                    raise PoseError(f"{path}: no array named 'poses' or 'T_pose'")
                poses = np.asarray(z[key], dtype=float)
                if "openings" in z:
                    openings = np.asarray(z["openings"], dtype=float)
        else:
            poses = np.asarray(np.load(path, allow_pickle=False), dtype=float)
    except ARRAY_FILE_ERRORS as exc:
        raise PoseError(f"{path}: cannot read poses: {str(exc).strip() or type(exc).__name__}") from None
    if poses.shape == (4, 4):
        poses = poses[None]
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
        raise PoseError(f"{path}: poses must have shape (N, 4, 4), got {poses.shape}")
    if openings is None:
        openings = np.full((len(poses), 2), geometry.hand_max_width / 2)
    if openings.shape != (len(poses), 2):
        raise PoseError(f"{path}: openings must have shape ({len(poses)}, 2)")
    return [Candidate(T, float(a), float(b)) for T, (a, b) in zip(poses, openings, strict=True)]


def auto_candidate(cloud: np.ndarray, geometry: GripperGeometry) -> Candidate:
    """A top-down pose above the cloud's centroid, closing across its narrow horizontal side."""
    pts = np.asarray(cloud, dtype=float)
    centre = pts.mean(axis=0)
    xy = pts[:, :2] - centre[:2]
    # Closing direction: the horizontal direction of least extent (narrowest caliper width).
    angles = np.deg2rad(np.arange(0.0, 180.0, _YAW_STEP_DEG))
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    proj = xy @ dirs.T
    y_axis = np.array([*dirs[np.argmin(np.ptp(proj, axis=0))], 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    x_axis = np.cross(y_axis, z_axis)
    if x_axis[0] < 0:  # keep the hand's x pointing away from the robot, near its home yaw
        x_axis, y_axis = -x_axis, -y_axis
    width = float(np.ptp(xy @ y_axis[:2]))
    if width > geometry.hand_max_width:
        raise PoseError(f"object is {width:.3f} m wide, more than the hand opens")
    tip_z = max(pts[:, 2].min() + AUTO_TIP_CLEARANCE_M, pts[:, 2].max() - geometry.finger_length)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x_axis, y_axis, z_axis])
    T[:3, 3] = [centre[0], centre[1], tip_z]
    half = max(width - AUTO_SQUEEZE_M, 0.0) / 2
    return Candidate(T, half, half)


def plan_grasp(
    candidate: Candidate,
    cloud: np.ndarray,
    settings: GraspSettings,
    tendon: TendonConfig | None = None,
    index: int = 0,
) -> GraspPlan:
    """Plan the grasp of one candidate; raise `PoseError`/`HardwareError` if any step is unsafe."""
    geo, ws = settings.geometry, settings.workspace
    width = candidate.s1 + candidate.s2
    if width > geo.hand_max_width:
        raise PoseError(f"openings s1+s2 = {width:.3f} m exceed the hand's {geo.hand_max_width} m")
    if tendon is not None:
        tendon.check_pull(settings.tendon_ticks)
    T = candidate.pose
    hand = T.copy()
    hand[:3, 3] += T[:3, 1] * (candidate.s1 - candidate.s2) / 2
    pre = hand.copy()
    pre[:3, 3] -= T[:3, 2] * settings.approach_m
    lift = hand.copy()
    lift[2, 3] += settings.lift_m
    for what, target in (("grasp pose", hand), ("pre-grasp pose", pre), ("lift target", lift)):
        ws.check(target, f"candidate {index} {what}")
    n_points = len(crop_to_gripper(cloud, T, geo, candidate.s1, candidate.s2))
    steps = (
        Step("hand", f"open to {geo.hand_max_width:.3f} m"),
        Step("arm", f"move to pre-grasp {_xyz(pre)}", pre),
        Step("arm", f"approach to grasp pose {_xyz(hand)}", hand),
        Step("hand", f"close to opening {width:.4f} m (s1 {candidate.s1:.4f}, s2 {candidate.s2:.4f})"),
        Step("tendon", f"pull {settings.tendon_ticks} ticks from slack"),
        Step("arm", f"lift {settings.lift_m:.3f} m to {_xyz(lift)}", lift),
        Step("check", f"object held: hand wider than {width + HELD_MARGIN_M:.4f} m"),
    )
    return GraspPlan(
        candidate=candidate,
        index=index,
        hand_pose=hand,
        pre_pose=pre,
        lift_pose=lift,
        open_width=geo.hand_max_width,
        width=width,
        tendon_ticks=settings.tendon_ticks,
        lift_m=settings.lift_m,
        n_points=n_points,
        steps=steps,
    )


def select_candidate(
    candidates: list[Candidate],
    cloud: np.ndarray,
    settings: GraspSettings,
    tendon: TendonConfig | None = None,
    scores: dict[int, dict] | None = None,
) -> GraspPlan:
    """Plan every candidate; return the valid plan with the best score (else most points in its box).

    ``scores`` maps a candidate's index to the surrogate's prediction (``success_score`` and the
    outputs); a feasible candidate without one ranks below every scored one. The plan's ``ranking``
    lists every candidate with its prediction, or the reason it is infeasible. Raises the first
    candidate's error if none is valid.
    """
    plans, errors, ranking = [], [], []
    for i, cand in enumerate(candidates):
        row = {"index": i, **(scores or {}).get(i, {})}
        try:
            plan = plan_grasp(cand, cloud, settings, tendon, i)
        except MjcodesignError as exc:
            errors.append(exc)
            ranking.append({**row, "feasible": False, "reason": str(exc)})
            continue
        plans.append(plan)
        ranking.append({**row, "feasible": True, "points": plan.n_points})
    if not plans:
        if errors:
            raise errors[0]
        raise PoseError("no candidate poses")

    def key(p: GraspPlan) -> tuple:
        s = (scores or {}).get(p.index, {}).get("success_score")
        return (s is not None, -np.inf if s is None else s, p.n_points, -p.index)

    best = max(plans, key=key)
    return dataclasses.replace(best, ranking=tuple(ranking) if scores is not None else ())


def execute(
    plan: GraspPlan,
    arm: Arm,
    tendons: Tendons,
    log: Callable[[str], None] = lambda line: None,
    after_lift: Callable[[], object] | None = None,
) -> GraspReport:
    """Run a checked plan on the arm and tendons; report whether the object stays held.

    `after_lift` is called once the object is lifted, while the arm still holds it (the
    selftest measures the object's height there).
    """
    records: list[dict] = []
    pulled: dict[int, MotorPull] = {}

    def run(step: Step, fn: Callable[[], object]) -> None:
        log(f"{len(records) + 1}. {step.action}: {step.detail}")
        t0 = time.monotonic()
        fn()
        records.append({"action": step.action, "detail": step.detail, "s": round(time.monotonic() - t0, 3)})

    hand_open, pre, approach, close, pull, lift, check = plan.steps
    run(hand_open, lambda: arm.set_width(plan.open_width))
    run(pre, lambda: arm.move_to(plan.pre_pose, "pre-grasp pose"))
    run(approach, lambda: arm.move_to(plan.hand_pose, "grasp pose"))
    run(close, lambda: arm.grasp(plan.width))
    run(pull, lambda: pulled.update(tendons.pull_report(plan.tendon_ticks)))
    z0 = arm.pose()[2, 3]
    run(lift, lambda: arm.move_to(plan.lift_pose, "lift target"))
    lift_m = float(arm.pose()[2, 3] - z0)
    width = arm.width()
    held = width > plan.width + HELD_MARGIN_M
    if after_lift is not None:
        after_lift()
    run(check, lambda: None)
    records[-1]["held"] = held
    ticks = round(float(np.mean([r.displacement_ticks for r in pulled.values()]))) if pulled else 0
    if abs(lift_m - plan.lift_m) > 0.01:
        raise HardwareError(f"arm lifted {lift_m:.3f} m instead of {plan.lift_m:.3f} m")
    ranked = list(plan.ranking)
    pulls = [pulled[i].as_dict() for i in sorted(pulled)]
    return GraspReport(
        held, held, lift_m, ticks, width, records, ranked, plan.index if ranked else None, pulls
    )
