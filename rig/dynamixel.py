"""Dynamixel X-series servo chain driver on the official ``dynamixel_sdk`` (Protocol 2.0).

Degrees in and out; servo ticks never leave this module. Each axis maps its angle to ticks as

    ticks = 2048 + direction * gear_ratio * (deg - offset_deg) * 4096 / 360

so ``offset_deg`` is the axis angle at the servo's centre tick. Every transaction is retried a
bounded number of times; a write whose reply was lost is confirmed by reading the item back and
sent again only when the read shows it did not take. Every status packet's alert bit is checked:
a servo with a hardware error raises :class:`ServoHardwareError` naming the error in words.
Leaving the context manager (normally or by an exception) switches torque off on every servo.

Why one module of ~680 lines: it is one driver class over one serial chain; every method goes
through the same locked, retried, confirmed transaction. The control table (addresses, sizes,
error bits) is :mod:`rig.dynamixel_table`.
"""

from __future__ import annotations

import math
import termios
import threading
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from dynamixel_sdk import (
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from core.errors import (
    ConfigError,
    DeviceError,
    DeviceFault,
    ProtocolError,
    RigError,
    SafetyError,
)
from rig import dynamixel_table as tbl
from rig.devices import close_after
from rig.dynamixel_table import Item

__all__ = ["DynamixelChain", "ServoAxisConfig", "ServoHardwareError"]


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


class DynamixelChain:
    """A chain of X-series servos on one serial port, driven in axis degrees.

    Parameters
    ----------
    port, baudrate
        Serial device and its baud rate (the servos' Baud Rate item must match).
    axes
        The axes on this chain (distinct ids and roles).
    retries
        Extra attempts after a failed transaction before giving up.
    timeout_s
        Default time a move may take to arrive.
    tolerance_deg
        Arrival tolerance on the axis angle.
    poll_interval_s
        Pause between polls while waiting for arrival.
    latency_s
        Time allowed for a reply beyond its transmission time.
    retry_backoff_s
        Pause after a failed attempt, after which late bytes are flushed before trying again.
    """

    def __init__(
        self,
        port: str,
        baudrate: int,
        axes: Sequence[ServoAxisConfig],
        *,
        retries: int = 3,
        timeout_s: float = 10.0,
        tolerance_deg: float = 0.3,
        poll_interval_s: float = 0.01,
        latency_s: float = 0.034,
        retry_backoff_s: float = 0.02,
    ) -> None:
        self._check_axes(port, axes)
        if retries < 0:
            raise ConfigError(f"retries must be >= 0, got {retries}")
        self._port_name = port
        self._baudrate = baudrate
        self._axes = {axis.role: axis for axis in axes}
        self._retries = retries
        self._timeout_s = timeout_s
        self._tolerance_deg = tolerance_deg
        self._poll_s = poll_interval_s
        self._latency_ms = latency_s * 1000.0
        self._backoff_s = retry_backoff_s
        self._ph: Any = PacketHandler(2.0)
        self._port: Any = None
        self._lock = threading.RLock()
        self._targets: dict[str, int] = {}
        self._patience = 1  # the current attempt's factor on reply latency and backoff

    @staticmethod
    def _check_axes(port: str, axes: Sequence[ServoAxisConfig]) -> None:
        ids = [a.id for a in axes]
        roles = [a.role for a in axes]
        if not axes or len(set(ids)) != len(ids) or len(set(roles)) != len(roles):
            pairs = ", ".join(f"{r}={i}" for r, i in zip(roles, ids, strict=True))
            raise ConfigError(f"{port}: axes need distinct ids and roles, got {pairs or 'none'}")
        for axis in axes:
            lo, hi = sorted((_ticks(axis, axis.min_deg), _ticks(axis, axis.max_deg)))
            if lo < 0 or hi > tbl.MAX_TICK:
                raise ConfigError(
                    f"servo axis {axis.role!r} (id {axis.id}): limits"
                    f" {axis.min_deg}..{axis.max_deg} deg map to ticks {lo}..{hi},"
                    f" outside one servo turn (0..{tbl.MAX_TICK});"
                    " change offset_deg or the limits"
                )

    # -- lifecycle ------------------------------------------------------------------------

    @property
    def roles(self) -> list[str]:
        """Axis roles in configuration order."""
        return list(self._axes)

    def connect(self, *, clear_errors: bool = False) -> None:
        """Open the port, ping every servo and check its model, configure it, torque on.

        Configuration switches torque off first (EEPROM items are only written then, and only
        when they differ), sets Position Control Mode, Homing Offset 0 (the axis offset is
        applied here), the position limits and the profile. A servo that reports a hardware
        error raises :class:`ServoHardwareError` unless ``clear_errors``, which reboots it.
        On any failure torque is switched off again and the port closed.
        """
        with self._lock:
            if self._port is not None:
                return
            port = _PortHandler(self._port_name, self._latency_ms)
            try:
                opened = port.openPort() and port.setBaudRate(self._baudrate)
            except Exception as exc:  # pyserial raises SerialException/OSError subclasses
                if port.is_open:
                    port.closePort()
                raise DeviceError(f"{self._port_name}: cannot open the port: {exc}") from exc
            if not opened:
                if port.is_open:
                    port.closePort()
                raise DeviceError(
                    f"{self._port_name}: cannot open the port at {self._baudrate} baud"
                    " (unsupported baud rate?)"
                )
            self._port = port
            try:
                for axis in self._axes.values():
                    self._check_model(axis)
                for axis in self._axes.values():
                    status = self._read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
                    if status and clear_errors:
                        self._reboot(axis)
                    elif status:
                        raise self._hardware_error(axis, status)
                for axis in self._axes.values():
                    self._configure(axis)
            except BaseException as exc:
                failures = self._shutdown()
                if failures:
                    exc.add_note("torque could not be switched off: " + "; ".join(failures))
                raise

    def close(self) -> None:
        """Switch torque off on every servo (best effort) and close the port.

        Raises :class:`DeviceError` after closing when some servo could not be switched off.
        """
        with self._lock:
            if self._port is not None:
                failures = self._shutdown()
                if failures:
                    raise DeviceError(
                        f"{self._port_name}: torque could not be switched off: "
                        + "; ".join(failures)
                    )

    def __enter__(self) -> DynamixelChain:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        close_after(self.close, exc)  # a failed torque-off is said, never hidden

    def _shutdown(self) -> list[str]:
        failures = []
        for axis in self._axes.values():
            try:
                self._write(axis, tbl.TORQUE_ENABLE, 0, tolerate_alert=True)
            except RigError as exc:
                failures.append(f"servo {axis.id} ({axis.role}): {exc}")
        self._port.closePort()
        self._port = None
        self._targets.clear()
        return failures

    # -- motion ---------------------------------------------------------------------------

    def move_to_deg(self, role: str, deg: float, *, wait: bool = True) -> None:
        """Move one axis to ``deg``; with ``wait``, return once it has arrived."""
        self.move_many_deg({role: deg}, wait=wait)

    def move_many_deg(self, targets: Mapping[str, float], *, wait: bool = True) -> None:
        """Move several axes together (one Sync Write), then wait for all when ``wait``.

        Every target is checked against the soft limits before any byte is sent
        (:class:`SafetyError`). The Sync Write has no reply, so the goals are read back; a
        servo whose goal did not change gets its goal again by a confirmed single write.
        """
        axes = [self._axis(role) for role in targets]
        for axis in axes:
            self._check_limits(axis, targets[axis.role])
        if not axes:
            return
        ticks = {axis.role: _ticks(axis, targets[axis.role]) for axis in axes}
        with self._lock:
            self._require_port()
            if len(axes) == 1:
                self._write(axes[0], tbl.GOAL_POSITION, ticks[axes[0].role])
            else:
                self._sync_write_goals(axes, ticks)
            self._targets.update(ticks)
        if wait:
            self.wait_until_arrived(list(targets))

    def _sync_write_goals(self, axes: list[ServoAxisConfig], ticks: dict[str, int]) -> None:
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
                f"{self._port_name}: sync write of goal positions failed: {self._comm(result)}"
            )
        states = self._read_states(axes)
        for axis in axes:
            if states[axis.role][0] != ticks[axis.role]:
                self._write(axis, tbl.GOAL_POSITION, ticks[axis.role])

    def wait_until_arrived(self, roles: Iterable[str], timeout_s: float | None = None) -> None:
        """Poll until every axis has stopped (Moving = 0) within tolerance of its target.

        Raises :class:`ServoHardwareError` as soon as a servo reports one (e.g. an overload
        stopping it short), and :class:`DeviceError` naming the laggards after ``timeout_s``.
        """
        axes = [self._axis(role) for role in roles]
        if not axes:
            return
        timeout = self._timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        while True:
            with self._lock:
                self._require_port()
                states = self._read_states(axes)
            pending = []
            for axis in axes:
                goal, moving, present = states[axis.role]
                target = self._targets.get(axis.role, goal)
                error_deg = abs(_deg(axis, present) - _deg(axis, target))
                if moving or error_deg > self._tolerance_deg:
                    pending.append((axis, present, target, moving))
            if not pending:
                return
            for axis, _, _, moving in pending:
                if not moving:
                    self._why_stopped_short(axis)
            if time.monotonic() > deadline:
                lagging = ", ".join(
                    f"servo {a.id} ({a.role}) at {_deg(a, p):.2f} deg, target {_deg(a, t):.2f} deg"
                    f"{', moving' if m else ''}"
                    for a, p, t, m in pending
                )
                raise DeviceError(
                    f"{self._port_name}: not arrived within {timeout:.2f} s: {lagging}"
                )
            time.sleep(self._poll_s)

    def _why_stopped_short(self, axis: ServoAxisConfig) -> None:
        """Raise when a servo that stopped off target cannot get there by itself."""
        with self._lock:
            # A shutdown (overload, overheating...) drops torque and sets the error status.
            status = self._read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
            if status:
                raise self._hardware_error(axis, status)
            if not self._read(axis, tbl.TORQUE_ENABLE):
                raise DeviceError(
                    f"{self._where(axis)}: torque is off, so it will not reach its target;"
                    " call torque(True) first"
                )

    def position_deg(self, role: str) -> float:
        """Present position of one axis in degrees."""
        axis = self._axis(role)
        with self._lock:
            self._require_port()
            return _deg(axis, self._read(axis, tbl.PRESENT_POSITION))

    def positions_deg(self) -> dict[str, float]:
        """Present positions of every axis in degrees (one Sync Read)."""
        axes = list(self._axes.values())
        with self._lock:
            self._require_port()
            states = self._read_states(axes)
        return {axis.role: _deg(axis, states[axis.role][2]) for axis in axes}

    # -- status and recovery --------------------------------------------------------------

    def hardware_errors(self) -> dict[str, list[str]]:
        """Hardware Error Status of every axis in words (empty lists when healthy)."""
        with self._lock:
            self._require_port()
            return {
                axis.role: tbl.hardware_error_words(
                    self._read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
                )
                for axis in self._axes.values()
            }

    def reboot(self, role: str) -> None:
        """Reboot one servo to clear its hardware error; torque stays off afterwards.

        Waits until the servo answers again, checks that the error is gone and writes its
        profile back (a reboot resets RAM items). Call :meth:`torque` to hold position again.
        """
        axis = self._axis(role)
        with self._lock:
            self._require_port()
            self._reboot(axis)

    def torque(self, on: bool, roles: Iterable[str] | None = None) -> None:
        """Switch torque on or off (all axes by default). Off always goes through alerts."""
        axes = [self._axis(r) for r in roles] if roles is not None else list(self._axes.values())
        with self._lock:
            self._require_port()
            for axis in axes:
                self._write(axis, tbl.TORQUE_ENABLE, int(on), tolerate_alert=not on)
                self._targets.pop(axis.role, None)

    # -- internals ------------------------------------------------------------------------

    def _axis(self, role: str) -> ServoAxisConfig:
        try:
            return self._axes[role]
        except KeyError:
            raise ConfigError(
                f"{self._port_name}: no servo axis {role!r} (axes: {', '.join(self._axes)})"
            ) from None

    def _where(self, axis: ServoAxisConfig) -> str:
        return f"{self._port_name}: servo {axis.id} ({axis.role})"

    def _require_port(self) -> None:
        if self._port is None:
            raise DeviceError(f"{self._port_name}: not connected (call connect())")

    def _check_limits(self, axis: ServoAxisConfig, deg: float) -> None:
        if not (math.isfinite(deg) and axis.min_deg <= deg <= axis.max_deg):
            raise SafetyError(
                f"{self._where(axis)}: target {deg} deg is outside the soft limits"
                f" [{axis.min_deg}, {axis.max_deg}] deg; nothing was sent"
            )

    def _comm(self, result: int) -> str:
        return str(self._ph.getTxRxResult(result)).removeprefix("[TxRxResult] ")

    def _attempts(self) -> Iterator[int]:
        """Attempt numbers of one transaction, each allowing twice the reply latency before.

        A real servo answers within a millisecond; a loaded host (or an emulator sharing its
        cores) may not read the reply for tens of milliseconds. Doubling the allowance per
        attempt keeps the usual case fast and a busy machine from failing the transaction.
        """
        try:
            for attempt in range(self._retries + 1):
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
            raise DeviceError(f"{self._port_name}: the serial port failed: {exc}") from exc

    def _check_model(self, axis: ServoAxisConfig) -> None:
        last = ""
        for _ in self._attempts():
            model, result, _ = self._ph.ping(self._port, axis.id)
            if result == COMM_SUCCESS:
                if model != axis.model_number:
                    raise DeviceError(
                        f"{self._where(axis)} is model {tbl.model_name(model)}, the config"
                        f" expects {tbl.model_name(axis.model_number)}"
                    )
                return
            last = self._comm(result)
            self._recover()
        raise DeviceError(
            f"{self._where(axis)} does not answer a ping at {self._baudrate} baud after"
            f" {self._retries + 1} attempts ({last}); check power, cabling, id and baud rate"
        )

    def _check_status(self, axis: ServoAxisConfig, error: int, action: str, alert: bool) -> None:
        code = error & 0x7F
        if code:
            cls = ProtocolError if code in tbl.PROTOCOL_RESULTS else DeviceError
            alert_note = " (it also reports a hardware error)" if error & tbl.ALERT_BIT else ""
            raise cls(f"{self._where(axis)}: {action}: {tbl.result_error_words(code)}{alert_note}")
        if error & tbl.ALERT_BIT and not alert:
            raise self._hardware_error(axis)

    def _hardware_error(
        self, axis: ServoAxisConfig, status: int | None = None
    ) -> ServoHardwareError:
        if status is None:
            status = self._read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
        words = tbl.hardware_error_words(status) or ["alert bit set, Hardware Error Status 0"]
        return ServoHardwareError(
            f"{self._where(axis)} reports a hardware error: {', '.join(words)}"
            f" (Hardware Error Status 0x{status:02X}); torque is off until reboot({axis.role!r})",
            servo_id=axis.id,
            role=axis.role,
            errors=words,
        )

    def _read(self, axis: ServoAxisConfig, item: Item, *, tolerate_alert: bool = False) -> int:
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
            f"{self._where(axis)}: reading {item} failed after {self._retries + 1} attempts: {last}"
        )

    def _write(
        self, axis: ServoAxisConfig, item: Item, value: int, *, tolerate_alert: bool = False
    ) -> None:
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
                current = self._read(axis, item, tolerate_alert=tolerate_alert)
            except ServoHardwareError:
                raise
            except DeviceError as exc:
                raise DeviceError(
                    f"{self._where(axis)}: {action}: no reply ({last}) and the outcome could"
                    f" not be confirmed by reading it back: {exc}"
                ) from exc
            if current == value:
                return
        raise DeviceError(
            f"{self._where(axis)}: {action} failed after {self._retries + 1} attempts: {last}"
        )

    def _read_states(self, axes: list[ServoAxisConfig]) -> dict[str, tuple[int, int, int]]:
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
            f"{self._port_name}: reading the state of"
            f" {', '.join(f'servo {a.id} ({a.role})' for a in axes)} failed after"
            f" {self._retries + 1} attempts: {last}"
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

    def _configure(self, axis: ServoAxisConfig) -> None:
        self._write(axis, tbl.TORQUE_ENABLE, 0)
        lo, hi = sorted((_ticks(axis, axis.min_deg), _ticks(axis, axis.max_deg)))
        eeprom = (
            (tbl.OPERATING_MODE, tbl.OPERATING_MODE_POSITION),
            (tbl.HOMING_OFFSET, 0),
            (tbl.MAX_POSITION_LIMIT, hi),
            (tbl.MIN_POSITION_LIMIT, lo),
        )
        for item, value in eeprom:
            # EEPROM wears: write only what differs.
            if self._read(axis, item) != value:
                self._write(axis, item, value)
        self._write_profile(axis)
        self._write(axis, tbl.TORQUE_ENABLE, 1)

    def _write_profile(self, axis: ServoAxisConfig) -> None:
        velocity, acceleration = _profile_units(axis)
        self._write(axis, tbl.PROFILE_ACCELERATION, acceleration)
        self._write(axis, tbl.PROFILE_VELOCITY, velocity)

    def _reboot(self, axis: ServoAxisConfig, boot_timeout_s: float = 2.0) -> None:
        status = 0
        for _ in self._attempts():
            result, error = self._ph.reboot(self._port, axis.id)
            if result == COMM_SUCCESS and error & 0x7F:
                self._check_status(axis, error, "reboot", True)
            self._wait_answering(axis, boot_timeout_s)
            status = self._read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
            if not status:
                self._write_profile(axis)
                self._targets.pop(axis.role, None)
                return
        raise self._hardware_error(axis, status)

    def _wait_answering(self, axis: ServoAxisConfig, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            _, result, _ = self._ph.ping(self._port, axis.id)
            if result == COMM_SUCCESS:
                return
            if time.monotonic() > deadline:
                raise DeviceError(
                    f"{self._where(axis)} does not answer within {timeout_s} s of a reboot"
                )
            self._recover()
