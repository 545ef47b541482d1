"""``mjcodesign hw …``: grasp, tendon, status, emulate-dxl, selftest.

`add_parser(subparsers)` registers the ``hw`` command on the main CLI's subparsers; its handler
is `run(args) -> int`. Library errors propagate as `MjcodesignError` for the main CLI to map to
exit 2 and one line.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from mjcodesign.cli.common import finite_float, parse_design, path_text
from mjcodesign.design.servo import PAPER_TICKS
from mjcodesign.errors import HardwareError

__all__ = ["add_parser", "run"]

_EXIT_REFUSED = 2
_MAX_ID = 252  # Dynamixel protocol 2.0: 253..255 are reserved (254 is the broadcast ID)


def _ids(text: str) -> tuple[int, ...]:
    try:
        ids = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"motor IDs must be integers, got {text!r}") from None
    if not ids or any(not 0 <= i <= _MAX_ID for i in ids) or len(set(ids)) != len(ids):
        raise argparse.ArgumentTypeError(f"motor IDs must be distinct and in 0..{_MAX_ID}, got {text!r}")
    return ids


def _path(text: str) -> Path:
    return Path(path_text(text))


_SHIPPED = object()  # a bare ``--surrogate`` (not a str: argparse would pass a str const through type=)


def _surrogate(value: Path | object | None) -> Path | None:
    """``hw grasp``'s checkpoint: the folder given, the shipped one for a bare ``--surrogate``, or None."""
    if value is not _SHIPPED:
        return value
    from mjcodesign.surrogate.shipped import checkpoint_or_shipped

    return Path(checkpoint_or_shipped(None, "--surrogate"))


def _paths(text: str) -> tuple[Path, ...]:
    return tuple(Path(path_text(t.strip())) for t in text.split(","))


