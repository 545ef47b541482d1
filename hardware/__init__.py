"""Hardware: Franka arm (franky), XL330 tendon motors (dynamixel-sdk), point-cloud camera.

Heavy dependencies (franky, dynamixel_sdk, pyrealsense2, franky_sim) are imported only when a
driver is opened, so ``import hardware`` stays light.
"""

from .arm import ArmConfig, FrankaArm, Workspace
from .camera import FileCamera, GripperGeometry, RealSenseCamera, crop_to_gripper, load_point_cloud
from .dxl_emulator import XL330Emulator
from .grasp import RobotGraspJob, plan_job, run_job
from .pipeline import Candidate, GraspPlan, GraspReport, GraspSettings
from .tendon import FingerMotor, TendonConfig, TendonMotors

__all__ = [
    "ArmConfig",
    "Candidate",
    "FileCamera",
    "FingerMotor",
    "FrankaArm",
    "RobotGraspJob",
    "GraspPlan",
    "GraspReport",
    "GraspSettings",
    "GripperGeometry",
    "RealSenseCamera",
    "TendonConfig",
    "TendonMotors",
    "Workspace",
    "XL330Emulator",
    "crop_to_gripper",
    "load_point_cloud",
    "plan_job",
    "run_job",
]
