"""Dynamixel X-series servo chain driver on the official ``dynamixel_sdk`` (Protocol 2.0).

Degrees in and out; servo ticks never leave the driver. Each axis maps its angle to ticks as

    ticks = 2048 + direction * gear_ratio * (deg - offset_deg) * 4096 / 360

so ``offset_deg`` is the axis angle at the servo's centre tick. Every transaction is retried a
bounded number of times; a write whose reply was lost is confirmed by reading the item back and
sent again only when the read shows it did not take. Every status packet's alert bit is checked:
a servo with a hardware error raises :class:`ServoHardwareError` naming the error in words.
Leaving the context manager (normally or by an exception) switches torque off on every servo.

This module is the chain's API (connect, move, wait, positions, status, reboot, torque), each
call under one lock; the transactions and an axis's ticks are :mod:`rig.dynamixel_link`
(:class:`~rig.dynamixel_link.ServoLink`, :class:`ServoAxisConfig`), the control table
(addresses, sizes, error bits) :mod:`rig.dynamixel_table`.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from types import TracebackType

from core.errors import ConfigError, DeviceError, RigError, SafetyError
from rig import dynamixel_table as tbl
from rig.devices import close_after
from rig.dynamixel_link import (
    ServoAxisConfig,
    ServoHardwareError,
    ServoLink,
    _deg,
    _profile_units,
    _ticks,
)

__all__ = ["DynamixelChain", "ServoAxisConfig", "ServoHardwareError"]


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
        self._axes = {axis.role: axis for axis in axes}
        self._timeout_s = timeout_s
        self._tolerance_deg = tolerance_deg
        self._poll_s = poll_interval_s
        self._link = ServoLink(
            port, baudrate, retries=retries, latency_s=latency_s, retry_backoff_s=retry_backoff_s
        )
        self._lock = threading.RLock()
        self._targets: dict[str, int] = {}

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
            if self._link.is_open:
                return
            self._link.open()
            try:
                for axis in self._axes.values():
                    self._link.check_model(axis)
                for axis in self._axes.values():
                    status = self._link.read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
                    if status and clear_errors:
                        self._reboot(axis)
                    elif status:
                        raise self._link.hardware_error(axis, status)
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
            if self._link.is_open:
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
                self._link.write(axis, tbl.TORQUE_ENABLE, 0, tolerate_alert=True)
            except RigError as exc:
                failures.append(f"servo {axis.id} ({axis.role}): {exc}")
        self._link.close()
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
            self._link.require_open()
            if len(axes) == 1:
                self._link.write(axes[0], tbl.GOAL_POSITION, ticks[axes[0].role])
            else:
                self._link.sync_write_goals(axes, ticks)
            self._targets.update(ticks)
        if wait:
            self.wait_until_arrived(list(targets))

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
                self._link.require_open()
                states = self._link.read_states(axes)
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
            status = self._link.read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
            if status:
                raise self._link.hardware_error(axis, status)
            if not self._link.read(axis, tbl.TORQUE_ENABLE):
                raise DeviceError(
                    f"{self._link.where(axis)}: torque is off, so it will not reach its target;"
                    " call torque(True) first"
                )

    def position_deg(self, role: str) -> float:
        """Present position of one axis in degrees."""
        axis = self._axis(role)
        with self._lock:
            self._link.require_open()
            return _deg(axis, self._link.read(axis, tbl.PRESENT_POSITION))

    def positions_deg(self) -> dict[str, float]:
        """Present positions of every axis in degrees (one Sync Read)."""
        axes = list(self._axes.values())
        with self._lock:
            self._link.require_open()
            states = self._link.read_states(axes)
        return {axis.role: _deg(axis, states[axis.role][2]) for axis in axes}

    # -- status and recovery --------------------------------------------------------------

    def hardware_errors(self) -> dict[str, list[str]]:
        """Hardware Error Status of every axis in words (empty lists when healthy)."""
        with self._lock:
            self._link.require_open()
            return {
                axis.role: tbl.hardware_error_words(
                    self._link.read(axis, tbl.HARDWARE_ERROR_STATUS, tolerate_alert=True)
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
            self._link.require_open()
            self._reboot(axis)

    def torque(self, on: bool, roles: Iterable[str] | None = None) -> None:
        """Switch torque on or off (all axes by default). Off always goes through alerts."""
        axes = [self._axis(r) for r in roles] if roles is not None else list(self._axes.values())
        with self._lock:
            self._link.require_open()
            for axis in axes:
                self._link.write(axis, tbl.TORQUE_ENABLE, int(on), tolerate_alert=not on)
                self._targets.pop(axis.role, None)

    # -- internals ------------------------------------------------------------------------

    def _axis(self, role: str) -> ServoAxisConfig:
        try:
            return self._axes[role]
        except KeyError:
            raise ConfigError(
                f"{self._port_name}: no servo axis {role!r} (axes: {', '.join(self._axes)})"
            ) from None

    def _reboot(self, axis: ServoAxisConfig) -> None:
        """Reboot one servo (the link's) and write back what a reboot resets."""
        self._link.reboot(axis)
        self._write_profile(axis)
        self._targets.pop(axis.role, None)

    def _check_limits(self, axis: ServoAxisConfig, deg: float) -> None:
        if not (math.isfinite(deg) and axis.min_deg <= deg <= axis.max_deg):
            raise SafetyError(
                f"{self._link.where(axis)}: target {deg} deg is outside the soft limits"
                f" [{axis.min_deg}, {axis.max_deg}] deg; nothing was sent"
            )

    def _configure(self, axis: ServoAxisConfig) -> None:
        self._link.write(axis, tbl.TORQUE_ENABLE, 0)
        lo, hi = sorted((_ticks(axis, axis.min_deg), _ticks(axis, axis.max_deg)))
        eeprom = (
            (tbl.OPERATING_MODE, tbl.OPERATING_MODE_POSITION),
            (tbl.HOMING_OFFSET, 0),
            (tbl.MAX_POSITION_LIMIT, hi),
            (tbl.MIN_POSITION_LIMIT, lo),
        )
        for item, value in eeprom:
            # EEPROM wears: write only what differs.
            if self._link.read(axis, item) != value:
                self._link.write(axis, item, value)
        self._write_profile(axis)
        self._link.write(axis, tbl.TORQUE_ENABLE, 1)

    def _write_profile(self, axis: ServoAxisConfig) -> None:
        velocity, acceleration = _profile_units(axis)
        self._link.write(axis, tbl.PROFILE_ACCELERATION, acceleration)
        self._link.write(axis, tbl.PROFILE_VELOCITY, velocity)
