"""Over 500 lines because one driver class keeps the pinned modes and safety rules below.

GRBL 1.1 light gantry driver on ``pyserial``: light azimuth and inclination as two GRBL axes.

Degrees in, G-code only inside this module and :mod:`rig.grbl_link` (the serial link: one line
at a time, never re-sent, alarms and resets). See ``docs/grbl.md``.

What the driver pins on connect and after every reset, so the controller's own state cannot
change what a move means:

- units, distance mode and feed mode: ``G21 G90 G94``, read back with ``$G``; every move line
  names ``G21 G90 G53`` again, so a startup line (``$N0=G20``) or a stray ``G91`` cannot turn a
  3 mm move into 3 inches;
- the units of status reports: ``$13=1`` (inches) is read and converted;
- the axes' maximum rates and accelerations (``$110+``, ``$120+``), written from the config when
  they differ and read back: the controller moves as the capture plan estimated;
- refusals, before anything moves: laser mode (``$32=1``: ``M3`` would light only during
  motion, so the camera would expose in the dark) and startup lines that move an axis.

Safety rules it keeps: every line is validated (printable ASCII, no ``%``, no real-time
characters, no newline inside) before a byte is written; targets outside the configured soft
limits raise :class:`~core.errors.SafetyError` before a byte is written; moves go to machine
coordinates (``G53``), so a stray ``G92`` or work offset cannot shift them; an alarm is never
cleared implicitly (only :meth:`GrblGantry.unlock`, :meth:`GrblGantry.home` or
``unlock_on_connect=True``); a line whose reply does not come is not sent again: the gantry is
stopped; leaving the context manager (normally or by an exception) stops motion with a feed hold
and switches the light off.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Literal

from core.errors import ConfigError, DeviceError, InputError, ProtocolError, RigError, SafetyError
from rig.grbl_link import (
    GrblAlarmError,
    GrblCommandError,
    GrblLink,
    GrblResetError,
    GrblTimeoutError,
    wait_for,
)
from rig.grbl_protocol import (
    MM_PER_INCH,
    GrblStatus,
    ReplyKind,
    Vector3,
    classify,
    format_number,
    parse_modal_state,
    parse_setting,
    parse_startup_lines,
    scaled_status,
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
_INTEGER_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32})
#: The modal state every exchange assumes: millimetres, absolute, feed in units per minute.
PINNED_MODES = ("G21", "G90", "G94")
#: Lines that wait for the planner to empty before GRBL answers them (buffer synchronisation).
_SYNC_PREFIXES = ("M3", "M4", "M5", "M7", "M8", "M9", "G4", "$")
#: Relative difference under which a setting read back counts as the value written (GRBL keeps
#: floats and prints three decimals).
_SETTING_TOLERANCE = 1e-4


@dataclass(frozen=True)
class GantryAxisConfig:
    """How one rig angle maps to one GRBL axis, and how fast that axis may move.

    ``units = direction * (angle_deg - offset_deg) * units_per_deg``: ``offset_deg`` is the angle
    at machine zero (where homing puts the axis, less GRBL's pull-off), ``direction`` is +1 or
    -1, ``units_per_deg`` the GRBL units (mm) per degree. ``min_deg`` and ``max_deg`` are the
    soft limits the driver enforces before sending. ``max_rate_deg_min`` and
    ``acceleration_deg_s2``, when given, are written to the axis' ``$11x`` and ``$12x`` (in
    units) on connect.
    """

    letter: Literal["X", "Y", "Z"]
    min_deg: float
    max_deg: float
    offset_deg: float = 0.0
    direction: Literal[1, -1] = 1
    units_per_deg: float = 1.0
    max_rate_deg_min: float | None = None
    acceleration_deg_s2: float | None = None

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
        for name in ("max_rate_deg_min", "acceleration_deg_s2"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ConfigError(f"axis {self.letter}: {name} {value} must be positive")

    @property
    def index(self) -> int:
        """0, 1 or 2 for X, Y, Z: the axis' place in positions and settings ($110 + index)."""
        return _AXIS_INDEX[self.letter]

    def to_units(self, angle_deg: float) -> float:
        """GRBL machine units of a rig angle."""
        return self.direction * (angle_deg - self.offset_deg) * self.units_per_deg

    def to_deg(self, units: float) -> float:
        """Rig angle of a GRBL machine coordinate."""
        return self.offset_deg + self.direction * units / self.units_per_deg

    def settings(self) -> dict[int, float]:
        """The ``$11x``/``$12x`` values this axis asks for, in units/min and units/s^2."""
        wanted: dict[int, float] = {}
        if self.max_rate_deg_min is not None:
            wanted[110 + self.index] = self.max_rate_deg_min * self.units_per_deg
        if self.acceleration_deg_s2 is not None:
            wanted[120 + self.index] = self.acceleration_deg_s2 * self.units_per_deg
        return wanted


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
        return az.to_deg(machine[az.index]), inc.to_deg(machine[inc.index])


