"""Protocol peers for the hardware tests: the XL330 emulator and an in-process franky-sim."""

from __future__ import annotations

import pytest

from mjcodesign.hardware.dxl_emulator import XL330Emulator
from mjcodesign.hardware.tendon import port_handler

FAST_TICKS_S = 20_000.0  # emulated motor speed: fast enough that a 1000-tick pull takes 50 ms
SDK_LATENCY_MS = 100.0
"""Adapter latency of the raw SDK port [ms]: a 204 ms reply window instead of the SDK's 34 ms, which the
in-process emulator thread missed on a loaded host (as in test_hw_tendon, where the 16 ms timeout
itself is tested)."""


@pytest.fixture
def emulator():
    with XL330Emulator(ids=(1, 2), speed_ticks_s=FAST_TICKS_S) as emu:
        yield emu


@pytest.fixture
def sdk_port(emulator):
    """A real dynamixel-sdk port and packet handler connected to the emulator."""
    dxl = pytest.importorskip("dynamixel_sdk")
    port = port_handler(dxl, emulator.port, SDK_LATENCY_MS)
    assert port.openPort() and port.setBaudRate(57600)
    yield port, dxl.PacketHandler(2.0)
    port.closePort()