def _box(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(t) for t in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 6:
        raise argparse.ArgumentTypeError("workspace is xmin,ymin,zmin,xmax,ymax,zmax in metres")
    return values


def _add_motor_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--ids", type=_ids, default=(1, 2), help="tendon motor IDs (default 1,2)")
    p.add_argument("--min-ticks", type=int, default=-100, help="per-finger lower pull limit")
    p.add_argument("--max-ticks", type=int, default=1500, help="per-finger upper pull limit")
    p.add_argument(
        "--latency-ms",
        type=float,
        default=16.0,
        help="USB-serial adapter latency [ms]; the reply window is bytes*t_byte + 2*latency + 2 ms",
    )


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``hw`` and its sub-commands on `subparsers`; sets ``func=run``."""
    hw = subparsers.add_parser("hw", help="hardware: Franka arm, XL330 tendon motors, camera")
    sub = hw.add_subparsers(dest="hw_command", required=True)

    g = sub.add_parser("grasp", help="plan and run one grasp on the robot")
    g.add_argument("--robot", help="Franka FCI host")
    g.add_argument("--dxl", help="serial port of the tendon motors")
    g.add_argument("--pose", type=path_text, default="auto", help="pose file (.npz/.npy of 4x4) or 'auto'")
    g.add_argument(
        "--cloud",
        type=_paths,
        help="point cloud file (.ply/.npz/.npy), or one per camera, comma-separated (merged)",
    )
    g.add_argument(
        "--calib",
        type=_paths,
        help="camera-to-base calibration (.json/.npz/.npy), or one per --cloud, comma-separated",
    )
    g.add_argument("--ticks", type=int, default=PAPER_TICKS, help="tendon pull [ticks of 4096]")
    g.add_argument(
        "--lift", type=float, default=None, help="lift height [m] (default: the paper's hardware lift)"
    )
    g.add_argument("--speed", type=float, default=0.1, help="franky speed factor (0, 1]")
    g.add_argument("--force", type=float, default=20.0, help="hand grasp force [N]")
    g.add_argument("--workspace", type=_box, help="xmin,ymin,zmin,xmax,ymax,zmax [m]")
    g.add_argument("--no-realtime", action="store_true", help="allow a non-realtime kernel")
    g.add_argument("--dry-run", action="store_true", help="print the plan, touch nothing")
    g.add_argument(
        "--surrogate",
        type=_path,
        nargs="?",
        const=_SHIPPED,
        default=None,
        metavar="CKPT",
        help="surrogate checkpoint: run the candidate it predicts best (--surrogate alone: the shipped weights)",
    )
    g.add_argument("--design", default=None, help="the printed design (preset, 22 ln E or a design file)")
    g.add_argument(
        "--density",
        type=finite_float(0.0, strict=True),
        default=None,
        help="object density the surrogate assumes [kg/m³] (default: 680, the real regime's for an object "
        "without a published mass, the median of the YCB objects')",
    )
    g.add_argument("--json", action="store_true", help="print the report as JSON")
    _add_motor_args(g)

    t = sub.add_parser("tendon", help="pull the tendons by N ticks from slack, then release")
    t.add_argument("--dxl", required=True, help="serial port of the tendon motors")
    t.add_argument("--ticks", type=int, required=True, help="pull from slack [ticks]")
    t.add_argument("--hold", type=finite_float(0.0), default=0.0, help="hold time before release [s]")
    _add_motor_args(t)

    s = sub.add_parser("status", help="report what answers: motors and/or robot")
    s.add_argument("--robot", help="Franka FCI host")
    s.add_argument("--dxl", help="serial port of the tendon motors")
    s.add_argument("--no-realtime", action="store_true", help="allow a non-realtime kernel")
    _add_motor_args(s)

    e = sub.add_parser("emulate-dxl", help="run the XL330 emulator on a pty; prints the port")
    e.add_argument("--ids", type=_ids, default=(1, 2), help="emulated motor IDs")
    e.add_argument(
        "--speed", type=finite_float(0.0, strict=True), default=4000.0, help="follow speed [tick/s]"
    )
    e.add_argument(
        "--seconds", type=finite_float(0.0), default=0.0, help="stop after this long [s] (0: never)"
    )

    st = sub.add_parser("selftest", help="whole grasp against franky-sim and the emulator")
    st.add_argument("--json", action="store_true", help="print the result as JSON")
    st.add_argument(
        "--timeout-s",
        type=float,
        default=150.0,
        help="watchdog: past this, print every thread's stack and exit 1 (a hang in a peer) [s]",
    )
    st.add_argument(
        "--surrogate", type=_path, default=None, help="surrogate checkpoint: choose the grasp with it"
    )
    st.add_argument(
        "--design", default=None, help="the design the surrogate scores (preset, 22 ln E or a file)"
    )
    st.add_argument(
        "--density",
        type=finite_float(0.0, strict=True),
        default=None,
        help="object density the surrogate assumes [kg/m³] (default: the selftest box's own, 417)",
    )

    hw.set_defaults(func=run)
    return hw


def _motors(args: argparse.Namespace) -> tuple:
    from mjcodesign.hardware.tendon import FingerMotor

    names = "ABCDEFGH"
    return tuple(
        FingerMotor(i, names[k] if k < len(names) else "", args.min_ticks, args.max_ticks)
        for k, i in enumerate(args.ids)
    )


def _grasp(args: argparse.Namespace) -> int:
    from mjcodesign.hardware.arm import Workspace
    from mjcodesign.hardware.grasp import RobotGraspJob, run_job
    from mjcodesign.hardware.pipeline import GraspReport, GraspSettings

    box = args.workspace
    ws = Workspace() if box is None else Workspace(box[:3], box[3:])
    job = RobotGraspJob(
        robot=args.robot,
        dxl=args.dxl,
        pose=args.pose,
        cloud=args.cloud,
        calibration=args.calib,
        settings=GraspSettings(
            workspace=ws, tendon_ticks=args.ticks, **({} if args.lift is None else {"lift_m": args.lift})
        ),
        motors=_motors(args),
        latency_ms=args.latency_ms,
        speed_factor=args.speed,
        grasp_force=args.force,
        realtime=not args.no_realtime,
        dry_run=args.dry_run,
        surrogate=_surrogate(args.surrogate),
        design=None if args.design is None else parse_design(args.design),
        density=args.density,
    )
    if job.surrogate is not None and not job.surrogate.is_dir():
        raise HardwareError(f"--surrogate: {job.surrogate} is not a checkpoint folder")
    result = run_job(job, log=(lambda line: None) if args.json else print)
    if isinstance(result, GraspReport):
        if args.json:
            print(json.dumps(result.as_dict()))
        else:
            print(f"held: {result.held}, lift {result.lift_m:.3f} m, tendon {result.tendon_ticks}")
        return 0 if result.ok else 1
    if args.json:
        extra = {"candidates": list(result.ranking), "selected": result.index} if result.ranking else {}
        print(json.dumps({"dry_run": True, "plan": result.lines(), **extra}))
    return 0


def _tendon(args: argparse.Namespace) -> int:
    from mjcodesign.hardware.tendon import TendonConfig, TendonMotors, raise_on_signals

    config = TendonConfig(port=args.dxl, motors=_motors(args), latency_ms=args.latency_ms)
    config.check_pull(args.ticks)  # refuse before opening the port
    with raise_on_signals(), TendonMotors(config) as motors:
        report = motors.pull_report(args.ticks)
        print(
            "displacement [ticks]: " + ", ".join(f"ID {i}: {r.displacement_ticks}" for i, r in report.items())
        )
        print(
            "ended: "
            + ", ".join(f"ID {i}: {r.outcome.value} at {r.current_ma} mA" for i, r in report.items())
        )
        time.sleep(args.hold)
    print("torque off")
    return 0


def _status(args: argparse.Namespace) -> int:
    if not (args.robot or args.dxl):
        raise HardwareError("give --robot and/or --dxl")
    if args.dxl:
        from mjcodesign.hardware.tendon import TendonConfig, TendonMotors

        with TendonMotors(
            TendonConfig(port=args.dxl, motors=_motors(args), latency_ms=args.latency_ms)
        ) as motors:
            pos = motors.slack
        print("tendon motors: " + ", ".join(f"ID {i} at {p} ticks" for i, p in pos.items()))
    if args.robot:
        from mjcodesign.hardware.arm import ArmConfig, FrankaArm

        with FrankaArm(ArmConfig(host=args.robot, realtime=not args.no_realtime)) as arm:
            xyz = ", ".join(f"{v:.3f}" for v in arm.pose()[:3, 3])
            print(f"arm: end effector at ({xyz}) m, hand {arm.width():.4f} m")
    return 0


def _emulate(args: argparse.Namespace) -> int:
    from mjcodesign.hardware.dxl_emulator import XL330Emulator

    with XL330Emulator(ids=args.ids, speed_ticks_s=args.speed) as emu:
        print(emu.port, flush=True)
        try:
            deadline = time.monotonic() + args.seconds if args.seconds > 0 else float("inf")
            while time.monotonic() < deadline:
                time.sleep(0.1)
        except KeyboardInterrupt:
            pass
    return 0


def _selftest(args: argparse.Namespace) -> int:
    import faulthandler

    from mjcodesign.hardware.selftest import STATE_CHANNEL_NOTE, run_selftest

    if not args.timeout_s > 0:
        raise HardwareError(f"--timeout-s must be positive, got {args.timeout_s}")
    if (args.surrogate is None) != (args.design is None):
        raise HardwareError(
            "--surrogate and --design go together: the surrogate scores candidates for that design"
        )
    if args.surrogate is not None and not args.surrogate.is_dir():
        raise HardwareError(f"--surrogate: {args.surrogate} is not a checkpoint folder")
    if args.design is not None:
        parse_design(args.design)  # refused before any process starts
    # franky's and the SDK's blocking calls cannot be interrupted from Python; if a peer hangs
    # in a way no motion or serial timeout catches, leave its stacks for the report, not a hang.
    print(STATE_CHANNEL_NOTE, file=sys.stderr)
    faulthandler.dump_traceback_later(args.timeout_s, exit=True)
    try:
        result = run_selftest(
            log=(lambda line: None) if args.json else print,
            surrogate=args.surrogate,
            design=None if args.design is None else parse_design(args.design),
            density=args.density,
        )
    finally:
        faulthandler.cancel_dump_traceback_later()
    print(json.dumps(result) if args.json else f"selftest ok: {result['ok']}")
    return 0 if result["ok"] else 1


_HANDLERS = {
    "grasp": _grasp,
    "tendon": _tendon,
    "status": _status,
    "emulate-dxl": _emulate,
    "selftest": _selftest,
}


def run(args: argparse.Namespace) -> int:
    """Run one ``hw`` sub-command; returns the exit code. Raises `MjcodesignError` on refusal."""
    return _HANDLERS[args.hw_command](args)
