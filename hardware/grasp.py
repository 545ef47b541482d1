"""``hw grasp`` end to end: build the drivers from a `RobotGraspJob` and run the pipeline.

The tendon motors are opened first and closed last, so that torque goes off on every exit path,
including a failure to reach the arm; SIGTERM and SIGHUP are turned into `SystemExit` for the
duration (`tendon.raise_on_signals`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.errors import HardwareError, PoseError

from .arm import ArmConfig, FrankaArm
from .camera import FileCamera, RealSenseCamera, load_calibration
from .pipeline import (
    GraspPlan,
    GraspReport,
    GraspSettings,
    auto_candidate,
    execute,
    load_candidates,
    select_candidate,
)
from .tendon import FingerMotor, TendonConfig, TendonMotors, raise_on_signals

__all__ = ["RobotGraspJob", "plan_job", "run_job"]

AUTO = "auto"


@dataclass(frozen=True)
class RobotGraspJob:
    """One `hw grasp` request.

    Args:
        robot: Robot FCI host (None only for a dry run).
        dxl: Serial port of the tendon motors (None only for a dry run).
        pose: Path of a candidate-pose file, or ``"auto"``.
        cloud: Recorded point cloud (PLY/NPZ/NPY), or one per camera (a tuple: merged in the base
            frame); None to capture from a RealSense.
        calibration: Camera-to-base transform file, or one per cloud; None means the clouds are in the
            base frame.
        settings: Grasp parameters and limits.
        motors: Tendon motors, one per finger.
        speed_factor: franky relative dynamics factor in (0, 1].
        grasp_force: Franka Hand grasp force [N].
        tendon_retries: Attempts per serial transaction before the link counts as lost.
        realtime: Require a realtime kernel for the arm (False for franky-sim).
        motion_timeout_s: Longest an arm or hand motion may take (`ArmConfig.motion_timeout_s`).
        dry_run: Plan and report; connect to nothing.
        surrogate: A surrogate checkpoint folder: score every candidate for ``design`` and run the
            feasible one with the best predicted success (`surrogate_select`); None: most points.
        design: The printed fingers' design (a `Stiffness`), needed with ``surrogate``.
        density: Object density the surrogate assumes [kg/m³]; None: the real regime's density of an
            object without a published mass (`mjcodesign.objects.YCB_MEDIAN_DENSITY`, 680).
    """

    robot: str | None
    dxl: str | None
    pose: str = AUTO
    cloud: Path | tuple[Path, ...] | None = None
    calibration: Path | tuple[Path, ...] | None = None
    settings: GraspSettings = field(
        default_factory=GraspSettings
    )  # built when used: its lift reads the scenarios
    motors: tuple[FingerMotor, ...] = (FingerMotor(1, "A"), FingerMotor(2, "B"))
    speed_factor: float = 0.1
    grasp_force: float = 20.0
    tendon_retries: int = 3
    latency_ms: float = 16.0
    """USB-serial adapter latency [ms] (`hardware.tendon.TendonConfig.latency_ms`)."""
    realtime: bool = True
    motion_timeout_s: float = 60.0
    dry_run: bool = False
    surrogate: Path | None = None
    design: object | None = None
    density: float | None = None

    def __post_init__(self) -> None:
        if self.density is None:
            from mjcodesign.objects.mesh import YCB_MEDIAN_DENSITY  # here: the objects import trimesh

            object.__setattr__(self, "density", YCB_MEDIAN_DENSITY)
        if not self.dry_run and not (self.robot and self.dxl):
            raise HardwareError("a grasp needs --robot and --dxl (or --dry-run)")
        if self.surrogate is not None and self.design is None:
            raise HardwareError("--surrogate scores candidates for a design: give --design too")
        if not (np.isfinite(self.density) and self.density > 0):
            raise HardwareError(f"density must be a finite value > 0 kg/m³, got {self.density}")
        if self.cloud is None and self.calibration is None:
            raise HardwareError("give a point cloud file, or a calibration file for the camera")

    def tendon_config(self) -> TendonConfig:
        """Tendon configuration (a placeholder port in a dry run, for limit checks only)."""
        return TendonConfig(
            port=self.dxl or "(dry run)",
            motors=self.motors,
            retries=self.tendon_retries,
            latency_ms=self.latency_ms,
        )

    def arm_config(self) -> ArmConfig:
        """Arm configuration."""
        return ArmConfig(
            host=self.robot or "(dry run)",
            speed_factor=self.speed_factor,
            grasp_force=self.grasp_force,
            workspace=self.settings.workspace,
            realtime=self.realtime,
            motion_timeout_s=self.motion_timeout_s,
        )


def _paths(value) -> tuple[Path, ...]:
    if value is None:
        return ()
    return tuple(Path(v) for v in value) if isinstance(value, tuple | list) else (Path(value),)


def _capture(job: RobotGraspJob) -> np.ndarray:
    """The object's cloud in the base frame: the recorded clouds of every camera, merged.

    Each cloud is mapped by its own calibration (one per cloud, or one for all of them).
    """
    clouds, calibs = _paths(job.cloud), _paths(job.calibration)
    Ts = [load_calibration(c) for c in calibs]
    if clouds:
        if len(Ts) not in (0, 1, len(clouds)):
            raise HardwareError(
                f"{len(clouds)} clouds need one calibration each or one for all, got {len(Ts)}"
            )
        per = Ts if len(Ts) == len(clouds) else [Ts[0] if Ts else None] * len(clouds)
        return np.concatenate([FileCamera(c, T).capture() for c, T in zip(clouds, per, strict=True)])
    if len(Ts) != 1:
        raise HardwareError(
            "a live capture uses one RealSense camera: give one calibration, or recorded clouds"
        )
    return RealSenseCamera(Ts[0]).capture()


def plan_job(job: RobotGraspJob) -> tuple[np.ndarray, GraspPlan]:
    """Steps 1-3 and the plan: cloud, candidates, selection. Moves nothing."""
    tendon = job.tendon_config()
    tendon.check_pull(job.settings.tendon_ticks)  # refuse a bad tick count before anything
    arm = job.arm_config()  # validates the speed factor
    del arm
    cloud = _capture(job)
    geometry = job.settings.geometry
    if job.pose == AUTO:
        candidates = [auto_candidate(cloud, geometry)]
    else:
        candidates = load_candidates(job.pose, geometry)
    if not candidates:
        raise PoseError("no candidate poses")
    scores = None
    if job.surrogate is not None:
        from .surrogate_select import score_candidates

        ranked, _ = score_candidates(job.surrogate, job.design, job.density, cloud, candidates, geometry)
        scores = {s.index: s.as_dict() for s in ranked}
    return cloud, select_candidate(candidates, cloud, job.settings, tendon, scores)


def run_job(
    job: RobotGraspJob,
    log: Callable[[str], None] = print,
    after_lift: Callable[[], object] | None = None,
) -> GraspReport | GraspPlan:
    """Plan, then (unless a dry run) execute on the arm and tendons. Returns the report or plan.

    `after_lift` is passed to `pipeline.execute`.
    """
    _, plan = plan_job(job)
    for line in plan.lines():
        log(("[dry run] " if job.dry_run else "") + line)
    if job.dry_run:
        return plan
    with raise_on_signals(), TendonMotors(job.tendon_config()) as tendons:
        with FrankaArm(job.arm_config()) as arm:
            return execute(plan, arm, tendons, log, after_lift)
