"""One emulated X-series servo: its spec, the XM430-W350 control table and its state.

:class:`EmulatedServo` keeps the control table (EEPROM writes refused while torque is on,
value ranges, position limits in Position Control Mode), computes the items that change by
themselves (Moving, Present Position, Present Velocity...) from its move
(:class:`sim.dynamixel.motion.TrapezoidMove`), and raises its hardware errors (overload,
overheating; Shutdown turns torque off). It knows no wire format and no faults: the chain
(:mod:`sim.dynamixel.emulator`) reads and writes it and keeps its fault counters on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.dynamixel.motion import (
    TICKS_PER_TURN,
    VELOCITY_UNIT_RPM,
    TrapezoidMove,
    acceleration_ticks_per_s2,
    velocity_ticks_per_s,
)
from sim.dynamixel.protocol import ALERT_BIT, ResultError, from_le, u_le

__all__ = [
    "CONTROL_ITEMS",
    "HW_OVERHEATING",
    "HW_OVERLOAD",
    "TABLE_SIZE",
    "ControlItem",
    "EmulatedServo",
    "ServoSpec",
]

HW_OVERLOAD = 0x20
HW_OVERHEATING = 0x04


@dataclass(frozen=True)
class ControlItem:
    """One control table item: address, size in bytes, default, writable range, signedness."""

    address: int
    size: int
    default: int
    lo: int = 0
    hi: int = 0
    writable: bool = True
    signed: bool = False


# The XM430-W350 items the emulator keeps (values not listed read as 0). EEPROM is below 64.
_STORED: dict[int, ControlItem] = {
    item.address: item
    for item in (
        ControlItem(0, 2, 1020, writable=False),  # Model Number
        ControlItem(6, 1, 45, writable=False),  # Firmware Version
        ControlItem(7, 1, 1, 0, 252),  # ID
        ControlItem(8, 1, 1, 0, 7),  # Baud Rate
        ControlItem(9, 1, 250, 0, 254),  # Return Delay Time
        ControlItem(10, 1, 0, 0, 13),  # Drive Mode
        ControlItem(11, 1, 3, 0, 16),  # Operating Mode
        ControlItem(20, 4, 0, -1_044_479, 1_044_479, signed=True),  # Homing Offset
        ControlItem(24, 4, 10, 0, 1023),  # Moving Threshold
        ControlItem(31, 1, 80, 0, 100),  # Temperature Limit
        ControlItem(44, 4, 200, 0, 1023),  # Velocity Limit
        ControlItem(48, 4, 4095, 0, 4095),  # Max Position Limit
        ControlItem(52, 4, 0, 0, 4095),  # Min Position Limit
        ControlItem(63, 1, 0x34, 0, 0x3D),  # Shutdown
        ControlItem(64, 1, 0, 0, 1),  # Torque Enable
        ControlItem(65, 1, 0, 0, 1),  # LED
        ControlItem(68, 1, 2, 0, 2),  # Status Return Level
        ControlItem(70, 1, 0, writable=False),  # Hardware Error Status
        ControlItem(108, 4, 0, 0, 32767),  # Profile Acceleration
        ControlItem(112, 4, 0, 0, 32767),  # Profile Velocity
        ControlItem(116, 4, 0, -1_048_575, 1_048_575, signed=True),  # Goal Position
    )
}
# Computed when read: Realtime Tick, Moving, Moving Status, Present Velocity, Present Position,
# Velocity/Position Trajectory, Present Input Voltage, Present Temperature.
_DYNAMIC: dict[int, ControlItem] = {
    a: ControlItem(a, s, 0, writable=False, signed=sg)
    for a, s, sg in (
        (120, 2, False),
        (122, 1, False),
        (123, 1, False),
        (128, 4, True),
        (132, 4, True),
        (136, 4, True),
        (140, 4, True),
        (144, 2, False),
        (146, 1, False),
    )
}
CONTROL_ITEMS = {**_STORED, **_DYNAMIC}
"""Every item the emulator knows, stored and computed, by address."""
TABLE_SIZE = 147
_EEPROM_END = 64
_OPERATING_MODES = frozenset({0, 1, 3, 4, 5, 16})
_ADDR_TORQUE, _ADDR_HW_ERROR, _ADDR_GOAL = 64, 70, 116


@dataclass(frozen=True)
class ServoSpec:
    """One emulated servo: id, model number, where it starts, its temperature and supply."""

    id: int
    model: int = 1020
    position_ticks: int = 2048
    temperature_c: int = 35
    voltage_dv: int = 120
    reboot_s: float = 0.02
    """How long the servo stays silent after a REBOOT."""


class EmulatedServo:
    """The control table and motion state of one servo. Not thread-safe (the chain locks).

    Parameters
    ----------
    spec
        The servo's id, model, start position, temperature and supply.
    now
        The clock at power-up, seconds.

    Attributes
    ----------
    table
        Stored control table values by address.
    temperature_c
        Present Temperature.
    goal_writes
        Goal Position writes received so far.
    instructions_seen, moves, overload_after
        The chain's fault counters: instructions counted for a silence, moves completed, and
        the moves after which the servo overloads (None: never).
    silent_until
        The clock until which the servo is rebooting and does not answer.
    """

    def __init__(self, spec: ServoSpec, now: float) -> None:
        self.spec = spec
        self.table = {address: item.default for address, item in _STORED.items()}
        self.table[0] = spec.model
        self.table[7] = spec.id
        self.temperature_c = spec.temperature_c
        self.hold = float(spec.position_ticks)
        self.move: TrapezoidMove | None = None
        self.fault_at: float | None = None
        self.moves = 0
        self.overload_after: int | None = None
        self.goal_writes = 0
        self.instructions_seen = 0
        self.silent_until = 0.0
        self.table[_ADDR_GOAL] = spec.position_ticks
        self.advance(now)

    @property
    def id(self) -> int:
        """The servo's present ID (control table item 7)."""
        return self.table[7]

    def position(self, now: float) -> float:
        """Position in ticks at clock ``now``."""
        return self.move.position(now) if self.move is not None else self.hold

    def advance(self, now: float) -> None:
        """Apply what time has done: the end of a move, a scheduled overload, overheating."""
        if self.fault_at is not None and now >= self.fault_at:
            self.stop(self.fault_at)
            self.fault_at = None
            self.set_hardware_error(HW_OVERLOAD, now)
        if self.move is not None and now >= self.move.t0 + self.move.duration:
            self.stop(now)
        if self.temperature_c > self.table[31]:
            self.set_hardware_error(HW_OVERHEATING, now)

    def stop(self, now: float) -> None:
        """End the move at where it is at clock ``now``."""
        self.hold = self.position(now)
        self.move = None

    def set_hardware_error(self, bits: int, now: float) -> None:
        """Raise hardware error ``bits``; those in Shutdown stop the servo and turn torque off."""
        self.table[_ADDR_HW_ERROR] |= bits
        if bits & self.table[63]:
            self.stop(now)
            self.fault_at = None
            self.table[_ADDR_TORQUE] = 0

    @property
    def alert(self) -> int:
        """The alert bit of a status packet's error byte while Hardware Error Status is not 0."""
        return ALERT_BIT if self.table[_ADDR_HW_ERROR] else 0

    def value(self, address: int, now: float) -> int:
        """The value of the item at ``address`` at clock ``now`` (stored or computed)."""
        if address in self.table:
            return self.table[address]
        moving = self.move is not None
        velocity = self.move.velocity_at(now) if self.move is not None else 0.0
        present = round(self.position(now))
        if address == 120:
            return int(now * 1000.0) % 32768
        if address == 122:
            return int(moving)
        if address == 123:
            in_position = abs(present - self.table[_ADDR_GOAL]) <= 1 and not moving
            profile = self.move.profile_bits if self.move is not None else 0
            return int(in_position) | (0x02 if moving else 0) | profile
        if address in (128, 136):
            return round(velocity * 60.0 / (VELOCITY_UNIT_RPM * TICKS_PER_TURN))
        if address in (132, 140):
            return present
        if address == 144:
            return self.spec.voltage_dv
        return self.temperature_c  # 146

    def read(self, address: int, length: int, now: float) -> tuple[int, bytes]:
        """(result code, the ``length`` bytes from ``address``); items not kept read as 0."""
        if length < 1 or address + length > TABLE_SIZE:
            return ResultError.ACCESS, b""
        image = bytearray(TABLE_SIZE)
        for item in CONTROL_ITEMS.values():
            if item.address < address + length and address < item.address + item.size:
                image[item.address : item.address + item.size] = u_le(
                    self.value(item.address, now), item.size
                )
        return ResultError.NONE, bytes(image[address : address + length])

    def write(self, address: int, data: bytes, now: float) -> int:
        """Validate the whole write first, then apply it; return the result code."""
        end = address + len(data)
        covered = [item for item in CONTROL_ITEMS.values() if address <= item.address < end]
        if address not in CONTROL_ITEMS or not all(item.writable for item in covered):
            return ResultError.ACCESS
        if sum(item.size for item in covered) != len(data):
            # An item cut short, or a byte in a gap between items (undefined address).
            partial = any(item.address + item.size > end for item in covered)
            return ResultError.DATA_LENGTH if partial else ResultError.ACCESS
        values: dict[int, int] = {}
        for item in covered:
            if item.address < _EEPROM_END and self.table[_ADDR_TORQUE]:
                return ResultError.ACCESS
            offset = item.address - address
            value = from_le(data[offset : offset + item.size], signed=item.signed)
            if not item.lo <= value <= item.hi:
                return ResultError.DATA_RANGE
            if item.address == 11 and value not in _OPERATING_MODES:
                return ResultError.DATA_RANGE
            values[item.address] = value
        if _ADDR_GOAL in values:
            self.goal_writes += 1
            if self.table[11] == 3 and not self.table[52] <= values[_ADDR_GOAL] <= self.table[48]:
                return ResultError.DATA_LIMIT
        if values.get(_ADDR_TORQUE) and self.table[_ADDR_HW_ERROR] & self.table[63]:
            # Only a reboot re-enables torque after a shutdown.
            return ResultError.RESULT_FAIL
        for addr, value in values.items():
            self._apply(addr, value, now)
        return ResultError.NONE

    def _apply(self, address: int, value: int, now: float) -> None:
        if address == 20:
            self.hold += value - self.table[20]
        if address == _ADDR_TORQUE:
            if value and not self.table[_ADDR_TORQUE]:
                self.table[_ADDR_GOAL] = round(self.position(now))
            elif not value:
                self.stop(now)
                self.fault_at = None
        self.table[address] = value
        if address == _ADDR_GOAL and self.table[_ADDR_TORQUE]:
            self.start_move(value, now)

    def start_move(self, goal: int, now: float) -> None:
        """Start a profile toward ``goal`` ticks at clock ``now``."""
        # A new goal during a move starts a fresh profile from where the servo is (from rest;
        # real firmware blends, which only makes it arrive a little sooner).
        self.stop(now)
        limit = self.table[44] or 1023
        velocity = self.table[112] if 0 < self.table[112] < limit else limit
        acc = self.table[108]
        self.move = TrapezoidMove(
            start=self.hold,
            goal=float(goal),
            t0=now,
            velocity=velocity_ticks_per_s(velocity),
            acceleration=acceleration_ticks_per_s2(acc) if acc else math.inf,
        )
        self.moves += 1
        if self.overload_after is not None and self.moves > self.overload_after:
            self.fault_at = now + 0.5 * self.move.duration

    def reboot(self, now: float) -> None:
        """Stop, restore the RAM items' defaults and stay silent for ``spec.reboot_s``."""
        self.stop(now)
        self.fault_at = None
        for address, item in _STORED.items():
            if address >= _EEPROM_END:
                self.table[address] = item.default
        self.table[_ADDR_GOAL] = round(self.hold)
        self.silent_until = now + self.spec.reboot_s
