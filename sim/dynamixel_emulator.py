"""A Dynamixel Protocol 2.0 servo chain on a pseudo-terminal, for the real ``dynamixel_sdk``.

The emulator opens a pty, and a background thread answers the instruction packets that arrive
on it as a chain of X-series servos would: PING, READ, WRITE, SYNC_READ, SYNC_WRITE and REBOOT
(unicast and, where the protocol allows, broadcast), status packets with the result code and the
hardware-error alert bit, the XM430-W350 control table (EEPROM writes refused while torque is on),
a trapezoidal motion model against a monotonic clock, position limits, temperature and hardware
errors. Faults are injected by a frozen :class:`FaultConfig` (dropped, corrupted and delayed
replies, a servo that stops answering, an overload after N moves), deterministic for a seed.

>>> with ServoChainEmulator([ServoSpec(id=1)]) as emulator:  # doctest: +SKIP
...     port = PortHandler(emulator.port)

The emulator has its own control table and wire code (``sim/dynamixel_protocol.py``) and shares
nothing with the driver, so a wrong constant on one side shows up as a failing test.
"""

from __future__ import annotations

import math
import os
import random
import select
import threading
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import TracebackType

from sim.dynamixel_protocol import (
    ALERT_BIT,
    BROADCAST_ID,
    Instruction,
    Packet,
    PacketParser,
    ResultError,
    encode_status,
    from_le,
    u_le,
)

TICKS_PER_TURN = 4096
VELOCITY_UNIT_RPM = 0.229
ACCELERATION_UNIT_RPM2 = 214.577
HW_OVERLOAD = 0x20
HW_OVERHEATING = 0x04


def velocity_ticks_per_s(units: int) -> float:
    """An X-series velocity value (0.229 rpm per unit) in ticks per second."""
    return units * VELOCITY_UNIT_RPM * TICKS_PER_TURN / 60.0


def acceleration_ticks_per_s2(units: int) -> float:
    """An X-series acceleration value (214.577 rev/min^2 per unit) in ticks per second^2."""
    return units * ACCELERATION_UNIT_RPM2 * TICKS_PER_TURN / 3600.0


@dataclass(frozen=True)
class TrapezoidMove:
    """A point-to-point move: accelerate, cruise, decelerate; a triangle when too short to cruise.

    ``velocity`` in ticks/s (> 0) and ``acceleration`` in ticks/s^2 (``math.inf`` for a
    rectangular velocity profile) are the profile's limits; ``t0`` is the clock at the start.
    """

    start: float
    goal: float
    t0: float
    velocity: float
    acceleration: float

    @property
    def _shape(self) -> tuple[float, float, float]:
        """(acceleration time, cruise time, peak velocity)."""
        distance = abs(self.goal - self.start)
        if math.isinf(self.acceleration):
            return 0.0, distance / self.velocity, self.velocity
        t_acc = self.velocity / self.acceleration
        if self.acceleration * t_acc * t_acc >= distance:
            t_acc = math.sqrt(distance / self.acceleration)
            return t_acc, 0.0, self.acceleration * t_acc
        return t_acc, (distance - self.acceleration * t_acc * t_acc) / self.velocity, self.velocity

    @property
    def duration(self) -> float:
        """Seconds from start to standstill at the goal."""
        t_acc, t_cruise, _ = self._shape
        return 2.0 * t_acc + t_cruise

    @property
    def profile_bits(self) -> int:
        """Moving Status bits 4-5: 3 trapezoidal, 2 triangular, 1 rectangular."""
        t_acc, t_cruise, _ = self._shape
        return 0x10 if t_acc == 0.0 else (0x30 if t_cruise > 0.0 else 0x20)

    def position(self, t: float) -> float:
        """Position in ticks at clock ``t`` (held at the ends)."""
        t_acc, t_cruise, v_peak = self._shape
        tau = min(max(t - self.t0, 0.0), 2.0 * t_acc + t_cruise)
        a = self.acceleration
        if tau <= t_acc:
            s = 0.5 * a * tau * tau if t_acc > 0.0 else 0.0
        elif tau <= t_acc + t_cruise:
            s = 0.5 * v_peak * t_acc + v_peak * (tau - t_acc)
        else:
            rest = 2.0 * t_acc + t_cruise - tau
            s = abs(self.goal - self.start) - 0.5 * a * rest * rest
        return self.start + math.copysign(s, self.goal - self.start)

    def velocity_at(self, t: float) -> float:
        """Signed velocity in ticks/s at clock ``t``."""
        t_acc, t_cruise, v_peak = self._shape
        tau = t - self.t0
        if tau < 0.0 or tau >= 2.0 * t_acc + t_cruise:
            return 0.0
        if tau < t_acc:
            v = self.acceleration * tau
        elif tau < t_acc + t_cruise:
            v = v_peak
        else:
            v = self.acceleration * (2.0 * t_acc + t_cruise - tau)
        return math.copysign(v, self.goal - self.start)


