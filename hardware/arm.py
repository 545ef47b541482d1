"""Franka arm and Franka Hand through franky-control.

All Cartesian targets are absolute poses of franky's end-effector frame in the robot base
(world) frame, as 4x4 homogeneous matrices [m]. franky's `ReferenceType.Relative` moves are in the
end-effector frame (z points down for a top-down grasp), so a "lift 10 cm" is built here as an
absolute target: the present pose plus 0.10 m along world z. Every target is checked against the
workspace box before the robot is asked to move.

``franky`` is imported lazily, inside `FrankaArm.open`.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from mjcodesign.errors import HardwareError, PoseError

__all__ = ["ArmConfig", "FrankaArm", "Workspace", "check_fci", "check_transform"]

FRANKA_HAND_MAX_WIDTH = 0.08  # Franka Hand stroke [m], from the Franka datasheet
_RIGID_TOL = 1e-4  # |R^T R - I| and |det R - 1| tolerance for a pose matrix
_T = TypeVar("_T")
_UNANSWERED: list[tuple[Any, Any]] = []  # hand connections with a command that never answered
_UNRESPONSIVE: list[Any] = []  # robot connections whose motion did not end after a stop
FCI_COMMAND_PORT = 1337
"""libfranka's TCP command port on the robot's controller (franky-sim listens on it too)."""
_FCI_CONNECT_S = 5.0
"""Longest wait for the controller's command port to accept a TCP connection before libfranka is asked
[s]: on a LAN it answers in milliseconds; libfranka's own connect waits 60 s (measured: 65 s to refuse
an address nobody answers, a core busy in the kernel throughout)."""
_HANDSHAKE_S = 15.0
"""Longest wait for libfranka's connection to the robot or the hand to complete once the port answers
[s]: a controller answers its handshake in milliseconds, franky-sim on a loaded machine in well under a
second; a peer that accepts TCP but never speaks (a proxy, another service on the port) would hold
libfranka for 60 s."""
_STOP_WAIT_S = 5.0
"""Longest wait for a stopped arm motion to end [s]: a stop decelerates the arm within about a second
(franky's stop motion; franky-sim alike), so longer means the connection no longer answers."""


def check_fci(host: str, *, port: int = FCI_COMMAND_PORT, timeout: float = _FCI_CONNECT_S) -> None:
    """Raise :class:`HardwareError` unless ``host`` accepts a TCP connection on ``port`` within ``timeout`` [s].

    The connection is closed again at once, before any libfranka message (the controller and franky-sim
    treat it as a client that went away).
    """
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except socket.gaierror as exc:
        raise HardwareError(f"arm: cannot resolve robot host {host!r} ({exc.strerror})") from None
    except OSError as exc:
        why = f"no answer within {timeout:g} s" if isinstance(exc, TimeoutError) else exc.strerror or exc
        raise HardwareError(
            f"arm: no robot answers at {host}:{port} ({why}); check the address, the network and that "
            "FCI is activated in Desk"
        ) from None


def check_transform(matrix: Any, what: str = "pose") -> np.ndarray:
    """Return `matrix` as a float (4, 4) rigid transform, or raise `PoseError`."""
    try:
        T = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError) as exc:
        raise PoseError(f"{what} is not numeric: {exc}") from None
    if T.shape != (4, 4):
        raise PoseError(f"{what} must be a 4x4 matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise PoseError(f"{what} has NaN or inf entries")
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > _RIGID_TOL
        or abs(np.linalg.det(R) - 1.0) > _RIGID_TOL
        or np.abs(T[3] - (0, 0, 0, 1)).max() > _RIGID_TOL
    ):
        raise PoseError(f"{what} is not a rigid transform (rotation not orthonormal)")
    return T


@dataclass(frozen=True)
class Workspace:
    """Axis-aligned box that the end-effector position must stay in, base frame [m].

    The default box sits in front of the robot and above the table (z = 0), within the FR3's
    855 mm reach.
    """

    lo: tuple[float, float, float] = (0.25, -0.45, 0.005)
    hi: tuple[float, float, float] = (0.80, 0.45, 0.70)

    def __post_init__(self) -> None:
        if len(self.lo) != 3 or len(self.hi) != 3:
            raise PoseError("workspace corners need three coordinates each")
        if not all(a < b for a, b in zip(self.lo, self.hi, strict=True)):
            raise PoseError(f"workspace lower corner {self.lo} is not below upper corner {self.hi}")

    def check(self, pose: np.ndarray, what: str = "target") -> None:
        """Raise `PoseError` if the translation of the (4, 4) `pose` is outside the box."""
        p = np.asarray(pose, dtype=float)[:3, 3]
        if np.any(p < self.lo) or np.any(p > self.hi):
            xyz = ", ".join(f"{v:.3f}" for v in p)
            raise PoseError(f"{what} ({xyz}) m is outside the workspace box {self.lo}..{self.hi} m")


