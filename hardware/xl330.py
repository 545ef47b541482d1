"""Control-table facts of the Dynamixel XL330-M288 (protocol 2.0), shared by driver and emulator."""

from __future__ import annotations

__all__ = ["ADDR", "XL330_MODEL_NUMBER"]

XL330_MODEL_NUMBER = 1200  # XL330-M288-T, from the ROBOTIS control table

ADDR = {
    "model_number": 0,
    "firmware_version": 6,
    "id": 7,
    "baud_rate": 8,
    "return_delay_time": 9,
    "drive_mode": 10,
    "operating_mode": 11,
    "homing_offset": 20,
    "moving_threshold": 24,
    "current_limit": 38,
    "velocity_limit": 44,
    "max_position_limit": 48,
    "min_position_limit": 52,
    "torque_enable": 64,
    "led": 65,
    "status_return_level": 68,
    "hardware_error_status": 70,
    "goal_current": 102,
    "profile_velocity": 112,
    "goal_position": 116,
    "moving": 122,
    "present_current": 126,
    "present_velocity": 128,
    "present_position": 132,
    "present_input_voltage": 144,
    "present_temperature": 146,
}
"""Control-table addresses of the XL330-M288 (protocol 2.0) used here."""
