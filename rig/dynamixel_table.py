"""The X-series (Protocol 2.0) control table items the driver uses, and error wording.

Addresses and sizes are those of the XM430-W350 e-manual; the other X-series servos
(XL430, XC430, XM540, XH430...) share them. Units: positions in ticks (4096 per turn),
velocity in 0.229 rpm, acceleration in 214.577 rev/min^2.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Item:
    """One control table item: where it lives, how wide it is, and whether it is signed."""

    name: str
    address: int
    size: int
    eeprom: bool = False
    signed: bool = False

    def __str__(self) -> str:
        return f"{self.name} ({self.address})"


MODEL_NUMBER = Item("Model Number", 0, 2, eeprom=True)
OPERATING_MODE = Item("Operating Mode", 11, 1, eeprom=True)
HOMING_OFFSET = Item("Homing Offset", 20, 4, eeprom=True, signed=True)
MAX_POSITION_LIMIT = Item("Max Position Limit", 48, 4, eeprom=True)
MIN_POSITION_LIMIT = Item("Min Position Limit", 52, 4, eeprom=True)
TORQUE_ENABLE = Item("Torque Enable", 64, 1)
HARDWARE_ERROR_STATUS = Item("Hardware Error Status", 70, 1)
PROFILE_ACCELERATION = Item("Profile Acceleration", 108, 4)
PROFILE_VELOCITY = Item("Profile Velocity", 112, 4)
GOAL_POSITION = Item("Goal Position", 116, 4, signed=True)
MOVING = Item("Moving", 122, 1)
PRESENT_POSITION = Item("Present Position", 132, 4, signed=True)
PRESENT_TEMPERATURE = Item("Present Temperature", 146, 1)

STATE_BLOCK = (GOAL_POSITION.address, PRESENT_POSITION.address + 4 - GOAL_POSITION.address)
"""(address, length) of one read covering Goal Position, Moving and Present Position."""

OPERATING_MODE_POSITION = 3
TICKS_PER_TURN = 4096
CENTRE_TICK = 2048
MAX_TICK = 4095
VELOCITY_UNIT_RPM = 0.229
ACCELERATION_UNIT_RPM2 = 214.577
PROFILE_MAX = 32767

ALERT_BIT = 0x80
"""Set in a status packet's error byte while Hardware Error Status is not zero."""

HARDWARE_ERROR_WORDS: dict[int, str] = {
    0x01: "input voltage out of range",
    0x04: "overheating",
    0x08: "motor encoder malfunction",
    0x10: "electrical shock or insufficient power",
    0x20: "overload",
}

RESULT_CRC = 0x03
RESULT_ERROR_WORDS: dict[int, str] = {
    0x01: "result fail (the instruction could not be processed)",
    0x02: "instruction error (undefined instruction or wrong use)",
    0x03: "CRC error (the servo received a damaged packet)",
    0x04: "data range error (value out of the item's range)",
    0x05: "data length error (wrong number of bytes for the item)",
    0x06: "data limit error (value outside the servo's limits)",
    0x07: "access error (read-only item, undefined address, or EEPROM while torque is on)",
}
PROTOCOL_RESULTS = frozenset({0x02, 0x03, 0x05})
"""Result codes that mean the bytes were wrong rather than the request refused."""

MODEL_NAMES: dict[int, str] = {
    1000: "XH430-W350",
    1010: "XH430-W210",
    1020: "XM430-W350",
    1030: "XM430-W210",
    1060: "XL430-W250",
    1120: "XM540-W270",
    1130: "XM540-W150",
}


def model_name(model_number: int) -> str:
    """``"1020 (XM430-W350)"``, or the bare number for a model not listed."""
    name = MODEL_NAMES.get(model_number)
    return f"{model_number} ({name})" if name else str(model_number)


def hardware_error_words(status: int) -> list[str]:
    """The Hardware Error Status bits of ``status`` in words, lowest bit first."""
    words = [word for bit, word in HARDWARE_ERROR_WORDS.items() if status & bit]
    unknown = status & ~sum(HARDWARE_ERROR_WORDS) & 0xFF
    if unknown:
        words.append(f"unknown hardware error bits 0x{unknown:02X}")
    return words


def result_error_words(error: int) -> str:
    """The result code in the low 7 bits of a status error byte, in words."""
    code = error & 0x7F
    return RESULT_ERROR_WORDS.get(code, f"unknown result code 0x{code:02X}")
