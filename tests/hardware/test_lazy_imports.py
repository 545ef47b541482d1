"""`import mjcodesign.hardware` must not import the heavy SDKs (fresh interpreter)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("franky", "franky_sim", "dynamixel_sdk", "pyrealsense2", "serial", "mujoco")


def test_import_is_light():
    code = (
        "import sys, mjcodesign.hardware, mjcodesign.cli.hardware, mjcodesign.hardware.selftest; "
        f"print([m for m in {HEAVY!r} if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"
