import mujoco
import numpy as np
import pytest

from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import PoseError
from mjcodesign.models.builder import build_gripper, make_data
from mjcodesign.models.simulate import check_state
from mjcodesign.models.tendon import TendonDriver
from mjcodesign.models.types import FingerModel, GripperPose, TendonMode


def _tips_y(m, d):
    return [float(d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{x}_tip"), 1]) for x in "AB"]


@pytest.mark.parametrize("mode", [TendonMode.NATIVE, TendonMode.POINT_FORCE])
def test_gripper_closes_and_lifts(mode):
    pose = GripperPose(position=(0, 0, 0.3), openings=(0.03, 0.03))
    built = build_gripper(
        FingerDesign(), Stiffness.preset("semi-rigid"), FingerModel.CHAIN, pose=pose, tendon_mode=mode
    )
    m = built.model
    d = make_data(built)
    a0, b0 = _tips_y(m, d)
    # finger A's inner face is at y = +30 mm, B's at -30 mm; tips sit 1 mm behind the inner face's spine
    assert a0 == pytest.approx(0.03 + 0.014 - 0.001) and b0 == pytest.approx(-a0)
    # fingers hang from the palm: tips are below it, and openings place the inner faces at +-30 mm
    assert d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "A_tip"), 2] < 0.3 - 0.12
    drv = TendonDriver(built)
    lift = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "lift")
    for i in range(500):
        drv.set_tension(d, 1.0)
        d.ctrl[lift] = 0.03 if i > 250 else 0.0
        drv.apply(d)
        mujoco.mj_step(m, d)
    check_state(d)
    a1, b1 = _tips_y(m, d)
    assert a1 < a0 - 0.01 and b1 > b0 + 0.01  # tendons curl the tips towards each other
    palm = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "palm")
    assert d.xpos[palm, 2] == pytest.approx(0.33, abs=0.003)


def test_pose_validation():
    with pytest.raises(PoseError):
        GripperPose(openings=(0.1, 0.01))
    with pytest.raises(PoseError):
        GripperPose(quat=(1, 1, 0, 0))
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.0, 0.2]
    assert GripperPose.from_matrix(T).position == pytest.approx((0.1, 0.0, 0.2))


def test_flex_gripper_builds_with_per_block_cells():
    built = build_gripper(FingerDesign(), Stiffness.preset("paper-optimized"), FingerModel.FLEX)
    assert built.model.nflex == 2
    a, b = (h.cell_young for h in built.fingers)
    assert not np.allclose(a, b)  # the two fingers carry their own designs
