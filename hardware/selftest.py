"""Protocol peers for `hw selftest` and the tests: franky-sim with a box, and the XL330 emulator.

`franka_sim` runs franky-sim's MuJoCo simulator and `SimulationServer` in a child process, bound to
127.0.0.1 only (its UDP state channel too, which franky-sim itself binds to every interface; libfranka's
own UDP socket, in the calling process, it cannot: :data:`STATE_CHANNEL_NOTE`); franky then speaks the libfranka protocol to it over loopback, as to a robot on
the network, and the simulator keeps stepping whatever the client process does (franky's blocking
C++ calls, the GIL, a stuck test). `run_selftest`
performs the whole ``hw grasp`` code path against both peers, starting from a recorded point
cloud in a camera frame plus a calibration file.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mjcodesign.errors import HardwareError

from .camera import save_point_cloud, transform_points
from .dxl_emulator import child_process, emulator_process
from .grasp import RobotGraspJob, run_job
from .pipeline import GraspReport
from .tendon import port_handler
from .xl330 import ADDR

__all__ = ["SimScene", "franka_sim", "run_selftest", "sample_box_surface", "surrogate_candidates"]

LOOPBACK = "127.0.0.1"
BOX_SIZE = (0.06, 0.04, 0.05)  # full extents x, y, z [m]: narrow along y, the closing axis
BOX_CENTRE = (0.5, 0.0, 0.025)  # resting on the ground in front of the robot [m]
BOX_MASS = 0.05  # [kg]
SIM_SPEED_FACTOR = 0.5  # franky dynamics factor in the simulator: fast, and still holds the box
LIFT_OK_FRACTION = 0.8  # the box may slip a little in the PD-controlled hand
SETTLE_S = 0.5  # let the box come to rest in the hand before measuring its lift [s]
_CLOUD_POINTS = 2000
_SIM_START_S = 60.0  # spawn, import MuJoCo and compile the FR3 scene, on a loaded host [s]
_SIM_REPLY_S = 10.0  # a state query to the simulator process [s]
_IDS = (1, 2)
# The selftest runs simulator, franky, SDK and emulator (three processes) on one small machine; a
# serial reply can miss the SDK's window (34 ms at the real adapter's 16 ms latency) when the CPU is
# oversubscribed, so give the emulator a 100 ms adapter latency (as the tests do) and more attempts
# than on the real bus. A CI run lost the link with 16 ms and 10 attempts.
_SELFTEST_RETRIES = 10
_SELFTEST_LATENCY_MS = 100.0
_SELFTEST_MOTION_TIMEOUT_S = 20.0
"""Each selftest motion takes 0.4-1 s on franky-sim; 20 s leaves a stalled one time to be reported as an
error (stop included) well inside the selftest's watchdog, instead of 60 s for the move, then its stop."""
_CANDIDATE_SHIFTS_M = (0.0, -0.008, 0.008)  # surrogate_candidates: along the box's 60-mm side [m]
# A camera 0.6 m above the table looking down at the box, rotated about its optical axis.
_T_BASE_CAMERA = np.array(
    [
        [0.0, -1.0, 0.0, 0.5],
        [-1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 0.6],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


@dataclass
class SimScene:
    """A running franky-sim: host to connect to, and ground-truth reads of the box."""

    host: str
    _conn: Any

    def box_z(self) -> float:
        """Height of the box centre in the world [m]."""
        self._conn.send("box_z")
        if not self._conn.poll(_SIM_REPLY_S):
            raise HardwareError("franky-sim did not answer a state query")
        return float(self._conn.recv())


STATE_CHANNEL_NOTE = (
    "note: libfranka (franky) opens its robot-state channel on UDP port 0 of every interface (0.0.0.0) "
    "while it is connected, reachable from the network; it has no option to bind it to 127.0.0.1 "
    "(franky-sim's side is bound to 127.0.0.1)"
)
"""What the selftest says on stderr about the one socket it cannot keep on loopback."""


def _loopback_datagrams() -> None:
    """In franky-sim's own process: bind its UDP state channel to 127.0.0.1, not every interface.

    franky-sim 1.0.4 binds that socket to ``0.0.0.0`` in ``FrankaServer._setup_udp_connection`` with
    no option; this process runs nothing else, so every IPv4 datagram socket bound to all interfaces
    is bound to loopback instead.
    """
    import socket

    bind = socket.socket.bind

    def loopback_bind(sock, address):
        if sock.family == socket.AF_INET and sock.type == socket.SOCK_DGRAM and address[0] in ("", "0.0.0.0"):
            address = (LOOPBACK, *address[1:])
        return bind(sock, address)

    socket.socket.bind = loopback_bind


def _serve_sim(conn: Any, box: bool) -> None:
    """Child process of `franka_sim`: build and serve the simulator, answer box-height queries."""
    import xml.etree.ElementTree as ET

    _loopback_datagrams()

    import franky_sim
    from franky_sim.mujoco_simulator import MujocoSimulator

    sim = MujocoSimulator()
    sim.init()
    sim.add_robot()
    if box:
        body = ET.SubElement(sim.worldbody, "body", name="box", pos=" ".join(map(str, BOX_CENTRE)))
        ET.SubElement(body, "freejoint", name="box_joint")
        half = " ".join(str(s / 2) for s in BOX_SIZE)
        ET.SubElement(body, "geom", type="box", size=half, mass=str(BOX_MASS))
    server = franky_sim.SimulationServer(sim, hostname_candidates=[LOOPBACK])
    try:
        try:
            server.init()
        except OSError as exc:  # libfranka's fixed ports are taken (another simulator running?)
            conn.send(("error", f"franky-sim cannot serve on {LOOPBACK}: {exc}"))
            return
        server.run_async()
        conn.send(("ready", LOOPBACK))
        box_id = sim.model.body("box").id if box else -1
        while True:
            try:
                request = conn.recv()
            except EOFError:  # the parent is gone
                return
            if request is None:
                return
            conn.send(float(sim.data.xpos[box_id][2]) if box_id >= 0 else float("nan"))
    finally:
        server.cleanup()
        sim.cleanup()


@contextmanager
def franka_sim(box: bool = True) -> Iterator[SimScene]:
    """Run franky-sim (MuJoCo) with one FR3 and optionally a box in a child process, on 127.0.0.1."""
    import importlib.util

    if importlib.util.find_spec("franky_sim") is None:
        raise HardwareError("franky-sim is not installed (needed for the selftest)")
    with child_process(
        _serve_sim, (box,), what="franky-sim", start_s=_SIM_START_S, grace_s=5.0, error=HardwareError
    ) as (conn, (status, detail)):
        if status != "ready":
            raise HardwareError(detail)
        yield SimScene(detail, conn)


def sample_box_surface(
    size: tuple[float, float, float], centre: tuple[float, float, float], n: int, seed: int = 0
) -> np.ndarray:
    """`n` points on the visible faces (top and sides) of a box, shape (n, 3) [m]."""
    rng = np.random.default_rng(seed)
    half = np.asarray(size) / 2
    pts = rng.uniform(-half, half, size=(n, 3))
    # Snap each point to one of five faces (not the bottom, which rests on the table).
    face = rng.integers(0, 5, size=n)
    axis = np.array([2, 0, 0, 1, 1])[face]
    sign = np.array([1, 1, -1, 1, -1])[face]
    pts[np.arange(n), axis] = sign * half[axis]
    return pts + np.asarray(centre)


def torque_over_bus(port: str, ids: tuple[int, ...]) -> dict[int, bool]:
    """Torque Enable of each motor, read over the serial bus with dynamixel-sdk."""
    import dynamixel_sdk as sdk

    handler, packets = port_handler(sdk, port, _SELFTEST_LATENCY_MS), sdk.PacketHandler(2.0)
    if not (handler.openPort() and handler.setBaudRate(57600)):
        raise HardwareError(f"cannot open {port}")
    try:
        out = {}
        for i in ids:
            for _ in range(_SELFTEST_RETRIES):
                value, result, _ = packets.read1ByteTxRx(handler, i, ADDR["torque_enable"])
                if result == sdk.COMM_SUCCESS:
                    break
            else:
                raise HardwareError(f"motor {i} did not answer on {port}")
            out[i] = value == 1
        return out
    finally:
        handler.closePort()


def surrogate_candidates(cloud_base: np.ndarray, path: Path) -> Path:
    """Candidates for the surrogate to choose among, written to ``path`` (npz).

    The auto pose above the box and the same pose shifted along the box's long side (x) by
    :data:`_CANDIDATE_SHIFTS_M`.
    """
    from .camera import GripperGeometry
    from .pipeline import auto_candidate

    c = auto_candidate(cloud_base, GripperGeometry())
    poses = []
    for dx in _CANDIDATE_SHIFTS_M:
        T = c.pose.copy()
        T[0, 3] += dx
        poses.append(T)
    np.savez(path, poses=np.stack(poses), openings=np.full((len(poses), 2), (c.s1, c.s2)))
    return path


def run_selftest(
    log: Callable[[str], None] = lambda line: None,
    *,
    surrogate: Path | None = None,
    design: Any = None,
    density: float | None = None,
) -> dict:
    """The whole grasp against franky-sim and the XL330 emulator; a JSON-ready result.

    With ``surrogate`` (a checkpoint folder) and ``design`` (a Stiffness), the surrogate scores
    :func:`surrogate_candidates` for the design and the best predicted one runs, as on the robot,
    assuming the object's density ``density`` [kg/m³] (None: the box's own, :data:`BOX_MASS` over its
    volume).
    """
    if density is None:
        density = BOX_MASS / float(np.prod(BOX_SIZE))
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="mjcodesign-selftest-") as tmp:
        cloud_base = sample_box_surface(BOX_SIZE, BOX_CENTRE, _CLOUD_POINTS)
        cloud_path, calib_path = Path(tmp) / "cloud.ply", Path(tmp) / "calib.json"
        save_point_cloud(cloud_path, transform_points(cloud_base, np.linalg.inv(_T_BASE_CAMERA)))
        calib_path.write_text(json.dumps({"T_base_camera": _T_BASE_CAMERA.tolist()}))
        pose = "auto" if surrogate is None else str(surrogate_candidates(cloud_base, Path(tmp) / "cands.npz"))
        with emulator_process(ids=_IDS) as port, franka_sim() as scene:
            job = RobotGraspJob(
                robot=scene.host,
                dxl=port,
                pose=pose,
                surrogate=surrogate,
                design=design,
                density=density,
                cloud=cloud_path,
                calibration=calib_path,
                speed_factor=SIM_SPEED_FACTOR,
                tendon_retries=_SELFTEST_RETRIES,
                latency_ms=_SELFTEST_LATENCY_MS,
                realtime=False,
                motion_timeout_s=_SELFTEST_MOTION_TIMEOUT_S,
            )
            z0 = scene.box_z()
            lifted: list[float] = []

            def measure() -> None:
                time.sleep(SETTLE_S)
                lifted.append(scene.box_z() - z0)

            report = run_job(job, log, after_lift=measure)
            assert isinstance(report, GraspReport) and lifted
            object_lift = lifted[0]
            torque_off = not any(torque_over_bus(port, _IDS).values())
    lift_ok = object_lift >= LIFT_OK_FRACTION * job.settings.lift_m
    result = report.as_dict()
    result.update(
        ok=bool(report.held and lift_ok and torque_off),
        lift_m=round(float(object_lift), 5),
        arm_lift_m=round(report.lift_m, 5),
        torque_off_after=torque_off,
        seconds=round(time.monotonic() - t0, 2),
    )
    return result