@dataclass(frozen=True)
class _Item:
    address: int
    size: int
    default: int
    lo: int = 0
    hi: int = 0
    writable: bool = True
    signed: bool = False


# The XM430-W350 items the emulator keeps (values not listed read as 0). EEPROM is below 64.
_STORED: dict[int, _Item] = {
    item.address: item
    for item in (
        _Item(0, 2, 1020, writable=False),  # Model Number
        _Item(6, 1, 45, writable=False),  # Firmware Version
        _Item(7, 1, 1, 0, 252),  # ID
        _Item(8, 1, 1, 0, 7),  # Baud Rate
        _Item(9, 1, 250, 0, 254),  # Return Delay Time
        _Item(10, 1, 0, 0, 13),  # Drive Mode
        _Item(11, 1, 3, 0, 16),  # Operating Mode
        _Item(20, 4, 0, -1_044_479, 1_044_479, signed=True),  # Homing Offset
        _Item(24, 4, 10, 0, 1023),  # Moving Threshold
        _Item(31, 1, 80, 0, 100),  # Temperature Limit
        _Item(44, 4, 200, 0, 1023),  # Velocity Limit
        _Item(48, 4, 4095, 0, 4095),  # Max Position Limit
        _Item(52, 4, 0, 0, 4095),  # Min Position Limit
        _Item(63, 1, 0x34, 0, 0x3D),  # Shutdown
        _Item(64, 1, 0, 0, 1),  # Torque Enable
        _Item(65, 1, 0, 0, 1),  # LED
        _Item(68, 1, 2, 0, 2),  # Status Return Level
        _Item(70, 1, 0, writable=False),  # Hardware Error Status
        _Item(108, 4, 0, 0, 32767),  # Profile Acceleration
        _Item(112, 4, 0, 0, 32767),  # Profile Velocity
        _Item(116, 4, 0, -1_048_575, 1_048_575, signed=True),  # Goal Position
    )
}
# Computed when read: Realtime Tick, Moving, Moving Status, Present Velocity, Present Position,
# Velocity/Position Trajectory, Present Input Voltage, Present Temperature.
_DYNAMIC: dict[int, _Item] = {
    a: _Item(a, s, 0, writable=False, signed=sg)
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
_ITEMS = {**_STORED, **_DYNAMIC}
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


@dataclass(frozen=True)
class FaultConfig:
    """Faults to inject; the defaults inject none. Deterministic for a given ``seed``.

    ``lose_first`` = N: the first N instruction packets are lost on the way in (neither
    executed nor answered). Reply faults (drop, corrupt, delay) act on status packets after
    the instruction was executed, so a dropped reply to a WRITE leaves the write done: an
    "unknown outcome". The ``*_first`` counts hit the first N replies; the probabilities then
    apply to every reply. ``instructions`` restricts lost packets and reply faults to those
    instruction codes (empty: all).
    A servo in ``silent_ids`` answers ``silent_after`` instructions, then neither executes nor
    answers anything. ``overload_after_moves`` = N: each servo (or those in ``overload_ids``)
    completes N moves, then overloads half-way through the next (torque off, alert bit set,
    Hardware Error Status 0x20 until a reboot).
    """

    seed: int = 0
    lose_first: int = 0
    drop_first: int = 0
    drop_probability: float = 0.0
    corrupt_first: int = 0
    corrupt_probability: float = 0.0
    delay_s: float = 0.0
    delay_first: int = 0
    delay_probability: float = 0.0
    instructions: frozenset[int] = frozenset()
    silent_ids: frozenset[int] = frozenset()
    silent_after: int = 0
    overload_after_moves: int | None = None
    overload_ids: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        for name in ("drop_probability", "corrupt_probability", "delay_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"FaultConfig.{name} must be in [0, 1]")
        if self.delay_s < 0.0:
            raise ValueError("FaultConfig.delay_s must be >= 0")


class _Servo:
    """The control table and motion state of one servo. Not thread-safe (the chain locks)."""

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
        return self.table[7]

    def position(self, now: float) -> float:
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
        self.hold = self.position(now)
        self.move = None

    def set_hardware_error(self, bits: int, now: float) -> None:
        self.table[_ADDR_HW_ERROR] |= bits
        if bits & self.table[63]:
            self.stop(now)
            self.fault_at = None
            self.table[_ADDR_TORQUE] = 0

    @property
    def alert(self) -> int:
        return ALERT_BIT if self.table[_ADDR_HW_ERROR] else 0

    def value(self, address: int, now: float) -> int:
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
        if length < 1 or address + length > TABLE_SIZE:
            return ResultError.ACCESS, b""
        image = bytearray(TABLE_SIZE)
        for item in _ITEMS.values():
            if item.address < address + length and address < item.address + item.size:
                image[item.address : item.address + item.size] = u_le(
                    self.value(item.address, now), item.size
                )
        return ResultError.NONE, bytes(image[address : address + length])

    def write(self, address: int, data: bytes, now: float) -> int:
        """Validate the whole write first, then apply it; return the result code."""
        end = address + len(data)
        covered = [item for item in _ITEMS.values() if address <= item.address < end]
        if address not in _ITEMS or not all(item.writable for item in covered):
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
        self.stop(now)
        self.fault_at = None
        for address, item in _STORED.items():
            if address >= _EEPROM_END:
                self.table[address] = item.default
        self.table[_ADDR_GOAL] = round(self.hold)
        self.silent_until = now + self.spec.reboot_s


class ServoChainEmulator:
    """A chain of emulated X-series servos on a pseudo-terminal.

    Parameters
    ----------
    servos
        The servos on the bus (distinct ids).
    faults
        Faults to inject (none by default); :meth:`set_faults` replaces them at run time.
    clock
        Monotonic clock in seconds for the motion model.

    The pty is open and answered as soon as the object exists; :attr:`port` is the path a
    ``dynamixel_sdk.PortHandler`` opens. :meth:`close` (or leaving the ``with`` block) stops
    the thread and removes the pty.
    """

    def __init__(
        self,
        servos: Sequence[ServoSpec],
        *,
        faults: FaultConfig | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        ids = [spec.id for spec in servos]
        if len(set(ids)) != len(ids) or not all(0 <= i <= 252 for i in ids):
            raise ValueError(f"servo ids must be distinct and in 0..252, got {ids}")
        self._clock = clock
        self._lock = threading.Lock()
        # Kept in id order: a broadcast PING is answered in that order.
        self._servos = [_Servo(spec, clock()) for spec in sorted(servos, key=lambda s: s.id)]
        self._faults = FaultConfig()
        self._rng = random.Random(0)
        self._fault_replies = 0
        self._lost = 0
        self._fault_log: list[tuple[int, str]] = []
        self.set_faults(faults or FaultConfig())
        self._bytes_received = 0
        self._log: list[Packet] = []
        self._master, self._slave = os.openpty()
        # Raw mode: no echo, no line editing, 8-bit clean, so bytes pass untouched. The slave
        # end stays open here so the pty survives the client closing and reopening it.
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self._port = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._closed = False
        self._thread = threading.Thread(target=self._serve, name="dynamixel-emulator", daemon=True)
        self._thread.start()

    # -- public API -------------------------------------------------------------------------

    @property
    def port(self) -> str:
        """The pty device path the SDK opens."""
        return self._port

    def __enter__(self) -> ServoChainEmulator:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Stop answering, join the thread and remove the pty (idempotent)."""
        if self._closed:
            return
        self._closed = True
        os.write(self._wake_w, b"x")
        self._thread.join()
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            os.close(fd)

    def set_faults(self, faults: FaultConfig) -> None:
        """Replace the injected faults; counts and the random stream restart."""
        with self._lock:
            self._faults = faults
            self._rng = random.Random(faults.seed)
            self._fault_replies = 0
            self._lost = 0
            self._fault_log = []
            for servo in self._servos:
                servo.instructions_seen = 0
                servo.moves = 0
                targeted = not faults.overload_ids or servo.id in faults.overload_ids
                servo.overload_after = faults.overload_after_moves if targeted else None

    @property
    def bytes_received(self) -> int:
        """Bytes that have arrived from the client so far."""
        with self._lock:
            return self._bytes_received

    def packets(self) -> list[Packet]:
        """Every packet with a valid CRC that has arrived, in order (lost ones included)."""
        with self._lock:
            return list(self._log)

    def fault_log(self) -> list[tuple[int, str]]:
        """(reply index, "dropped" | "corrupted" | "delayed") since the last :meth:`set_faults`."""
        with self._lock:
            return list(self._fault_log)

    def goal_writes(self, servo_id: int) -> int:
        """Goal Position writes (WRITE or SYNC_WRITE) this servo has received."""
        with self._lock:
            return self._servo(servo_id).goal_writes

    def register(self, servo_id: int, address: int, size: int) -> int:
        """A control table value now (signed items decoded), bypassing the wire."""
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(self._clock())
            _, data = servo.read(address, size, self._clock())
            return from_le(data, signed=_ITEMS[address].signed if address in _ITEMS else False)

    def set_register(self, servo_id: int, address: int, value: int) -> None:
        """Overwrite a stored item behind the driver's back (e.g. shrink a position limit)."""
        with self._lock:
            self._servo(servo_id).table[address] = value

    def inject_hardware_error(self, servo_id: int, bits: int) -> None:
        """Raise hardware error ``bits`` (0x20 overload, 0x04 overheating...) now."""
        with self._lock:
            self._servo(servo_id).set_hardware_error(bits, self._clock())

    def set_temperature(self, servo_id: int, celsius: int) -> None:
        """Set Present Temperature; above Temperature Limit the servo reports overheating."""
        with self._lock:
            self._servo(servo_id).temperature_c = celsius

    # -- serving ----------------------------------------------------------------------------

    def _servo(self, servo_id: int) -> _Servo:
        for servo in self._servos:
            if servo.id == servo_id:
                return servo
        raise KeyError(f"no emulated servo with id {servo_id}")

    def _serve(self) -> None:
        parser = PacketParser()
        while True:
            ready, _, _ = select.select([self._master, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            try:
                data = os.read(self._master, 4096)
            except (BlockingIOError, InterruptedError):
                continue
            with self._lock:
                self._bytes_received += len(data)
            for packet in parser.feed(data):
                for reply, delay in self._handle(packet):
                    if delay > 0.0 and self._sleep(delay):
                        return
                    if reply:
                        self._send(reply)

    def _sleep(self, seconds: float) -> bool:
        """Sleep unless woken by :meth:`close`; True when woken."""
        ready, _, _ = select.select([self._wake_r], [], [], seconds)
        return bool(ready)

    def _send(self, data: bytes) -> None:
        try:
            os.write(self._master, data)
        except BlockingIOError:
            # Nobody is reading and the pty buffer is full: lost, as on an overrun bus.
            pass

    def _handle(self, packet: Packet) -> list[tuple[bytes, float]]:
        with self._lock:
            now = self._clock()
            for servo in self._servos:
                servo.advance(now)
            if packet.crc_ok:
                self._log.append(packet)
            if self._lose(packet):
                return []
            replies = self._execute(packet, now)
            return [self._apply_reply_faults(packet.instruction, reply) for reply in replies]

    def _lose(self, packet: Packet) -> bool:
        faults = self._faults
        if self._lost >= faults.lose_first:
            return False
        if faults.instructions and packet.instruction not in faults.instructions:
            return False
        self._lost += 1
        return True

    def _answering(self, servo: _Servo, now: float) -> bool:
        """Count an instruction for ``servo``; False when it is silent (faulted or rebooting)."""
        if now < servo.silent_until:
            return False
        servo.instructions_seen += 1
        faults = self._faults
        return not (servo.id in faults.silent_ids and servo.instructions_seen > faults.silent_after)

    def _execute(self, packet: Packet, now: float) -> list[bytes]:
        pid, inst, params = packet.packet_id, packet.instruction, packet.params
        broadcast = pid == BROADCAST_ID
        targets = self._servos if broadcast else [s for s in self._servos if s.id == pid]
        if not packet.crc_ok:
            return [
                encode_status(s.id, ResultError.CRC | s.alert)
                for s in targets
                if not broadcast and self._answering(s, now)
            ]
        if inst == Instruction.PING:
            return [
                encode_status(s.id, s.alert, u_le(s.table[0], 2) + bytes([s.table[6]]))
                for s in targets
                if self._answering(s, now)
            ]
        if inst == Instruction.SYNC_READ and broadcast:
            return self._sync_read(params, now)
        if inst == Instruction.SYNC_WRITE and broadcast:
            self._sync_write(params, now)
            return []
        replies = []
        for servo in targets:
            if not self._answering(servo, now):
                continue
            error, data = self._unicast(servo, inst, params, now)
            level = servo.table[68]
            wants = level == 2 or (level == 1 and inst == Instruction.READ)
            if not broadcast and wants:
                replies.append(encode_status(servo.id, error | servo.alert, data))
            if inst == Instruction.REBOOT:
                servo.reboot(now)
        return replies

    def _unicast(self, servo: _Servo, inst: int, params: bytes, now: float) -> tuple[int, bytes]:
        if inst == Instruction.READ:
            if len(params) != 4:
                return ResultError.DATA_LENGTH, b""
            return servo.read(from_le(params[:2]), from_le(params[2:]), now)
        if inst == Instruction.WRITE:
            if len(params) < 3:
                return ResultError.DATA_LENGTH, b""
            return servo.write(from_le(params[:2]), params[2:], now), b""
        if inst == Instruction.REBOOT:
            return ResultError.NONE, b""
        return ResultError.INSTRUCTION, b""

    def _sync_read(self, params: bytes, now: float) -> list[bytes]:
        if len(params) < 5:
            return []
        address, length = from_le(params[:2]), from_le(params[2:4])
        replies = []
        for servo_id in params[4:]:
            servo = next((s for s in self._servos if s.id == servo_id), None)
            if servo is None or not self._answering(servo, now):
                continue
            error, data = servo.read(address, length, now)
            replies.append(encode_status(servo.id, error | servo.alert, data))
        return replies

    def _sync_write(self, params: bytes, now: float) -> None:
        if len(params) < 4:
            return
        address, length = from_le(params[:2]), from_le(params[2:4])
        block = 1 + length
        body = params[4:]
        if length < 1 or len(body) % block:
            return
        for start in range(0, len(body), block):
            servo = next((s for s in self._servos if s.id == body[start]), None)
            if servo is not None and self._answering(servo, now):
                # No status packet for a sync write: a refused item is silently not applied.
                servo.write(address, body[start + 1 : start + block], now)

    def _apply_reply_faults(self, instruction: int, reply: bytes) -> tuple[bytes, float]:
        """Return (bytes to send, delay before sending); empty bytes for a dropped reply."""
        faults = self._faults
        if faults.instructions and instruction not in faults.instructions:
            return reply, 0.0
        index = self._fault_replies
        self._fault_replies += 1
        rng = self._rng
        if index < faults.drop_first or (
            faults.drop_probability and rng.random() < faults.drop_probability
        ):
            self._fault_log.append((index, "dropped"))
            return b"", 0.0
        if index < faults.corrupt_first or (
            faults.corrupt_probability and rng.random() < faults.corrupt_probability
        ):
            self._fault_log.append((index, "corrupted"))
            reply = reply[:-2] + bytes([reply[-2] ^ 0xFF, reply[-1]])
        delayed = index < faults.delay_first or (
            faults.delay_probability and rng.random() < faults.delay_probability
        )
        if delayed:
            self._fault_log.append((index, "delayed"))
        return reply, faults.delay_s if delayed else 0.0
