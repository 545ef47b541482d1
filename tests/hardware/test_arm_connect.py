"""Connecting to the arm: an address nobody answers, or a port that answers but never speaks, is refused
in seconds with one line (libfranka alone waited 60 s for either, a core busy in the kernel)."""

from __future__ import annotations

import socket
import time

import pytest

from mjcodesign.errors import HardwareError

pytest.importorskip("franky")

from mjcodesign.hardware import arm  # noqa: E402
from mjcodesign.hardware.arm import FCI_COMMAND_PORT, ArmConfig, FrankaArm  # noqa: E402

# A loopback address of its own (the Ray tests use 127.0.0.2 and .3): libfranka always dials port 1337.
_HOST = "127.0.0.4"
_HANDSHAKE_S = 1.0  # the handshake's deadline in these tests (15 s in use)
_REFUSE_S = 10.0  # [s] either refusal, the deadline above included, on a loaded 2-core machine


def _open(monkeypatch) -> HardwareError:
    monkeypatch.setattr(arm, "_HANDSHAKE_S", _HANDSHAKE_S)
    t0 = time.monotonic()
    with pytest.raises(HardwareError) as info:
        FrankaArm(ArmConfig(host=_HOST, realtime=False)).open()
    assert time.monotonic() - t0 < _REFUSE_S
    return info.value


def test_nobody_on_the_command_port_is_refused_at_once(monkeypatch):
    with socket.socket() as probe:  # the port is free on this address: nothing answers there
        probe.bind((_HOST, FCI_COMMAND_PORT))
    err = _open(monkeypatch)
    assert str(err).startswith(f"arm: no robot answers at {_HOST}:{FCI_COMMAND_PORT} (")


def test_a_port_that_answers_but_never_speaks_is_refused_after_the_handshake_deadline(monkeypatch):
    with socket.socket() as silent:  # the kernel completes the connection; nothing ever replies
        silent.bind((_HOST, FCI_COMMAND_PORT))
        silent.listen(8)
        err = _open(monkeypatch)
    # closing the listener ends the abandoned libfranka connection in its thread
    assert str(err) == (
        f"arm: robot {_HOST} accepted the connection but libfranka's handshake did not finish within "
        f"{_HANDSHAKE_S:g} s (is a Franka controller, or franky-sim, on port {FCI_COMMAND_PORT} there?)"
    )
