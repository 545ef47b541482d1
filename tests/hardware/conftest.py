"""Protocol peers for the hardware tests: the XL330 emulator and an in-process franky-sim."""

from __future__ import annotations

import pytest

from hardware.dxl_emulator import XL330Emulator

FAST_TICKS_S = 20_000.0  # emulated motor speed: fast enough that a 1000-tick pull takes 50 ms


@pytest.fixture
def emulator():
    with XL330Emulator(ids=(1, 2), speed_ticks_s=FAST_TICKS_S) as emu:
        yield emu


@pytest.fixture
def sdk_port(emulator):
    """A real dynamixel-sdk port and packet handler connected to the emulator."""
    dxl = pytest.importorskip("dynamixel_sdk")
    port = dxl.PortHandler(emulator.port)
    assert port.openPort() and port.setBaudRate(57600)
    yield port, dxl.PacketHandler(2.0)
    port.closePort()
