"""The selftest's simulator keeps its sockets on loopback, the UDP state channel included."""

from __future__ import annotations

import gc
import os
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("franky")
pytest.importorskip("franky_sim")

from mjcodesign.hardware.selftest import franka_sim  # noqa: E402

_LOOPBACK_HEX = "0100007F"  # 127.0.0.1 as /proc/net/udp writes it
_WAIT_S = 20.0


def _udp_sockets_of(pids: set[int]) -> dict[str, str]:
    """Inode -> local address (hex) of the IPv4 UDP sockets the processes ``pids`` hold."""
    inodes = set()
    for pid in pids:
        try:
            for fd in Path(f"/proc/{pid}/fd").iterdir():
                target = os.readlink(fd)
                if target.startswith("socket:["):
                    inodes.add(target[8:-1])
        except OSError:
            continue
    rows = Path("/proc/net/udp").read_text().splitlines()[1:]
    return {f[9]: f[1].split(":")[0] for f in (r.split() for r in rows) if f[9] in inodes}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads sockets from /proc")
def test_the_simulator_binds_its_udp_state_channel_to_loopback(children):
    # franky-sim binds the channel to 0.0.0.0 itself; the selftest's simulator process rebinds it.
    import franky

    with franka_sim(box=False) as scene:
        robot = franky.Robot(scene.host, realtime_config=franky.RealtimeConfig.Ignore)  # opens the channel
        try:
            deadline = time.monotonic() + _WAIT_S
            while not (found := _udp_sockets_of(children())) and time.monotonic() < deadline:
                time.sleep(0.05)
            assert found, "the simulator opened no UDP socket"
            assert set(found.values()) == {_LOOPBACK_HEX}, found
        finally:
            del robot
            gc.collect()
