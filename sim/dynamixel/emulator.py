"""A Dynamixel Protocol 2.0 servo chain on a pseudo-terminal, for the real ``dynamixel_sdk``.

The emulator opens a pty, and a background thread answers the instruction packets that arrive
on it as a chain of X-series servos would: PING, READ, WRITE, SYNC_READ, SYNC_WRITE and REBOOT
(unicast and, where the protocol allows, broadcast), status packets with the result code and the
hardware-error alert bit, the XM430-W350 control table (EEPROM writes refused while torque is on),
a trapezoidal motion model against a monotonic clock, position limits, temperature and hardware
errors. Faults are injected by a frozen :class:`sim.dynamixel.faults.FaultConfig` (dropped,
corrupted and delayed replies, a servo that stops answering, an overload after N moves),
deterministic for a seed. One servo's control table and motion are
:class:`sim.dynamixel.servo.EmulatedServo`; this module is the chain: the pty, the serving
thread and the instructions.

>>> with ServoChainEmulator([ServoSpec(id=1)]) as emulator:  # doctest: +SKIP
...     port = PortHandler(emulator.port)

The emulator has its own control table and wire code (``sim/dynamixel/protocol.py``) and shares
nothing with the driver, so a wrong constant on one side shows up as a failing test.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections.abc import Callable, Sequence
from types import TracebackType

from sim.dynamixel.faults import FaultConfig, FaultInjector
from sim.dynamixel.protocol import (
    BROADCAST_ID,
    Instruction,
    Packet,
    PacketParser,
    ResultError,
    encode_status,
    from_le,
    u_le,
)
from sim.dynamixel.servo import CONTROL_ITEMS, EmulatedServo, ServoSpec

__all__ = ["ServoChainEmulator"]


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
        self._servos = [EmulatedServo(spec, clock()) for spec in sorted(servos, key=lambda s: s.id)]
        self._faults: FaultInjector
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

    # The context-manager protocol (leaving closes), alike in shape to SimulatedRig's and every
    # closable's: three lines of Python's protocol, no logic worth a shared base class.
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
            self._faults = FaultInjector(faults)
            for servo in self._servos:
                servo.instructions_seen = 0
                servo.moves = 0
                servo.overload_after = self._faults.overload_after(servo.id)

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
            return list(self._faults.log)

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
            signed = CONTROL_ITEMS[address].signed if address in CONTROL_ITEMS else False
            return from_le(data, signed=signed)

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

    def _servo(self, servo_id: int) -> EmulatedServo:
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
            if self._faults.lose(packet):
                return []
            replies = self._execute(packet, now)
            return [self._faults.reply(packet.instruction, reply) for reply in replies]

    def _answering(self, servo: EmulatedServo, now: float) -> bool:
        """Count an instruction for ``servo``; False when it is silent (faulted or rebooting)."""
        if now < servo.silent_until:
            return False
        servo.instructions_seen += 1
        return not self._faults.silences(servo.id, servo.instructions_seen)

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

    def _unicast(
        self, servo: EmulatedServo, inst: int, params: bytes, now: float
    ) -> tuple[int, bytes]:
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