@dataclass(frozen=True)
class ArmConfig:
    """Connection and motion limits of the arm.

    Args:
        host: FCI hostname or IP address of the robot (or of franky-sim).
        speed_factor: franky relative dynamics factor in (0, 1]: scales velocity,
            acceleration and jerk limits.
        workspace: Box that every target must stay in.
        gripper_speed: Franka Hand finger speed [m/s].
        grasp_force: Franka Hand grasp force [N].
        realtime: Require a realtime kernel (True on the real robot; False for franky-sim).
        motion_timeout_s: Longest an arm or hand motion may take before it is stopped and
            reported [s]. franky's blocking calls wait forever; a motion that neither
            finishes nor fails (a lost reply, a stalled controller) must not hang the job.
    """

    host: str
    speed_factor: float = 0.1
    workspace: Workspace = Workspace()
    gripper_speed: float = 0.05
    grasp_force: float = 20.0
    realtime: bool = True
    motion_timeout_s: float = 60.0

    def __post_init__(self) -> None:
        if not self.host:
            raise HardwareError("no robot host given")
        if not 0.0 < self.speed_factor <= 1.0:
            raise HardwareError(f"speed factor must be in (0, 1], got {self.speed_factor}")
        if not 0.0 < self.gripper_speed <= 0.1:  # Franka Hand: 0.1 m/s at most (datasheet)
            raise HardwareError(f"gripper speed must be in (0, 0.1] m/s, got {self.gripper_speed}")
        if not 0.0 < self.grasp_force <= 140.0:  # Franka Hand: 140 N continuous (datasheet)
            raise HardwareError(f"grasp force must be in (0, 140] N, got {self.grasp_force}")
        if not 0.0 < self.motion_timeout_s < float("inf"):
            raise HardwareError(f"motion timeout must be positive, got {self.motion_timeout_s} s")