class GrblGantry:
    """The light gantry on a GRBL 1.1 controller.

    Parameters
    ----------
    port : serial device (``/dev/ttyUSB0``, or an emulator's pty)
    baudrate : GRBL 1.1 uses 115200
    axes : the azimuth and inclination axis mapping, soft limits, rates and accelerations
    light : ``"spindle"`` (M3 S<pwm>/M5, intensity scaled to ``$30``) or ``"coolant"`` (M8/M9,
        on/off only)
    feed_deg_min : feed of moves along the straight line in (azimuth, inclination), deg/min
    timeout_s : wait for one reply (lines that wait for motion get the motion's time more)
    home_timeout_s : wait for ``$H`` to finish
    unlock_on_connect : send ``$X`` at connect when GRBL is in alarm (off: unlocking is an
        operator's explicit decision)
    retries : re-sends of a status request whose report was lost (lines are never re-sent)
    poll_interval_s : least time between status polls while waiting (GRBL hosts poll at 5 Hz or
        less: each report costs the controller time)
    position_tolerance_deg : how far from its target a finished move may be
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
        poll_interval_s: float = 0.2,
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
        self.home_timeout_s = home_timeout_s
        self.unlock_on_connect = unlock_on_connect
        self.poll_interval_s = poll_interval_s
        self.position_tolerance_deg = position_tolerance_deg
        self.link = GrblLink(port, baudrate, timeout_s=timeout_s, status_retries=retries)
        self.startup_lines: dict[int, str] = {}
        """The controller's startup lines (``$N``), run by GRBL after every reset."""
        self._settings: dict[int, float] = {}
        self._report_scale = 1.0  # mm per reported unit: 25.4 with $13=1
        self._wco: Vector3 | None = None
        self._pinned_at = -1  # link.resets when the modal state was last pinned
        self._motion_end = 0.0  # monotonic time when the motion sent so far should be done

    @property
    def timeout_s(self) -> float:
        """Wait for one reply, seconds."""
        return self.link.timeout_s

    @property
    def messages(self) -> list[str]:
        """Push messages seen (``[MSG:...]``, alarms, banners), oldest first."""
        return self.link.messages

    @property
    def noise_lines(self) -> int:
        """Unparseable lines received and skipped (line noise)."""
        return self.link.noise_lines

    @property
    def homing_enabled(self) -> bool:
        """Whether the controller's homing cycle is enabled (``$22=1``), as last read."""
        return bool(self._settings.get(22))

    @property
    def version(self) -> str | None:
        """GRBL's version from its last banner (``"1.1h"``)."""
        return self.link.version

    # -- connection -------------------------------------------------------------------------

    def connect(self) -> None:
        """Open the port, soft-reset GRBL, and put it in a known state (see the module docs).

        Raises
        ------
        DeviceError
            The port cannot be opened, no GRBL 1.1 banner came after the reset, the controller
            refuses a setting, or it is in laser mode or has a startup line that moves.
        """
        if self.link.is_open:
            return
        self.link.open()
        try:
            self.link.soft_reset(attempts=2)
            self._check_controller()
            self._write_axis_settings()
            status = self.status()
            if status.state == "Alarm" and self.unlock_on_connect:
                self.unlock()
            elif status.state != "Alarm":
                self._pin_modes()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the port (no bytes sent; see the context manager for a safe stop)."""
        self.link.close()

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
        if not self.link.is_open:
            return
        try:
            status = self.status()
            if status.moving or status.state in ("Hold", "Door", "Sleep"):
                if status.moving:
                    self.link.write_realtime(b"!", "!")
                    self._wait_for(lambda s: not s.moving, self.timeout_s, "!")
                self.link.soft_reset()
            elif status.state != "Alarm":
                self.light_off()
        except RigError:
            try:
                self.link.write_realtime(b"\x18", "soft reset")
            except RigError:
                pass
        self._motion_end = 0.0

    # -- queries ----------------------------------------------------------------------------

    def status(self) -> GrblStatus:
        """One real-time status report (``?``), positions and feed in millimetres."""
        status = scaled_status(self.link.request_status(), self._report_scale)
        if status.wco is not None:
            self._wco = status.wco
        return status

    def settings(self) -> dict[int, float]:
        """GRBL's settings from ``$$`` (``{110: 500.0, ...}``); also cached for the driver."""
        settings: dict[int, float] = {}
        for line in self._command("$$"):
            if classify(line).kind is ReplyKind.SETTING:
                number, value = parse_setting(line)
                settings[number] = value
        if not settings:
            raise ProtocolError(f"GRBL at {self.port} answered '$$' without any setting")
        self._settings = settings
        self._report_scale = MM_PER_INCH if int(settings.get(13, 0)) & 1 else 1.0
        return dict(settings)

    def set_setting(self, number: int, value: float) -> None:
        """Write ``$number=value`` (an EEPROM write; GRBL accepts it only when Idle or Alarm)."""
        self._store_setting(number, value)
        self.settings()  # GRBL changes other settings too ($22=0 clears $20)

    def modal_state(self) -> frozenset[str]:
        """The parser's modal state from ``$G`` (``{"G0", "G54", "G17", "G21", ...}``)."""
        for line in self._command("$G"):
            if line.startswith("[GC:"):
                return parse_modal_state(line)
        raise ProtocolError(f"GRBL at {self.port} answered '$G' without a [GC:...] report")

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
        if not self.homing_enabled:
            raise DeviceError(
                f"GRBL at {self.port}: homing is disabled ($22=0); nothing was sent. Enable it "
                "with set_setting(22, 1) on a gantry with limit switches, or place the gantry by "
                "hand and unlock()"
            )
        self.link.activity = "$H"
        self._command("$H", timeout_s=self.home_timeout_s)
        self._pin_modes()
        return self.status()

    def unlock(self) -> GrblStatus:
        """Clear an alarm lock with ``$X``: the operator's explicit decision that it is safe."""
        self._command("$X")
        self._pin_modes()
        return self.status()

    def move_to_deg(
        self, azimuth_deg: float, inclination_deg: float, wait: bool = True
    ) -> GrblStatus | None:
        """Move the light to (azimuth, inclination) with an absolute ``G21 G90 G53 G1`` move.

        Returns the Idle status after arrival when ``wait``, else None right after GRBL
        accepted the move.

        Raises
        ------
        SafetyError
            A target outside the soft limits (or not finite); nothing was sent.
        GrblCommandError, GrblAlarmError, GrblTimeoutError
            GRBL refused the move, raised an alarm, or did not arrive in time (a move whose
            reply is lost is not sent again: the gantry is stopped).
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
        self._ensure_pinned()
        start = self._machine_position()
        target = [start[0], start[1], start[2]]
        target[az.index] = az.to_units(azimuth_deg)
        target[inc.index] = inc.to_units(inclination_deg)
        start_deg = self.axes.angles(start)
        dist_deg = math.hypot(azimuth_deg - start_deg[0], inclination_deg - start_deg[1])
        dist_units = math.dist(start, target)
        # GRBL's F is along the path in units; scale it so the path runs at feed_deg_min.
        ratio = (
            dist_units / dist_deg if dist_deg > 1e-9 else max(az.units_per_deg, inc.units_per_deg)
        )
        feed = self.feed_deg_min * ratio
        line = (
            f"G21 G90 G53 G1 {az.letter}{format_number(target[az.index])} "
            f"{inc.letter}{format_number(target[inc.index])} F{format_number(feed)}"
        )
        goal = (target[0], target[1], target[2])
        duration = self._duration_s(start, goal, feed)
        self.link.activity = line
        self._command(line)
        self._motion_end = max(time.monotonic(), self._motion_end) + duration
        if not wait:
            return None
        status = self.wait_until_idle(self.timeout_s + 2.0 * duration)
        reached = status.machine_position(self._wco)
        if reached is None or self._distance_deg(reached, goal) > self.position_tolerance_deg:
            raise DeviceError(
                f"GRBL at {self.port} went Idle at {reached} instead of {goal} after {line!r}"
            )
        return status

    def wait_until_idle(self, timeout_s: float | None = None) -> GrblStatus:
        """Wait until GRBL is Idle: asleep until the motion should end, then polling.

        Raises
        ------
        GrblTimeoutError
            Not Idle within ``timeout_s`` (a feed hold counts as not Idle).
        DeviceError
            GRBL is in Alarm.
        """
        limit = self.timeout_s if timeout_s is None else timeout_s
        remaining = max(0.0, self._motion_end - time.monotonic())
        return self._wait_for(
            lambda s: s.state == "Idle", limit, "wait for Idle", first_poll_s=remaining
        )

    def feed_hold(self) -> GrblStatus:
        """Feed hold ``!``: decelerate to a stop; GRBL keeps the rest of the move."""
        self.link.write_realtime(b"!", "!")
        return self.status()

    def resume(self) -> GrblStatus:
        """Cycle start ``~`` after a feed hold (waits for Hold:0, as GRBL ignores it before)."""
        self._wait_for(lambda s: not (s.state == "Hold" and s.substate == 1), self.timeout_s, "~")
        self.link.write_realtime(b"~", "~")
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
            self._command("M8" if intensity else "M9")
            return
        max_speed = self._settings.get(30, 1000.0)
        self._command(f"M3 S{format_number(intensity * max_speed)}")

    def light_off(self) -> None:
        """Switch the light off (``M5`` or ``M9``)."""
        self._command("M5" if self.light_mode == "spindle" else "M9")

    # -- internals --------------------------------------------------------------------------

    def _command(self, command: str, *, timeout_s: float | None = None) -> list[str]:
        """Send one line (once) and wait for its ``ok``, allowing for motion it waits behind."""
        timeout = self.timeout_s if timeout_s is None else timeout_s
        if command.startswith(_SYNC_PREFIXES):
            # GRBL answers these only once the planner is empty.
            timeout += max(0.0, self._motion_end - time.monotonic())
        try:
            return self.link.send_line(command, timeout)
        except GrblCommandError as refused:
            if refused.code == 9:
                raise GrblCommandError(self.port, command, 9, self._alarm_advice()) from refused
            raise
        except (GrblTimeoutError, GrblResetError, GrblAlarmError):
            self._motion_end = 0.0  # whatever was queued is gone
            raise

    def _alarm_advice(self) -> str:
        if self.homing_enabled:
            return (
                "; GRBL is locked in alarm and needs homing ($22=1): home() (config: "
                "gantry.homing = true), or unlock() after placing the gantry by hand"
            )
        return "; GRBL is locked in alarm: check the gantry, then unlock() (or home())"

    def _store_setting(self, number: int, value: float) -> None:
        if not (isinstance(number, int) and 0 <= number <= 255):
            raise InputError(f"GRBL at {self.port}: setting number {number!r} is not 0..255")
        if not math.isfinite(value):
            raise InputError(f"GRBL at {self.port}: setting ${number} value {value} not finite")
        text = str(int(value)) if number in _INTEGER_SETTINGS else format_number(value)
        self._command(f"${number}={text}")

    def _check_controller(self) -> None:
        """Read settings and startup lines; refuse a controller this driver cannot drive safely."""
        settings = self.settings()
        if int(settings.get(32, 0)):
            raise DeviceError(
                f"GRBL at {self.port} is in laser mode ($32=1): M3 switches the spindle output "
                "on only while the axes move, so the light would be dark while the camera "
                "exposes. Switch laser mode off ('$32=0' in a GRBL terminal) and connect again"
            )
        lines = self._command("$N")
        self.startup_lines = parse_startup_lines(lines)
        for number, line in self.startup_lines.items():
            words = line.upper().replace(" ", "")
            if any(f"{axis}" in words for axis in "XYZ") and any(c.isdigit() for c in words):
                raise DeviceError(
                    f"GRBL at {self.port} runs startup line $N{number}={line} after every "
                    f"reset, which names an axis: the gantry would move on its own. Clear it "
                    f"('$N{number}=' in a GRBL terminal) and connect again"
                )

    def _write_axis_settings(self) -> None:
        """Write the axes' rates and accelerations where they differ, then check they hold."""
        wanted = {**self.axes.azimuth.settings(), **self.axes.inclination.settings()}
        differ = [n for n, v in wanted.items() if not _close(self._settings.get(n), v)]
        if not differ:
            return
        for number in differ:
            # One at a time, each awaiting its ok: GRBL drops serial data during EEPROM writes.
            self._store_setting(number, wanted[number])
        held = self.settings()
        wrong = [n for n in differ if not _close(held.get(n), wanted[n])]
        if wrong:
            listed = ", ".join(f"${n}={held.get(n)} (wanted {wanted[n]:g})" for n in wrong)
            raise DeviceError(
                f"GRBL at {self.port} did not keep the gantry's rates and accelerations: "
                f"{listed}; check the controller's EEPROM"
            )

    def _pin_modes(self) -> None:
        """Put the parser in ``G21 G90 G94`` and read it back (``$G``)."""
        self._command(" ".join(PINNED_MODES))
        modes = self.modal_state()
        missing = [m for m in PINNED_MODES if m not in modes]
        if missing:
            raise DeviceError(
                f"GRBL at {self.port} did not take {' '.join(missing)} (its modal state is "
                f"{' '.join(sorted(modes))}); refusing to move in units it has not confirmed"
            )
        self._pinned_at = self.link.resets

    def _ensure_pinned(self) -> None:
        """Re-pin the modal state after any reset (a startup line may have changed it)."""
        if self._pinned_at != self.link.resets:
            self._pin_modes()

    def _wait_for(
        self, done: Callable[[GrblStatus], bool], timeout_s: float, command: str,
        *, first_poll_s: float = 0.0,
    ) -> GrblStatus:  # fmt: skip
        return wait_for(
            self.link, done, self.status, timeout_s, command,
            first_poll_s=first_poll_s, poll_interval_s=self.poll_interval_s,
        )  # fmt: skip

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


def _close(have: float | None, want: float) -> bool:
    return have is not None and abs(have - want) <= _SETTING_TOLERANCE * max(abs(want), 1.0)
