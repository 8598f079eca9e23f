"""GRBL 1.1 light gantry driver on ``pyserial``: light azimuth and inclination as two GRBL axes.

Degrees in, G-code only inside this module. The driver speaks the send-response protocol (one
line, wait for ``ok``/``error:N``) and polls ``?`` status reports; see ``docs/grbl.md``.

Safety rules it keeps:

- every line is validated (printable ASCII, no ``%``, no real-time characters, no newline inside)
  before a byte is written (:func:`rig.grbl_protocol.validate_command`);
- targets outside the configured soft limits raise :class:`~core.errors.SafetyError` before a byte
  is written;
- moves go to *machine* coordinates (``G90 G53 G1``), so a stray ``G92`` or work offset left on
  the controller cannot shift them; the axis offsets of :class:`GantryAxisConfig` are the one
  place an angle zero is defined;
- an alarm is never cleared implicitly: only :meth:`GrblGantry.unlock`, :meth:`GrblGantry.home`
  or ``unlock_on_connect=True`` do;
- leaving the context manager (normally or by an exception) stops motion with a feed hold and
  switches the light off.

Why one module of ~700 lines: it is one driver class over one connection; its methods share the
exchange state (the line in flight, its replies, the last status), so splitting them would spread
one protocol exchange over files. The wire format (validation, replies, status reports) is
:mod:`rig.grbl_protocol`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Literal

import serial

from core.errors import (
    ConfigError,
    DeviceError,
    DeviceFault,
    InputError,
    ProtocolError,
    RigError,
    SafetyError,
)
from rig.grbl_protocol import (
    GrblStatus,
    Reply,
    ReplyKind,
    Vector3,
    alarm_meaning,
    banner_version,
    classify,
    error_meaning,
    format_number,
    parse_setting,
    parse_status,
    validate_command,
)

__all__ = [
    "GantryAxes",
    "GantryAxisConfig",
    "GrblAlarmError",
    "GrblCommandError",
    "GrblGantry",
    "GrblStatus",
    "GrblTimeoutError",
]

LightMode = Literal["spindle", "coolant"]
_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}
_MAX_NOISE_LINES = 50  # unparseable lines tolerated in one exchange before calling it broken
_INTEGER_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32})


@dataclass(frozen=True)
class GantryAxisConfig:
    """How one rig angle maps to one GRBL axis.

    ``units = direction * (angle_deg - offset_deg) * units_per_deg``: ``offset_deg`` is the angle
    at machine zero (where homing puts the axis, less GRBL's pull-off), ``direction`` is +1 or
    -1, ``units_per_deg`` the GRBL units (mm in GRBL's words) per degree. ``min_deg`` and
    ``max_deg`` are the soft limits the driver enforces before sending.
    """

    letter: Literal["X", "Y", "Z"]
    min_deg: float
    max_deg: float
    offset_deg: float = 0.0
    direction: Literal[1, -1] = 1
    units_per_deg: float = 1.0

    def __post_init__(self) -> None:
        if self.letter not in _AXIS_INDEX:
            raise ConfigError(f"GRBL axis letter {self.letter!r} is not one of X, Y, Z")
        if self.direction not in (1, -1):
            raise ConfigError(f"axis {self.letter}: direction {self.direction!r} is not 1 or -1")
        numbers = (self.min_deg, self.max_deg, self.offset_deg, self.units_per_deg)
        if not all(math.isfinite(v) for v in numbers):
            raise ConfigError(f"axis {self.letter}: limits, offset and scale must be finite")
        if not self.units_per_deg > 0:
            raise ConfigError(f"axis {self.letter}: units_per_deg {self.units_per_deg} <= 0")
        if not self.min_deg < self.max_deg:
            raise ConfigError(
                f"axis {self.letter}: min_deg {self.min_deg} is not below max_deg {self.max_deg}"
            )

    def to_units(self, angle_deg: float) -> float:
        """GRBL machine units of a rig angle."""
        return self.direction * (angle_deg - self.offset_deg) * self.units_per_deg

    def to_deg(self, units: float) -> float:
        """Rig angle of a GRBL machine coordinate."""
        return self.offset_deg + self.direction * units / self.units_per_deg


@dataclass(frozen=True)
class GantryAxes:
    """The two gantry axes: light azimuth and light inclination."""

    azimuth: GantryAxisConfig
    inclination: GantryAxisConfig

    def __post_init__(self) -> None:
        if self.azimuth.letter == self.inclination.letter:
            raise ConfigError(
                f"light azimuth and inclination both use GRBL axis {self.azimuth.letter}"
            )

    def angles(self, machine: Vector3) -> tuple[float, float]:
        """(azimuth_deg, inclination_deg) of a machine position."""
        az, inc = self.azimuth, self.inclination
        return az.to_deg(machine[_AXIS_INDEX[az.letter]]), inc.to_deg(
            machine[_AXIS_INDEX[inc.letter]]
        )


class GrblCommandError(DeviceError):
    """GRBL refused a command with ``error:N``; nothing of the line was executed."""

    def __init__(self, port: str, command: str, code: int) -> None:
        self.port, self.command, self.code = port, command, code
        self.meaning = error_meaning(code)
        hint = ""
        if code == 9:
            hint = "; GRBL is in alarm: check the gantry, then call home() or unlock()"
        super().__init__(
            f"GRBL at {port} refused {command!r} with error:{code} ({self.meaning}){hint}"
        )


class GrblAlarmError(DeviceFault):
    """GRBL raised ``ALARM:N``: motion stopped, spindle and coolant off, G-code locked."""

    def __init__(self, port: str, command: str, code: int, detail: str = "") -> None:
        self.port, self.command, self.code = port, command, code
        self.meaning = alarm_meaning(code)
        super().__init__(
            f"GRBL at {port} raised ALARM:{code} ({self.meaning}) during {command!r}{detail}"
        )


class GrblTimeoutError(DeviceError):
    """GRBL did not answer (or did not finish) in time."""

    def __init__(self, port: str, command: str, what: str) -> None:
        self.port, self.command = port, command
        super().__init__(f"GRBL at {port}: {what} (command {command!r})")


class GrblGantry:
    """The light gantry on a GRBL 1.1 controller.

    Parameters
    ----------
    port : serial device (``/dev/ttyUSB0``, or an emulator's pty)
    baudrate : GRBL 1.1 uses 115200
    axes : the azimuth and inclination axis mapping and soft limits
    light : ``"spindle"`` (M3 S<pwm>/M5, intensity scaled to ``$30``) or ``"coolant"`` (M8/M9,
        on/off only)
    feed_deg_min : feed of moves along the straight line in (azimuth, inclination), deg/min
    timeout_s : wait for one reply
    home_timeout_s : wait for ``$H`` to finish
    unlock_on_connect : send ``$X`` at connect when GRBL is in alarm (off: unlocking is an
        operator's explicit decision)
    retries : re-sends of a command whose reply was lost, where that is safe
    poll_interval_s : pause between status polls while waiting for Idle
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        axes: GantryAxes | None = None,
        *,
        light: LightMode = "spindle",
        feed_deg_min: float = 3600.0,
        timeout_s: float = 2.0,
        home_timeout_s: float = 120.0,
        unlock_on_connect: bool = False,
        retries: int = 2,
        poll_interval_s: float = 0.02,
        position_tolerance_deg: float = 0.01,
    ) -> None:
        if axes is None:
            raise ConfigError(f"GRBL at {port}: the gantry axes are not configured")
        if light not in ("spindle", "coolant"):
            raise ConfigError(f"GRBL at {port}: light mode {light!r} is not spindle or coolant")
        if not (math.isfinite(feed_deg_min) and feed_deg_min > 0):
            raise ConfigError(f"GRBL at {port}: feed_deg_min {feed_deg_min} must be > 0")
        self.port = port
        self.baudrate = baudrate
        self.axes = axes
        self.light_mode: LightMode = light
        self.feed_deg_min = feed_deg_min
        self.timeout_s = timeout_s
        self.home_timeout_s = home_timeout_s
        self.unlock_on_connect = unlock_on_connect
        self.retries = retries
        self.poll_interval_s = poll_interval_s
        self.position_tolerance_deg = position_tolerance_deg
        self.messages: list[str] = []
        """Push messages (``[MSG:...]``, alarms, banners) seen, oldest first."""
        self.noise_lines = 0
        """Unparseable lines received and skipped (line noise)."""
        self.version: str | None = None
        self._serial: Any = None
        self._rx = bytearray()
        self._settings: dict[int, float] = {}
        self._wco: Vector3 | None = None
        self._last_status: GrblStatus | None = None
        self._activity = ""  # the motion command under way, to name it when an alarm comes

    # -- connection -------------------------------------------------------------------------

    def connect(self) -> None:
        """Open the port, soft-reset GRBL, wait for its banner and read its settings.

        Raises
        ------
        DeviceError
            The port cannot be opened, or no GRBL 1.1 banner came after the reset.
        """
        if self._serial is not None:
            return
        try:
            self._serial = serial.Serial(self.port, self.baudrate, timeout=0.01, write_timeout=2)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"cannot open GRBL port {self.port}: {exc}") from exc
        try:
            # Bytes from before (a power-up banner, a half line) would be misread as replies.
            deadline = time.monotonic() + 0.02
            while self._read_line(deadline) is not None:
                pass
            self._rx.clear()
            self._soft_reset(attempts=2)
            self.settings()
            status = self.status()
            if status.state == "Alarm" and self.unlock_on_connect:
                self.unlock()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the port (no bytes sent; see the context manager for a safe stop)."""
        if self._serial is not None:
            try:
                self._serial.close()
            finally:
                self._serial = None
                self._rx.clear()

    def __enter__(self) -> GrblGantry:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self.safe_stop()
        finally:
            self.close()

    def safe_stop(self) -> None:
        """Stop motion and switch the light off, whatever state GRBL is in; never raises.

        Moving: feed hold, wait for Hold:0, soft reset (a reset at Hold:0 keeps the position and
        switches spindle and coolant off; ``M5`` would wait for the held motion forever). Idle:
        ``M5``/``M9``. Alarm: nothing, GRBL switched them off when it raised the alarm. If any
        of it fails, a bare soft reset, which stops everything.
        """
        if self._serial is None:
            return
        try:
            status = self.status()
            if status.moving or status.state in ("Hold", "Door", "Sleep"):
                if status.moving:
                    self._write(b"!", "!")
                    self._wait_for(lambda s: not s.moving, self.timeout_s, "!")
                self._soft_reset()
            elif status.state != "Alarm":
                self.light_off()
        except RigError:
            try:
                self._write(b"\x18", "soft reset")
            except RigError:
                pass

    # -- queries ----------------------------------------------------------------------------

    def status(self) -> GrblStatus:
        """One real-time status report (``?``), retried when it is lost."""
        for _ in range(self.retries + 1):
            self._write(b"?", "?")
            deadline = time.monotonic() + self.timeout_s
            while (reply := self._next_reply(deadline, "?")) is not None:
                if reply.kind is ReplyKind.STATUS and self._last_status is not None:
                    return self._last_status
        raise GrblTimeoutError(
            self.port, "?", f"no status report in {self.retries + 1} tries of {self.timeout_s} s"
        )

    def settings(self) -> dict[int, float]:
        """GRBL's settings from ``$$`` (``{110: 500.0, ...}``); also cached for the driver."""
        lines = self._command("$$", retry=True)
        settings: dict[int, float] = {}
        for line in lines:
            if classify(line).kind is ReplyKind.SETTING:
                number, value = parse_setting(line)
                settings[number] = value
        if not settings:
            raise ProtocolError(f"GRBL at {self.port} answered '$$' without any setting")
        self._settings = settings
        return dict(settings)

    def set_setting(self, number: int, value: float) -> None:
        """Write ``$number=value`` (an EEPROM write; GRBL accepts it only when Idle or Alarm)."""
        if not (isinstance(number, int) and 0 <= number <= 255):
            raise InputError(f"GRBL at {self.port}: setting number {number!r} is not 0..255")
        if not math.isfinite(value):
            raise InputError(f"GRBL at {self.port}: setting ${number} value {value} not finite")
        text = str(int(value)) if number in _INTEGER_SETTINGS else format_number(value)
        self._command(f"${number}={text}", retry=True)
        self.settings()  # GRBL changes other settings too ($22=0 clears $20)

    def position_deg(self) -> tuple[float, float]:
        """Current (light azimuth, light inclination) in degrees, from a status report."""
        return self.axes.angles(self._machine_position())

    # -- motion -----------------------------------------------------------------------------

    def home(self) -> GrblStatus:
        """Run GRBL's homing cycle ``$H`` (needs ``$22=1``); clears an alarm on success.

        Raises
        ------
        DeviceError
            Homing is disabled (nothing sent), or GRBL reports a homing alarm.
        """
        if not self._settings.get(22):
            raise DeviceError(
                f"GRBL at {self.port}: homing is disabled ($22=0); nothing was sent. Enable it "
                "with set_setting(22, 1) on a gantry with limit switches, or place the gantry by "
                "hand and unlock()"
            )
        self._activity = "$H"
        self._command(
            "$H",
            retry=True,
            timeout_s=self.home_timeout_s,
            confirm=lambda: self.status().state == "Idle",
        )
        return self.status()

    def unlock(self) -> GrblStatus:
        """Clear an alarm lock with ``$X``: the operator's explicit decision that it is safe."""
        self._command("$X", retry=True)
        return self.status()

    def move_to_deg(
        self, azimuth_deg: float, inclination_deg: float, wait: bool = True
    ) -> GrblStatus | None:
        """Move the light to (azimuth, inclination) with an absolute ``G90 G53 G1`` move.

        Returns the Idle status after arrival when ``wait``, else None right after GRBL
        accepted the move.

        Raises
        ------
        SafetyError
            A target outside the soft limits (or not finite); nothing was sent.
        GrblCommandError, GrblAlarmError, GrblTimeoutError
            GRBL refused the move, raised an alarm, or did not arrive in time.
        """
        az, inc = self.axes.azimuth, self.axes.inclination
        for role, axis, angle in (
            ("azimuth", az, azimuth_deg),
            ("inclination", inc, inclination_deg),
        ):
            if not (math.isfinite(angle) and axis.min_deg <= angle <= axis.max_deg):
                raise SafetyError(
                    f"light {role} {angle} deg is outside the gantry's soft limits "
                    f"[{axis.min_deg}, {axis.max_deg}] deg (GRBL axis {axis.letter} at "
                    f"{self.port}); nothing was sent"
                )
        target = [0.0, 0.0, 0.0]
        start = self._machine_position()
        target[2] = start[2]
        target[_AXIS_INDEX[az.letter]] = az.to_units(azimuth_deg)
        target[_AXIS_INDEX[inc.letter]] = inc.to_units(inclination_deg)
        start_deg = self.axes.angles(start)
        dist_deg = math.hypot(azimuth_deg - start_deg[0], inclination_deg - start_deg[1])
        dist_units = math.dist(start, target)
        # GRBL's F is along the path in units; scale it so the path runs at feed_deg_min.
        ratio = (
            dist_units / dist_deg if dist_deg > 1e-9 else max(az.units_per_deg, inc.units_per_deg)
        )
        feed = self.feed_deg_min * ratio
        line = (
            f"G90 G53 G1 {az.letter}{format_number(target[_AXIS_INDEX[az.letter]])} "
            f"{inc.letter}{format_number(target[_AXIS_INDEX[inc.letter]])} F{format_number(feed)}"
        )
        goal = (target[0], target[1], target[2])
        self._activity = line
        self._command(line, retry=True, confirm=lambda: self._accepted(goal))
        if not wait:
            return None
        status = self.wait_until_idle(self.timeout_s + 2.0 * self._duration_s(start, goal, feed))
        reached = status.machine_position(self._wco)
        if reached is None or self._distance_deg(reached, goal) > self.position_tolerance_deg:
            raise DeviceError(
                f"GRBL at {self.port} went Idle at {reached} instead of {goal} after {line!r}"
            )
        return status

    def wait_until_idle(self, timeout_s: float | None = None) -> GrblStatus:
        """Poll status until GRBL is Idle.

        Raises
        ------
        GrblTimeoutError
            Not Idle within ``timeout_s`` (a feed hold counts as not Idle).
        DeviceError
            GRBL is in Alarm.
        """
        limit = self.timeout_s if timeout_s is None else timeout_s
        return self._wait_for(lambda s: s.state == "Idle", limit, "wait for Idle")

    def feed_hold(self) -> GrblStatus:
        """Feed hold ``!``: decelerate to a stop; GRBL keeps the rest of the move."""
        self._write(b"!", "!")
        return self.status()

    def resume(self) -> GrblStatus:
        """Cycle start ``~`` after a feed hold (waits for Hold:0, as GRBL ignores it before)."""
        self._wait_for(lambda s: not (s.state == "Hold" and s.substate == 1), self.timeout_s, "~")
        self._write(b"~", "~")
        return self.status()

    # -- light ------------------------------------------------------------------------------

    def light_on(self, intensity: float = 1.0) -> None:
        """Switch the light on: ``M3 S<intensity * $30>`` or ``M8`` (coolant: 0 or 1 only)."""
        if not (math.isfinite(intensity) and 0.0 <= intensity <= 1.0):
            raise InputError(f"GRBL at {self.port}: light intensity {intensity} is not in [0, 1]")
        if self.light_mode == "coolant":
            if intensity not in (0.0, 1.0):
                raise InputError(
                    f"GRBL at {self.port}: the coolant-pin light is on/off only, not {intensity}"
                )
            self._command("M8" if intensity else "M9", retry=True)
            return
        max_speed = self._settings.get(30, 1000.0)
        self._command(f"M3 S{format_number(intensity * max_speed)}", retry=True)

    def light_off(self) -> None:
        """Switch the light off (``M5`` or ``M9``)."""
        self._command("M5" if self.light_mode == "spindle" else "M9", retry=True)

    # -- internals --------------------------------------------------------------------------

    def _require_open(self) -> Any:
        if self._serial is None:
            raise DeviceError(f"GRBL at {self.port} is not connected (call connect())")
        return self._serial

    def _write(self, data: bytes, command: str) -> None:
        port = self._require_open()
        try:
            port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"GRBL at {self.port}: writing {command!r} failed: {exc}") from exc

    def _read_line(self, deadline: float) -> str | None:
        port = self._require_open()
        while True:
            end = self._rx.find(b"\n")
            if end >= 0:
                raw = bytes(self._rx[:end]).rstrip(b"\r")
                del self._rx[: end + 1]
                return raw.decode("ascii", errors="replace")
            if time.monotonic() >= deadline:
                return None
            try:
                self._rx += port.read(max(1, port.in_waiting))
            except (serial.SerialException, OSError) as exc:
                raise DeviceError(f"GRBL at {self.port}: reading failed: {exc}") from exc

    def _next_reply(self, deadline: float, command: str) -> Reply | None:
        """The next reply that concerns the caller; push messages and alarms handled here."""
        noise = 0
        while (line := self._read_line(deadline)) is not None:
            reply = classify(line)
            if reply.kind is ReplyKind.STATUS:
                try:
                    status = parse_status(line)
                except ValueError:
                    reply = Reply(ReplyKind.UNKNOWN, line)
                else:
                    self._last_status = status
                    if status.wco is not None:
                        self._wco = status.wco
                    return reply
            if reply.kind is ReplyKind.ALARM and reply.code is not None:
                self._on_alarm(reply.code, command)
            if reply.kind is ReplyKind.BANNER:
                self.messages.append(line)
                raise DeviceError(
                    f"GRBL at {self.port} reset unexpectedly while waiting for the reply to "
                    f"{command!r} (banner {line!r}); queued motion and the light state are lost"
                )
            if reply.kind is ReplyKind.MESSAGE:
                self.messages.append(line)
            elif reply.kind is ReplyKind.UNKNOWN:
                noise += 1
                self.noise_lines += 1
                if noise > _MAX_NOISE_LINES:
                    raise ProtocolError(
                        f"GRBL at {self.port}: more than {_MAX_NOISE_LINES} unreadable lines "
                        f"while waiting for the reply to {command!r} (last {line!r})"
                    )
            elif reply.kind is not ReplyKind.EMPTY:
                return reply
        return None

    def _transact(self, command: str, timeout_s: float) -> list[str]:
        validate_command(command, port=self.port)
        self._write(command.encode("ascii") + b"\n", command)
        deadline = time.monotonic() + timeout_s
        payload: list[str] = []
        while (reply := self._next_reply(deadline, command)) is not None:
            if reply.kind is ReplyKind.OK:
                return payload
            if reply.kind is ReplyKind.ERROR and reply.code is not None:
                raise GrblCommandError(self.port, command, reply.code)
            if reply.kind is not ReplyKind.STATUS:
                payload.append(reply.text)
        raise GrblTimeoutError(self.port, command, f"no reply within {timeout_s} s")

    def _command(
        self,
        command: str,
        *,
        retry: bool,
        timeout_s: float | None = None,
        confirm: Callable[[], bool] | None = None,
    ) -> list[str]:
        """Send one line and wait for ``ok``; on a lost reply, confirm or re-send.

        Only idempotent lines are retried (queries, settings, absolute moves, light switches):
        after a timeout, late replies are drained, ``confirm`` (if given) asks GRBL whether the
        line took effect, and otherwise the line is sent again.
        """
        timeout = self.timeout_s if timeout_s is None else timeout_s
        attempts = self.retries + 1 if retry else 1
        for attempt in range(attempts):
            try:
                return self._transact(command, timeout)
            except GrblTimeoutError:
                if attempt == attempts - 1:
                    raise GrblTimeoutError(
                        self.port, command, f"no reply in {attempts} tries of {timeout} s"
                    ) from None
                self._drain(min(0.2, timeout))
                if confirm is not None and confirm():
                    return []
        raise AssertionError("unreachable")

    def _drain(self, quiet_s: float) -> None:
        """Read and drop replies that come late, handling alarms and messages as usual."""
        while self._next_reply(time.monotonic() + quiet_s, "drain") is not None:
            pass

    def _soft_reset(self, attempts: int = 1) -> None:
        """Send 0x18 and wait for the ``Grbl 1.1x`` banner; whatever came before is dropped."""
        for _ in range(attempts):
            self._write(b"\x18", "soft reset")
            deadline = time.monotonic() + self.timeout_s
            while (line := self._read_line(deadline)) is not None:
                version = banner_version(line)
                if version is None:
                    if classify(line).kind in (ReplyKind.ALARM, ReplyKind.MESSAGE):
                        self.messages.append(line)
                    continue
                self.messages.append(line)
                if not version.startswith("1.1"):
                    raise DeviceError(
                        f"{self.port} answers as GRBL {version}; this driver speaks GRBL 1.1"
                    )
                self.version = version
                self._last_status = None
                # A second banner may follow (a controller that was still booting when it got
                # the reset): take it here, not later as an "unexpected reset".
                while (more := self._read_line(time.monotonic() + 0.02)) is not None:
                    if classify(more).kind in (ReplyKind.BANNER, ReplyKind.MESSAGE):
                        self.messages.append(more)
                return
        raise DeviceError(
            f"no GRBL banner from {self.port} within {self.timeout_s} s after a soft reset "
            f"({attempts} tries): is it a GRBL 1.1 controller, at {self.baudrate} baud?"
        )

    def _on_alarm(self, code: int, command: str) -> None:
        self.messages.append(f"ALARM:{code}")
        if command in ("?", "drain", "wait for Idle") and self._activity:
            command = self._activity  # the alarm belongs to the motion, not to the poll
        if code in (1, 2):
            # Critical: GRBL now ignores everything but a reset (not even '?'). The reset keeps it
            # locked in Alarm, so this clears nothing; it only makes GRBL answer again.
            try:
                self._soft_reset()
            except DeviceError:
                detail = "; GRBL gave no banner after the soft reset that follows this alarm"
            else:
                detail = (
                    "; GRBL was soft-reset (it answers nothing else after this alarm) and stays "
                    "locked: check the gantry, then home() or unlock()"
                )
        else:
            detail = "; GRBL is locked: check the gantry, then home() or unlock()"
        raise GrblAlarmError(self.port, command, code, detail)

    def _wait_for(
        self, done: Callable[[GrblStatus], bool], timeout_s: float, command: str
    ) -> GrblStatus:
        deadline = time.monotonic() + timeout_s
        while True:
            status = self.status()
            if done(status):
                return status
            if status.state == "Alarm":
                raise DeviceError(
                    f"GRBL at {self.port} is in Alarm while waiting ({command!r}): "
                    f"{status.raw}; check the gantry, then home() or unlock()"
                )
            if time.monotonic() > deadline:
                raise GrblTimeoutError(
                    self.port, command, f"still {status.raw} after {timeout_s:.1f} s"
                )
            time.sleep(self.poll_interval_s)

    def _machine_position(self) -> Vector3:
        # WPos reports ($10=0) need a WCO, which GRBL sends only every 10-30 reports.
        for _ in range(32):
            position = self.status().machine_position(self._wco)
            if position is not None:
                return position
        raise ProtocolError(f"GRBL at {self.port} reports WPos but never its WCO offset")

    def _distance_deg(self, a: Vector3, b: Vector3) -> float:
        angles_a, angles_b = self.axes.angles(a), self.axes.angles(b)
        return math.hypot(angles_a[0] - angles_b[0], angles_a[1] - angles_b[1])

    def _accepted(self, goal: Vector3) -> bool:
        """Whether GRBL took a move whose reply was lost (it is moving, or already there)."""
        status = self.status()
        if status.state in ("Run", "Hold"):
            return True
        position = status.machine_position(self._wco)
        return position is not None and self._distance_deg(position, goal) <= (
            self.position_tolerance_deg
        )

    def _duration_s(self, start: Vector3, goal: Vector3, feed: float) -> float:
        """Expected duration of a move from GRBL's max rates ($11x) and accelerations ($12x)."""
        delta = [g - s for s, g in zip(start, goal, strict=True)]
        length = math.hypot(*delta)
        if length < 1e-9:
            return 0.0
        rate, accel = feed / 60.0, math.inf
        for axis, d in enumerate(delta):
            if abs(d) > 1e-12:
                share = abs(d) / length
                rate = min(rate, self._settings.get(110 + axis, math.inf) / 60.0 / share)
                accel = min(accel, self._settings.get(120 + axis, math.inf) / share)
        if not math.isfinite(accel) or accel <= 0 or rate <= 0:
            return length / max(rate, 1e-9)
        peak = min(rate, math.sqrt(accel * length))
        return 2 * peak / accel + (length - peak * peak / accel) / peak