def _within(what: str, connect: Callable[[], _T], seconds: float | None = None) -> _T:
    """``connect()``'s result, run in a daemon thread; :class:`HardwareError` past ``seconds`` [s].

    ``seconds`` defaults to :data:`_HANDSHAKE_S`.

    libfranka's connection releases the GIL while it waits; one that is given up runs on in its thread
    until libfranka's own timeout ends it, without holding up the process's exit.
    """
    out: dict[str, Any] = {}

    def run() -> None:
        try:
            out["value"] = connect()
        except BaseException as exc:  # handed to the caller's thread
            out["error"] = exc

    seconds = _HANDSHAKE_S if seconds is None else seconds
    thread = threading.Thread(target=run, name="franky-connect", daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        raise HardwareError(
            f"arm: {what} accepted the connection but libfranka's handshake did not finish within "
            f"{seconds:g} s (is a Franka controller, or franky-sim, on port {FCI_COMMAND_PORT} there?)"
        )
    if "error" in out:
        raise out["error"]
    return out["value"]


class FrankaArm:
    """Franka arm with Franka Hand over franky. Use as a context manager (connects on enter)."""

    def __init__(self, config: ArmConfig) -> None:
        self.config = config
        self._franky: Any = None
        self._robot: Any = None
        self._gripper: Any = None

    def __enter__(self) -> FrankaArm:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Connect to the robot and the hand, clear any reflex error, set the speed factor."""
        check_fci(self.config.host)
        import franky

        self._franky = franky
        rt = franky.RealtimeConfig.Enforce if self.config.realtime else franky.RealtimeConfig.Ignore
        self._robot = self._call(
            f"connect to robot {self.config.host}",
            lambda: _within(
                f"robot {self.config.host}", lambda: franky.Robot(self.config.host, realtime_config=rt)
            ),
        )
        self._gripper = self._call(
            f"connect to Franka Hand at {self.config.host}",
            lambda: _within(f"Franka Hand at {self.config.host}", lambda: franky.Gripper(self.config.host)),
        )
        self.recover()
        self._robot.relative_dynamics_factor = self.config.speed_factor

    def close(self) -> None:
        """Stop any motion still running, then drop the connections (franky closes them).

        A `franky.Robot` destroyed while a motion winds down blocks in its destructor, so the
        motion is stopped and joined first.
        """
        robot, self._robot = self._robot, None
        if robot is not None:
            self._halt(robot)
        self._gripper = None

    # ---- state ----

    def pose(self) -> np.ndarray:
        """Present end-effector pose in the base frame, shape (4, 4) [m]."""
        return np.array(self._connected().current_pose.end_effector_pose.matrix, dtype=float)

    def width(self) -> float:
        """Present Franka Hand opening [m]."""
        return float(self._call("read the hand width", lambda: self._hand().width))

    def has_errors(self) -> bool:
        """Whether the robot reports an error (reflex) that needs recovery."""
        return bool(self._connected().has_errors)

    # ---- motion ----

    def move_to(self, target: np.ndarray, what: str = "target") -> None:
        """Move the end effector to the absolute base-frame pose `target` (4, 4) [m]."""
        T = check_transform(target, what)
        self.config.workspace.check(T, what)
        franky = self._franky
        motion = franky.CartesianMotion(franky.Affine(T), franky.ReferenceType.Absolute)
        robot = self._connected()

        def move() -> None:
            robot.move(motion, asynchronous=True)
            if not robot.join_motion(timeout=self.config.motion_timeout_s):
                how = (
                    "the robot was stopped"
                    if self._halt(robot)
                    else f"it did not stop within {_STOP_WAIT_S:g} s either"
                )
                raise HardwareError(
                    f"arm: move to {what} did not finish within {self.config.motion_timeout_s:g} s; {how}"
                )

        self._call(f"move to {what}", move, recover=True)

    def lift(self, height: float) -> None:
        """Move straight up by `height` along world z, keeping the orientation [m]."""
        T = self.pose()
        T[2, 3] += height
        self.move_to(T, "lift target")

    def set_width(self, width: float) -> None:
        """Move the Franka Hand fingers to `width` [m] without grasping."""
        self._check_width(width)
        ok = self._call(
            "move the hand",
            lambda: self._hand_wait("move", self._hand().move_async(width, self.config.gripper_speed)),
        )
        if not ok:
            raise HardwareError(f"Franka Hand did not reach width {width:.4f} m")

    def grasp(self, width: float) -> None:
        """Close the hand toward `width` [m] with the configured force.

        The fingers stop where they meet the object, so no inner/outer tolerance is imposed
        here; whether the object is held is judged after the lift.
        """
        self._check_width(width)
        self._call(
            "grasp",
            lambda: self._hand_wait(
                "grasp",
                self._hand().grasp_async(
                    width,
                    self.config.gripper_speed,
                    self.config.grasp_force,
                    epsilon_inner=FRANKA_HAND_MAX_WIDTH,
                    epsilon_outer=FRANKA_HAND_MAX_WIDTH,
                ),
            ),
        )

    def recover(self) -> None:
        """Clear a reflex error (e.g. a collision) so that the robot accepts motions again."""
        robot = self._connected()
        if robot.has_errors and not robot.recover_from_errors():
            raise HardwareError("robot reports an error that automatic recovery did not clear")

    # ---- helpers ----

    def _connected(self) -> Any:
        if self._robot is None:
            raise HardwareError("arm is not connected")
        return self._robot

    def _hand(self) -> Any:
        if self._gripper is None:
            raise HardwareError("Franka Hand is not connected")
        return self._gripper

    def _halt(self, robot: Any) -> bool:
        """Stop the arm's motion if one is running and wait until it has ended; whether it has.

        A motion that has not ended :data:`_STOP_WAIT_S` after the stop leaves the connection parked
        and dropped: destroying a `franky.Robot` with a motion still running blocks in its destructor.
        """
        errors = (self._franky.Exception, RuntimeError)
        try:
            if robot.join_motion(timeout=0.0):
                return True
        except errors:  # the finished motion's own error, already reported by its caller
            return True
        robot.stop()
        try:
            if robot.join_motion(timeout=_STOP_WAIT_S):
                return True
        except errors:  # "Move command preempted": the stop itself
            return True
        _UNRESPONSIVE.append(robot)
        if self._robot is robot:
            self._robot = None
        return False

    def _hand_wait(self, what: str, future: Any) -> bool:
        """The result of a Franka Hand command's future; stop the hand if it runs past the timeout."""
        if not future.wait(self.config.motion_timeout_s):
            self._gripper.stop()
            if not future.wait(self.config.motion_timeout_s):
                # The stopped command never answered (the real hand answers a stop; franky-sim's
                # drops the reply). libfranka's destructor waits for that reply, so the connection
                # is parked rather than destroyed here; it still holds up interpreter exit, which
                # `hw selftest`'s watchdog bounds.
                _UNANSWERED.append((self._gripper, future))
                self._gripper = None
            raise HardwareError(
                f"arm: hand {what} did not finish within {self.config.motion_timeout_s:g} s; "
                "the hand was stopped"
            )
        return bool(future.get())

    def _check_width(self, width: float) -> None:
        if not 0.0 <= width <= FRANKA_HAND_MAX_WIDTH:
            raise PoseError(f"hand width {width:.4f} m is outside [0, {FRANKA_HAND_MAX_WIDTH}] m")

    def _call(self, what: str, fn: Callable[[], _T], recover: bool = False) -> _T:
        """Run a franky call; turn its exceptions into `HardwareError` after recovery."""
        franky = self._franky
        errors = (franky.Exception, franky.GripperException, RuntimeError)
        try:
            return fn()
        except HardwareError:
            raise
        except errors as exc:
            if recover and self._robot is not None:
                try:
                    self._robot.recover_from_errors()
                except errors:
                    pass
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise HardwareError(f"arm: could not {what}: {first}") from exc
