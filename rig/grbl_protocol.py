"""GRBL 1.1 wire format: reply classification, status reports, code tables, command validation.

Pure functions and tables only (no I/O), shared by the driver in :mod:`rig.grbl`. The tables
are GRBL 1.1's own (``doc/csv/error_codes_en_US.csv`` and ``alarm_codes_en_US.csv`` of the GRBL
repository); the status report grammar is the one of GRBL's ``doc/markdown/interface.md``::

    <State[:sub]|MPos:x,y,z or WPos:x,y,z|Bf:blocks,bytes|Ln:n|FS:feed,speed or F:feed|Pn:XYZPDHRS
     |WCO:x,y,z|Ov:feed,rapid,spindle|A:SCFM>

The first two fields are always present; every other field may be missing or come in any
order (WCO and Ov only every 10-30 reports, Bf only with ``$10`` bit 1, Pn only when a pin is
triggered, A only with Ov and only when the spindle or coolant is on).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from enum import Enum

from core.errors import InputError

__all__ = [
    "ALARM_CODES",
    "CHECK_LIMITS_MESSAGE",
    "CRITICAL_ALARMS",
    "CRITICAL_ALARM_MESSAGE",
    "ERROR_CODES",
    "MACHINE_STATES",
    "MM_PER_INCH",
    "SELF_RESETTING_ALARMS",
    "GrblStatus",
    "Reply",
    "ReplyKind",
    "alarm_meaning",
    "banner_version",
    "classify",
    "error_meaning",
    "format_number",
    "parse_modal_state",
    "parse_setting",
    "parse_startup_lines",
    "parse_status",
    "scaled_status",
    "validate_command",
]

ERROR_CODES: dict[int, str] = {
    1: "Expected command letter: G-code words consist of a letter and a value; letter was not "
    "found",
    2: "Bad number format: missing the expected G-code word value or numeric value format is "
    "not valid",
    3: "Invalid statement: Grbl '$' system command was not recognized or supported",
    4: "Value < 0: negative value received for an expected positive value",
    5: "Setting disabled: homing cycle is not enabled via settings ($22)",
    6: "Value < 3 usec: minimum step pulse time must be greater than 3 usec",
    7: "EEPROM read fail: an EEPROM read failed; auto-restoring affected EEPROM to default values",
    8: "Not idle: Grbl '$' command cannot be used unless Grbl is IDLE",
    9: "G-code lock: G-code commands are locked out during alarm or jog state",
    10: "Homing not enabled: soft limits cannot be enabled without homing also enabled",
    11: "Line overflow: max characters per line exceeded; the line was not executed",
    12: "Step rate > 30kHz: Grbl '$' setting value causes the step rate to exceed the maximum "
    "supported",
    13: "Check door: safety door detected as opened and door state initiated",
    14: "Line length exceeded: build info or startup line exceeded EEPROM line length limit",
    15: "Travel exceeded: jog target exceeds machine travel; jog command ignored",
    16: "Invalid jog command: jog command has no '=' or contains prohibited g-code",
    17: "Setting disabled: laser mode requires PWM output",
    20: "Unsupported command: unsupported or invalid g-code command found in block",
    21: "Modal group violation: more than one g-code command from same modal group found in block",
    22: "Undefined feed rate: feed rate has not yet been set or is undefined",
    23: "G-code command in block requires an integer value",
    24: "More than one g-code command that requires axis words found in block",
    25: "Repeated g-code word found in block",
    26: "No axis words found in block for g-code command or current modal state which requires "
    "them",
    27: "Line number value is invalid",
    28: "G-code command is missing a required value word",
    29: "G59.x work coordinate systems are not supported",
    30: "G53 only allowed with G0 and G1 motion modes",
    31: "Axis words found in block when no command or current modal state uses them",
    32: "G2 and G3 arcs require at least one in-plane axis word",
    33: "Motion command target is invalid",
    34: "Arc radius value is invalid",
    35: "G2 and G3 arcs require at least one in-plane offset word",
    36: "Unused value words found in block",
    37: "G43.1 dynamic tool length offset is not assigned to configured tool length axis",
    38: "Tool number greater than max supported value",
}
"""GRBL 1.1 ``error:N`` codes and their meanings (codes 18 and 19 are unassigned)."""

ALARM_CODES: dict[int, str] = {
    1: "Hard limit triggered; machine position is likely lost due to sudden halt; re-homing is "
    "highly recommended",
    2: "Soft limit: G-code motion target exceeds machine travel; machine position retained; "
    "alarm may be safely unlocked",
    3: "Reset while in motion; machine position is likely lost due to sudden halt; re-homing is "
    "highly recommended",
    4: "Probe fail: the probe is not in the expected initial state before starting probe cycle",
    5: "Probe fail: probe did not contact the workpiece within the programmed travel",
    6: "Homing fail: the active homing cycle was reset",
    7: "Homing fail: safety door was opened during homing cycle",
    8: "Homing fail: pull-off travel failed to clear limit switch; try increasing pull-off "
    "setting or check wiring",
    9: "Homing fail: could not find limit switch within search distances; try increasing max "
    "travel, decreasing pull-off distance, or check wiring",
}
"""GRBL 1.1 ``ALARM:N`` codes and their meanings."""

CRITICAL_ALARM_MESSAGE = "[MSG:Reset to continue]"
"""Sent some time after ALARM:1 or ALARM:2 (about 500 ms on GRBL 1.1h); a soft reset that
arrives before it is discarded, and GRBL ignores everything but a reset until one comes."""

CHECK_LIMITS_MESSAGE = "[MSG:Check Limits]"
"""Sent after the banner of a reset while a limit switch is still pressed (GRBL stays in Alarm)."""

#: Alarms after which GRBL resets itself (a failed homing cycle): its banner follows.
SELF_RESETTING_ALARMS = frozenset({6, 7, 8, 9})
#: Alarms after which GRBL serves nothing but a soft reset.
CRITICAL_ALARMS = frozenset({1, 2})

#: Inches to millimetres: status reports are in inches with ``$13=1``.
MM_PER_INCH = 25.4

MACHINE_STATES = ("Idle", "Run", "Hold", "Jog", "Alarm", "Door", "Check", "Home", "Sleep")

# Characters GRBL picks out of the stream as real-time commands wherever they appear, so inside
# a line they would act (status, feed hold, cycle start) instead of being part of the command.
_REALTIME_IN_LINE = frozenset("?!~")
_MAX_LINE_CHARS = 79  # GRBL's LINE_BUFFER_SIZE is 80 including the terminating zero.

_BANNER = re.compile(r"^Grbl (\d+\.\d+[a-z]?) \['\$' for help\]$")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)"
_SETTING = re.compile(rf"^\$(\d+)=({_NUMBER})$")
_CODE = re.compile(r"^(error|ALARM):(\d+)$")
_STORED_LINE = re.compile(r"^\$N\d=")


def error_meaning(code: int) -> str:
    """The meaning in words of GRBL ``error:code``."""
    return ERROR_CODES.get(code, f"unknown GRBL error code {code}")


def alarm_meaning(code: int) -> str:
    """The meaning in words of GRBL ``ALARM:code``."""
    return ALARM_CODES.get(code, f"unknown GRBL alarm code {code}")


class ReplyKind(Enum):
    """What one line received from GRBL is."""

    OK = "ok"
    ERROR = "error"
    ALARM = "alarm"
    STATUS = "status"
    BANNER = "banner"
    MESSAGE = "message"  # [MSG:...]
    FEEDBACK = "feedback"  # [GC:...], [VER:...], [G54:...] and other bracketed data
    SETTING = "setting"  # $N=value
    STARTUP = "startup"  # >line:ok, a startup line's echo after a reset
    STORED_LINE = "stored line"  # $N0=line, a line of the $N listing
    EMPTY = "empty"
    UNKNOWN = "unknown"


@dataclass(frozen=True)
class Reply:
    """One classified line: its kind, the code of error/alarm lines, the text."""

    kind: ReplyKind
    text: str
    code: int | None = None


def classify(line: str) -> Reply:
    """Classify one received line (without its line ending)."""
    text = line.strip()
    if not text:
        return Reply(ReplyKind.EMPTY, text)
    if text == "ok":
        return Reply(ReplyKind.OK, text)
    coded = _CODE.match(text)
    if coded:
        kind = ReplyKind.ERROR if coded.group(1) == "error" else ReplyKind.ALARM
        return Reply(kind, text, int(coded.group(2)))
    if text.startswith("<") and text.endswith(">"):
        return Reply(ReplyKind.STATUS, text)
    if _BANNER.match(text):
        return Reply(ReplyKind.BANNER, text)
    if text.startswith("[MSG:") and text.endswith("]"):
        return Reply(ReplyKind.MESSAGE, text)
    if text.startswith("[") and text.endswith("]") and text[1:2].isalpha():
        return Reply(ReplyKind.FEEDBACK, text)
    if _SETTING.match(text):
        return Reply(ReplyKind.SETTING, text)
    if _STORED_LINE.match(text):
        return Reply(ReplyKind.STORED_LINE, text)
    if text.startswith(">") and (text.endswith(":ok") or ":error:" in text):
        return Reply(ReplyKind.STARTUP, text)
    return Reply(ReplyKind.UNKNOWN, text)


def banner_version(line: str) -> str | None:
    """The version of a welcome banner (``"1.1h"``), or None when the line is not one."""
    match = _BANNER.match(line.strip())
    return match.group(1) if match else None


def parse_setting(line: str) -> tuple[int, float]:
    """Parse a ``$N=value`` line of a ``$$`` listing into ``(N, value)``.

    Raises
    ------
    ValueError
        The line is not a setting line.
    """
    match = _SETTING.match(line.strip())
    if not match:
        raise ValueError(f"not a GRBL setting line: {line!r}")
    return int(match.group(1)), float(match.group(2))


Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class GrblStatus:
    """One real-time status report, parsed.

    Attributes
    ----------
    state : one of :data:`MACHINE_STATES`
    substate : the number after ``Hold:`` or ``Door:``, else None
    mpos, wpos : machine or work position in GRBL units (one of them; GRBL sends one)
    wco : work coordinate offset, when this report carried it (``WPos = MPos - WCO``)
    feed : current feed rate in units/min; ``spindle`` the spindle speed (None with ``F:``)
    overrides : (feed, rapid, spindle) in percent, when reported
    accessories : letters of ``A:`` (S/C spindle, F flood, M mist); "" when Ov came without A
    buffer : (free planner blocks, free RX bytes) from ``Bf:``
    line_number : ``Ln:``; pins : letters of ``Pn:`` ("" when absent)
    raw : the report as received
    """

    state: str
    substate: int | None = None
    mpos: Vector3 | None = None
    wpos: Vector3 | None = None
    wco: Vector3 | None = None
    feed: float | None = None
    spindle: float | None = None
    overrides: tuple[int, int, int] | None = None
    accessories: str | None = None
    buffer: tuple[int, int] | None = None
    line_number: int | None = None
    pins: str = ""
    raw: str = ""

    @property
    def moving(self) -> bool:
        """True while motion may be under way (running, jogging, homing, decelerating)."""
        return self.state in ("Run", "Jog", "Home") or (self.state == "Hold" and self.substate == 1)

    def machine_position(self, wco: Vector3 | None = None) -> Vector3 | None:
        """Machine position: MPos, or WPos + WCO (this report's WCO, else ``wco``)."""
        if self.mpos is not None:
            return self.mpos
        offset = self.wco if self.wco is not None else wco
        if self.wpos is None or offset is None:
            return None
        return (
            self.wpos[0] + offset[0],
            self.wpos[1] + offset[1],
            self.wpos[2] + offset[2],
        )


def _floats(value: str, field: str, count: int | None = None) -> tuple[float, ...]:
    parts = value.split(",")
    if count is not None and len(parts) < count:
        raise ValueError(f"{field} has {len(parts)} values, expected {count}")
    numbers = tuple(float(part) for part in parts)
    if not all(math.isfinite(n) for n in numbers):
        raise ValueError(f"{field} has a non-finite value")
    return numbers


def _vector(value: str, field: str) -> Vector3:
    numbers = _floats(value, field, 3)
    return (numbers[0], numbers[1], numbers[2])


def parse_status(line: str) -> GrblStatus:
    """Parse a ``<...>`` status report.

    Raises
    ------
    ValueError
        The line is not a well-formed GRBL 1.1 status report (the message says why).
    """
    text = line.strip()
    if not (text.startswith("<") and text.endswith(">")):
        raise ValueError(f"a status report is enclosed in <>: {line!r}")
    fields = text[1:-1].split("|")
    state, _, sub = fields[0].partition(":")
    if state not in MACHINE_STATES:
        raise ValueError(f"unknown machine state {fields[0]!r} in {line!r}")
    values: dict[str, object] = {"state": state, "raw": text}
    try:
        if sub:
            values["substate"] = int(sub)
        for field in fields[1:]:
            name, sep, value = field.partition(":")
            if not sep:
                raise ValueError(f"field {field!r} has no ':'")
            if name in ("MPos", "WPos", "WCO"):
                values[name.lower()] = _vector(value, name)
            elif name == "FS":
                feed, speed = _floats(value, name, 2)[:2]
                values["feed"], values["spindle"] = feed, speed
            elif name == "F":
                values["feed"] = _floats(value, name, 1)[0]
            elif name == "Ov":
                ov = _floats(value, name, 3)
                values["overrides"] = (int(ov[0]), int(ov[1]), int(ov[2]))
            elif name == "Bf":
                bf = _floats(value, name, 2)
                values["buffer"] = (int(bf[0]), int(bf[1]))
            elif name == "Ln":
                values["line_number"] = int(value)
            elif name == "Pn":
                values["pins"] = value
            elif name == "A":
                values["accessories"] = value
            # Unknown fields are skipped: the interface document says to expect new ones.
    except ValueError as exc:
        raise ValueError(f"malformed status report {line!r}: {exc}") from None
    if "mpos" not in values and "wpos" not in values:
        raise ValueError(f"status report without MPos or WPos: {line!r}")
    if "overrides" in values and "accessories" not in values:
        values["accessories"] = ""  # Ov without A means spindle and coolant are off.
    return GrblStatus(**values)  # type: ignore[arg-type]


def scaled_status(status: GrblStatus, factor: float) -> GrblStatus:
    """The report with positions, offsets and feed multiplied by ``factor`` (inches to mm)."""
    if factor == 1.0:
        return status

    def scale(vector: Vector3 | None) -> Vector3 | None:
        if vector is None:
            return None
        return (vector[0] * factor, vector[1] * factor, vector[2] * factor)

    return replace(
        status,
        mpos=scale(status.mpos),
        wpos=scale(status.wpos),
        wco=scale(status.wco),
        feed=None if status.feed is None else status.feed * factor,
    )


def parse_modal_state(line: str) -> frozenset[str]:
    """The words of a ``$G`` report (``[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]``).

    Raises
    ------
    ValueError
        The line is not a ``[GC:...]`` report.
    """
    text = line.strip()
    if not (text.startswith("[GC:") and text.endswith("]")):
        raise ValueError(f"not a GRBL modal state report: {line!r}")
    return frozenset(text[4:-1].split())


def parse_startup_lines(lines: list[str]) -> dict[int, str]:
    """The startup lines of a ``$N`` listing (``$N0=G20``, ``$N1=``), by number; empty kept."""
    found: dict[int, str] = {}
    for line in lines:
        text = line.strip()
        number, sep, value = text[2:].partition("=")
        if text.startswith("$N") and sep and number.isdigit():
            found[int(number)] = value
    return found


def format_number(value: float) -> str:
    """A G-code number: fixed point, three decimals, no exponent, no negative zero."""
    text = f"{value:.3f}"
    return "0.000" if text == "-0.000" else text


def validate_command(line: str, *, port: str = "") -> str:
    """Check a command line before it is written and return it unchanged.

    A line must be printable ASCII (no control characters, no newline or carriage return
    inside: the driver adds the one terminator), contain no ``%`` (program delimiter, not a
    GRBL command), none of GRBL's real-time characters ``? ! ~`` (GRBL would act on them
    mid-line), and fit GRBL's 80-byte line buffer.

    Raises
    ------
    InputError
        Naming the port, the command and the offending character; nothing has been sent.
    """
    where = f"GRBL at {port}: " if port else ""
    if not line.strip():
        raise InputError(f"{where}refusing to send an empty command {line!r}")
    for index, char in enumerate(line):
        code = ord(char)
        if code > 0x7E:
            problem = f"non-ASCII character {char!r} (U+{code:04X})"
        elif code < 0x20:
            problem = f"control character {char!r}" + (" (newline)" if char in "\r\n" else "")
        elif char == "%":
            problem = "'%' (program delimiter)"
        elif char in _REALTIME_IN_LINE:
            problem = f"real-time character {char!r}"
        else:
            continue
        raise InputError(
            f"{where}refusing to send {line!r}: {problem} at position {index}; nothing was sent"
        )
    if len(line) > _MAX_LINE_CHARS:
        raise InputError(
            f"{where}refusing to send {line!r}: {len(line)} characters, GRBL accepts at most "
            f"{_MAX_LINE_CHARS} per line; nothing was sent"
        )
    return line
