"""The Dynamixel chain's transactions on ``dynamixel_sdk`` (Protocol 2.0), and a servo axis's ticks.

:class:`ServoLink` is the protocol layer under :class:`rig.dynamixel.DynamixelChain`: every
transaction is retried a bounded number of times, each attempt allowing twice the reply
latency of the one before; a write whose reply was lost is confirmed by reading the item back
and sent again only when the read shows it did not take; every status packet's alert bit is
checked, a servo with a hardware error raising :class:`ServoHardwareError` in words. Reads of
several servos go as one Sync Read whose replies keep their error bytes; goals go as one Sync
Write, read back. :class:`ServoAxisConfig` is one axis and its conversion between axis
degrees and servo ticks (the control table is :mod:`rig.dynamixel_table`).
"""

from __future__ import annotations

import math
import termios
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from dynamixel_sdk import (
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from core.errors import ConfigError, DeviceError, DeviceFault, ProtocolError
from rig import dynamixel_table as tbl
from rig.dynamixel_table import Item

__all__ = ["ServoAxisConfig", "ServoHardwareError", "ServoLink"]


@dataclass(frozen=True)
class ServoAxisConfig:
    """One servo axis of the rig.

    Parameters
    ----------
    id
        Servo id on the bus (0..252).
    role
        Axis name, e.g. ``"camera_azimuth"``.
    offset_deg
        Axis angle at which the servo sits at its centre tick (2048).
    direction
        +1 when axis angle and servo ticks grow together, -1 otherwise.
    gear_ratio
        Servo turns per axis turn.
    min_deg, max_deg
        Soft limits of the axis angle; also written to the servo as its position limits.
    velocity_deg_s, acceleration_deg_s2
        Profile velocity and acceleration of the axis.
    model_number
        Model the servo must report (1020 = XM430-W350).
    """

    id: int
    role: str
    offset_deg: float = 0.0
    direction: int = 1
    gear_ratio: float = 1.0
    min_deg: float = -90.0
    max_deg: float = 90.0
    velocity_deg_s: float = 60.0
    acceleration_deg_s2: float = 300.0
    model_number: int = 1020

    def __post_init__(self) -> None:
        problems = []
        if not 0 <= self.id <= 252:
            problems.append(f"id {self.id} is not in 0..252")
        if self.direction not in (1, -1):
            problems.append(f"direction {self.direction} is not +1 or -1")
        if not self.gear_ratio > 0:
            problems.append(f"gear_ratio {self.gear_ratio} is not positive")
        if not self.min_deg < self.max_deg:
            problems.append(f"min_deg {self.min_deg} is not below max_deg {self.max_deg}")
        if not (self.velocity_deg_s > 0 and self.acceleration_deg_s2 > 0):
            problems.append("velocity_deg_s and acceleration_deg_s2 must be positive")
        values = (self.offset_deg, self.min_deg, self.max_deg, self.gear_ratio)
        if not all(math.isfinite(v) for v in values):
            problems.append("angles and gear_ratio must be finite")
        if problems:
            raise ConfigError(f"servo axis {self.role!r}: " + "; ".join(problems))


def _ticks(axis: ServoAxisConfig, deg: float) -> int:
    turns = axis.direction * axis.gear_ratio * (deg - axis.offset_deg) / 360.0
    return round(tbl.CENTRE_TICK + turns * tbl.TICKS_PER_TURN)


def _deg(axis: ServoAxisConfig, ticks: int) -> float:
    turns = (ticks - tbl.CENTRE_TICK) / tbl.TICKS_PER_TURN
    return axis.offset_deg + 360.0 * turns / (axis.direction * axis.gear_ratio)


def _profile_units(axis: ServoAxisConfig) -> tuple[int, int]:
    """(Profile Velocity, Profile Acceleration) in servo units; never 0, which means unlimited."""
    servo_deg_s = axis.velocity_deg_s * axis.gear_ratio
    servo_deg_s2 = axis.acceleration_deg_s2 * axis.gear_ratio
    velocity = round(servo_deg_s / 6.0 / tbl.VELOCITY_UNIT_RPM)  # deg/s -> rpm
    acceleration = round(servo_deg_s2 * 10.0 / tbl.ACCELERATION_UNIT_RPM2)  # -> rev/min^2
    return (
        min(max(velocity, 1), tbl.PROFILE_MAX),
        min(max(acceleration, 1), tbl.PROFILE_MAX),
    )


class ServoHardwareError(DeviceFault):
    """A servo reports a hardware error (its alert bit); only a reboot clears it."""

    def __init__(self, message: str, *, servo_id: int, role: str, errors: list[str]) -> None:
        super().__init__(message)
        self.servo_id = servo_id
        self.role = role
        self.errors = errors


class _PortHandler(PortHandler):  # type: ignore[misc]
    """The SDK's port with a configurable allowance for reply latency.

    The SDK waits transmission time + 34 ms (twice the 16 ms USB latency timer + 2 ms) for a
    status packet; a loaded host or a slow adapter may need more, so it is a parameter here.
    """

    def __init__(self, port_name: str, latency_ms: float) -> None:
        super().__init__(port_name)
        self._latency_ms = latency_ms

    def set_latency(self, latency_ms: float) -> None:
        """Allow ``latency_ms`` beyond the transmission time for the next replies."""
        self._latency_ms = latency_ms

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + self._latency_ms


class ServoLink:
    """One chain's serial transactions: each retried, a lost write confirmed, every status checked.

    Parameters
    ----------
    port, baudrate
        Serial device and its baud rate (the servos' Baud Rate item must match).
    retries
        Extra attempts after a failed transaction before giving up.
    latency_s
        Time allowed for a reply beyond its transmission time.
    retry_backoff_s
        Pause after a failed attempt, after which late bytes are flushed before trying again.
    """

    def __init__(
        self, port: str, baudrate: int, *, retries: int, latency_s: float, retry_backoff_s: float
    ) -> None:
        self.port_name = port
        self.baudrate = baudrate
        self.retries = retries
        self._latency_ms = latency_s * 1000.0
        self._backoff_s = retry_backoff_s
        self._ph: Any = PacketHandler(2.0)
        self._port: Any = None
        self._patience = 1  # the current attempt's factor on reply latency and backoff

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._port is not None

    def open(self) -> None:
        """Open the port at its baud rate; :class:`DeviceError` (the port closed) if it fails."""
        port = _PortHandler(self.port_name, self._latency_ms)
        try:
            opened = port.openPort() and port.setBaudRate(self.baudrate)
        except Exception as exc:  # pyserial raises SerialException/OSError subclasses
            if port.is_open:
                port.closePort()
            raise DeviceError(f"{self.port_name}: cannot open the port: {exc}") from exc
        if not opened:
            if port.is_open:
                port.closePort()
            raise DeviceError(
                f"{self.port_name}: cannot open the port at {self.baudrate} baud"
                " (unsupported baud rate?)"
            )
        self._port = port

    def close(self) -> None:
        """Close the port."""
        self._port.closePort()
        self._port = None

    def where(self, axis: ServoAxisConfig) -> str:
        """``port: servo id (role)``, for messages."""
        return f"{self.port_name}: servo {axis.id} ({axis.role})"

    def require_open(self) -> None:
        """Refuse a transaction before :meth:`open`."""
        if self._port is None:
            raise DeviceError(f"{self.port_name}: not connected (call connect())")

    def _comm(self, result: int) -> str:
        """The SDK's words for a transaction result."""
        return str(self._ph.getTxRxResult(result)).removeprefix("[TxRxResult] ")

    def _attempts(self) -> Iterator[int]:
        """Attempt numbers of one transaction, each allowing twice the reply latency before.

        A real servo answers within a millisecond; a loaded host (or an emulator sharing its
        cores) may not read the reply for tens of milliseconds. Doubling the allowance per
        attempt keeps the usual case fast and a busy machine from failing the transaction.
        """
        try:
            for attempt in range(self.retries + 1):
                self._patience = 2**attempt
                self._port.set_latency(self._latency_ms * self._patience)
                yield attempt
        finally:
            self._patience = 1
            if self._port is not None:
                self._port.set_latency(self._latency_ms)

    def _recover(self) -> None:
        # A reply may still be on its way; wait it out (as long again as the attempt waited)
        # and drop it, so that the next transaction cannot mistake it for its own.
        time.sleep(self._patience * (self._backoff_s + self._latency_ms / 1000.0))
        try:
            self._port.clearPort()
        except (OSError, termios.error) as exc:
            raise DeviceError(f"{self.port_name}: the serial port failed: {exc}") from exc

    def check_model(self, axis: ServoAxisConfig) -> None:
        """Ping the servo (retried) and check it is the model the config expects."""
        last = ""
        for _ in self._attempts():
            model, result, _ = self._ph.ping(self._port, axis.id)
            if result == COMM_SUCCESS:
                if model != axis.model_number:
                    raise DeviceError(
                        f"{self.where(axis)} is model {tbl.model_name(model)}, the config"
                        f" expects {tbl.model_name(axis.model_number)}"
                    )
                return
            last = self._comm(result)
            self._recover()
        raise DeviceError(
            f"{self.where(axis)} does not answer a ping at {self.baudrate} baud after"
            f" {self.retries + 1} attempts ({last}); check power, cabling, id and baud rate"
        )

    def _check_status(self, axis: ServoAxisConfig, error: int, action: str, alert: bool) -> None:
        """Raise for a status packet's error byte (its alert bit unless ``alert``)."""
        code = error & 0x7F
        if code:
            cls = ProtocolError if code in tbl.PROTOCOL_RESULTS else DeviceError
            alert_note = " (it also reports a hardware error)" if error & tbl.ALERT_BIT else ""
            raise cls(f"{self.where(axis)}: {action}: {tbl.result_error_words(code)}{alert_note}")
        if error & tbl.ALERT_BIT and not alert:
            raise self.hardware_error(axis)

    def hardware_error(
        self, axis: ServoAxisConfig, status: int | None = None
    ) -> ServoHardwareError:
        """The :class:`ServoHardwareError` of a servo (its error status read if not given)."""
        if status is None:
            status = self.read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
        words = tbl.hardware_error_words(status) or ["alert bit set, Hardware Error Status 0"]
        return ServoHardwareError(
            f"{self.where(axis)} reports a hardware error: {', '.join(words)}"
            f" (Hardware Error Status 0x{status:02X}); torque is off until reboot({axis.role!r})",
            servo_id=axis.id,
            role=axis.role,
            errors=words,
        )

    def read(self, axis: ServoAxisConfig, item: Item, *, tolerate_alert: bool = False) -> int:
        """One control-table item, retried; a CRC-damaged reply is read again."""
        last = ""
        for _ in self._attempts():
            data, result, error = self._ph.readTxRx(self._port, axis.id, item.address, item.size)
            if result == COMM_SUCCESS and len(data) == item.size:
                if error & 0x7F == tbl.RESULT_CRC:
                    last = tbl.result_error_words(error)
                    self._recover()
                    continue
                self._check_status(axis, error, f"reading {item}", tolerate_alert)
                return int.from_bytes(bytes(data), "little", signed=item.signed)
            last = self._comm(result) if result != COMM_SUCCESS else "reply of the wrong length"
            self._recover()
        raise DeviceError(
            f"{self.where(axis)}: reading {item} failed after {self.retries + 1} attempts: {last}"
        )

    def write(
        self, axis: ServoAxisConfig, item: Item, value: int, *, tolerate_alert: bool = False
    ) -> None:
        """Write one control-table item, retried; a lost reply is confirmed by reading it back."""
        action = f"writing {item} = {value}"
        if item is tbl.GOAL_POSITION:
            action += f" ({_deg(axis, value):.2f} deg)"
        data = list(value.to_bytes(item.size, "little", signed=item.signed))
        last = ""
        for _ in self._attempts():
            result, error = self._ph.writeTxRx(self._port, axis.id, item.address, item.size, data)
            if result == COMM_SUCCESS and error & 0x7F != tbl.RESULT_CRC:
                self._check_status(axis, error, action, tolerate_alert)
                return
            last = self._comm(result) if result != COMM_SUCCESS else tbl.result_error_words(error)
            self._recover()
            if result == COMM_SUCCESS:
                continue  # the servo said it got a damaged packet: nothing was executed
            # Outcome unknown: the write may have been executed and only its reply lost.
            # Read the item back; send again only when it shows the write did not take.
            try:
                current = self.read(axis, item, tolerate_alert=tolerate_alert)
            except ServoHardwareError:
                raise
            except DeviceError as exc:
                raise DeviceError(
                    f"{self.where(axis)}: {action}: no reply ({last}) and the outcome could"
                    f" not be confirmed by reading it back: {exc}"
                ) from exc
            if current == value:
                return
        raise DeviceError(
            f"{self.where(axis)}: {action} failed after {self.retries + 1} attempts: {last}"
        )

    def read_states(self, axes: list[ServoAxisConfig]) -> dict[str, tuple[int, int, int]]:
        """(Goal Position, Moving, Present Position) per role, by one read or one Sync Read."""
        address, size = tbl.STATE_BLOCK
        last = ""
        for _ in self._attempts():
            replies, last = self._read_block(axes, address, size)
            if replies is None:
                self._recover()
                continue
            if any(error & 0x7F == tbl.RESULT_CRC for _, error in replies.values()):
                last = tbl.result_error_words(tbl.RESULT_CRC)
                self._recover()
                continue
            states = {}
            for axis in axes:
                data, error = replies[axis.id]
                self._check_status(axis, error, "reading position and motion state", False)
                goal = int.from_bytes(data[0:4], "little", signed=True)
                moving = data[tbl.MOVING.address - address]
                offset = tbl.PRESENT_POSITION.address - address
                present = int.from_bytes(data[offset : offset + 4], "little", signed=True)
                states[axis.role] = (goal, moving, present)
            return states
        raise DeviceError(
            f"{self.port_name}: reading the state of"
            f" {', '.join(f'servo {a.id} ({a.role})' for a in axes)} failed after"
            f" {self.retries + 1} attempts: {last}"
        )

    def _read_block(
        self, axes: list[ServoAxisConfig], address: int, size: int
    ) -> tuple[dict[int, tuple[bytes, int]] | None, str]:
        """One attempt: {id: (data, error byte)}, or None and what went wrong."""
        if len(axes) == 1:
            data, result, error = self._ph.readTxRx(self._port, axes[0].id, address, size)
            if result != COMM_SUCCESS or len(data) != size:
                return None, f"servo {axes[0].id} ({axes[0].role}): {self._comm(result)}"
            return {axes[0].id: (bytes(data), error)}, ""
        group = GroupSyncRead(self._port, self._ph, address, size)
        for axis in axes:
            group.addParam(axis.id)
        result = group.txPacket()
        if result != COMM_SUCCESS:
            return None, f"sync read not sent: {self._comm(result)}"
        replies = {}
        for axis in axes:
            # GroupSyncRead.rxPacket drops each reply's error byte; reading the replies here
            # keeps it, so the alert bit is seen on sync reads too.
            data, result, error = self._ph.readRx(self._port, axis.id, size)
            if result != COMM_SUCCESS or len(data) != size:
                return None, f"servo {axis.id} ({axis.role}): {self._comm(result)}"
            replies[axis.id] = (bytes(data), error)
        return replies, ""

    def sync_write_goals(self, axes: list[ServoAxisConfig], ticks: dict[str, int]) -> None:
        """Goal positions (ticks by role) by one Sync Write, read back, resent where missed."""
        group = GroupSyncWrite(self._port, self._ph, tbl.GOAL_POSITION.address, 4)
        for axis in axes:
            group.addParam(axis.id, list(ticks[axis.role].to_bytes(4, "little", signed=True)))
        result = COMM_SUCCESS
        for _ in self._attempts():
            result = group.txPacket()
            if result == COMM_SUCCESS:
                break
            self._recover()
        if result != COMM_SUCCESS:
            raise DeviceError(
                f"{self.port_name}: sync write of goal positions failed: {self._comm(result)}"
            )
        states = self.read_states(axes)
        for axis in axes:
            if states[axis.role][0] != ticks[axis.role]:
                self.write(axis, tbl.GOAL_POSITION, ticks[axis.role])

    def reboot(self, axis: ServoAxisConfig, boot_timeout_s: float = 2.0) -> None:
        """Reboot a servo until it answers with no hardware error (else ServoHardwareError).

        A reboot resets the servo's RAM items: the caller writes its profile back.
        """
        status = 0
        for _ in self._attempts():
            result, error = self._ph.reboot(self._port, axis.id)
            if result == COMM_SUCCESS and error & 0x7F:
                self._check_status(axis, error, "reboot", True)
            self._wait_answering(axis, boot_timeout_s)
            status = self.read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
            if not status:
                return
        raise self.hardware_error(axis, status)

    def _wait_answering(self, axis: ServoAxisConfig, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            _, result, _ = self._ph.ping(self._port, axis.id)
            if result == COMM_SUCCESS:
                return
            if time.monotonic() > deadline:
                raise DeviceError(
                    f"{self.where(axis)} does not answer within {timeout_s} s of a reboot"
                )
            self._recover()
