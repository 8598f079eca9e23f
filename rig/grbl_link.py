"""The serial link to a GRBL 1.1 controller: one line at a time, its reply, resets and alarms.

What a GRBL host must do, and this link does (``docs/grbl.md``, "Host behaviour"):

- send-response streaming: one line in flight, its ``ok``/``error:N`` awaited before the next,
  so replies are never taken for another line's; a line is **never sent again**: when its reply
  does not come, its outcome is unknown, and the link stops the machine (feed hold, wait for it
  to settle, soft reset: GRBL drops whatever it had buffered) before raising, so nothing late
  can be mistaken for the reply to a later line;
- real-time bytes (``?``, ``!``, ``~``, 0x18) go outside the line stream, at any time;
- after ``ALARM:1``/``ALARM:2`` GRBL discards resets until it prints ``[MSG:Reset to
  continue]`` (about 500 ms later on 1.1h): the link waits for that message (bounded) before
  it resets; after a failed homing cycle (``ALARM:6..9``) GRBL resets itself, and the link
  takes the banner that follows as part of the alarm, not as an unexpected reset;
- a bounded wait for the banner after every reset, and a count of resets (:attr:`resets`) so
  the driver re-pins its modal state after any of them, expected or not.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import serial

from core.errors import DeviceError, DeviceFault, ProtocolError, RigError
from rig.grbl_protocol import (
    CRITICAL_ALARM_MESSAGE,
    CRITICAL_ALARMS,
    SELF_RESETTING_ALARMS,
    GrblStatus,
    Reply,
    ReplyKind,
    alarm_meaning,
    banner_version,
    classify,
    error_meaning,
    parse_status,
    validate_command,
)

__all__ = [
    "GrblAlarmError",
    "GrblCommandError",
    "GrblLink",
    "GrblResetError",
    "GrblTimeoutError",
]

#: Unparseable lines tolerated in one exchange before the link is called broken.
MAX_NOISE_LINES = 50
#: Longest wait for each step of a stop after a lost reply (the link is slow or lossy then).
RECOVERY_S = 2.0


class GrblCommandError(DeviceError):
    """GRBL refused a command with ``error:N``; nothing of the line was executed."""

    def __init__(self, port: str, command: str, code: int, hint: str = "") -> None:
        self.port, self.command, self.code = port, command, code
        self.meaning = error_meaning(code)
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


class GrblResetError(DeviceError):
    """GRBL reset while a reply was awaited (its banner came): queued motion and light are lost."""


class GrblLink:
    """One serial connection to GRBL 1.1, line by line.

    Parameters
    ----------
    port, baudrate : the serial device
    timeout_s : wait for one reply (the caller lengthens it for lines that wait for motion)
    status_retries : re-sends of a status request ``?`` whose report was lost (a real-time
        byte with an unambiguous answer, so asking again is safe, unlike a line)
    alarm_message_timeout_s : longest wait for ``[MSG:Reset to continue]`` after a critical alarm
    """

    def __init__(
        self,
        port: str,
        baudrate: int,
        *,
        timeout_s: float = 2.0,
        status_retries: int = 2,
        alarm_message_timeout_s: float = 2.0,
    ) -> None:
        self.port = port
        self.baudrate = baudrate
        self.timeout_s = timeout_s
        self.status_retries = status_retries
        self.alarm_message_timeout_s = alarm_message_timeout_s
        self.messages: list[str] = []
        """Push messages (``[MSG:...]``, alarms, banners, startup-line echoes), oldest first."""
        self.noise_lines = 0
        """Unparseable lines received and skipped (line noise)."""
        self.version: str | None = None
        self.resets = 0
        """Banners seen: the driver re-pins its modal state when this changes."""
        self.last_status: GrblStatus | None = None
        self.activity = ""
        """The motion command under way, to name it when an alarm comes during a poll."""
        self._serial: Any = None
        self._rx = bytearray()

    # -- the port ---------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._serial is not None

    def open(self) -> None:
        """Open the port and drop whatever was pending (a power-up banner, a half line)."""
        try:
            self._serial = serial.Serial(self.port, self.baudrate, timeout=0.01, write_timeout=2)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"cannot open GRBL port {self.port}: {exc}") from exc
        deadline = time.monotonic() + 0.02
        while self._read_line(deadline) is not None:
            pass
        self._rx.clear()

    def close(self) -> None:
        """Close the port (no bytes sent)."""
        if self._serial is not None:
            try:
                self._serial.close()
            finally:
                self._serial = None
                self._rx.clear()

    def write_realtime(self, byte: bytes, name: str) -> None:
        """Send a real-time command (``?``, ``!``, ``~``, 0x18): GRBL acts on it at once."""
        self._write(byte, name)

    # -- lines ------------------------------------------------------------------------------

    def send_line(self, command: str, timeout_s: float | None = None) -> list[str]:
        """Send one line and return what came before its ``ok`` (``$$`` lines, ``[GC:...]``).

        Raises
        ------
        GrblCommandError
            GRBL answered ``error:N``.
        GrblAlarmError
            An alarm came instead of the reply.
        GrblTimeoutError
            No reply in time: the line's outcome is unknown, so it is not sent again; the
            machine was stopped (feed hold, soft reset) before this was raised.
        """
        validate_command(command, port=self.port)
        self._write(command.encode("ascii") + b"\n", command)
        limit = self.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + limit
        payload: list[str] = []
        while (reply := self.next_reply(deadline, command)) is not None:
            if reply.kind is ReplyKind.OK:
                return payload
            if reply.kind is ReplyKind.ERROR and reply.code is not None:
                raise GrblCommandError(self.port, command, reply.code)
            if reply.kind is not ReplyKind.STATUS:
                payload.append(reply.text)
        stopped = self.stop_after_unknown_outcome()
        raise GrblTimeoutError(
            self.port,
            command,
            f"no reply within {limit:.3g} s; the line's outcome is unknown, so it was not sent "
            f"again: {stopped}",
        )

    def request_status(self) -> GrblStatus:
        """One real-time status report (``?``) as GRBL sends it (units as ``$13`` says)."""
        for _ in range(self.status_retries + 1):
            self._write(b"?", "?")
            deadline = time.monotonic() + self.timeout_s
            while (reply := self.next_reply(deadline, "?")) is not None:
                if reply.kind is ReplyKind.STATUS and self.last_status is not None:
                    return self.last_status
        raise GrblTimeoutError(
            self.port,
            "?",
            f"no status report in {self.status_retries + 1} tries of {self.timeout_s} s",
        )

    def drain(self, quiet_s: float) -> None:
        """Read and drop replies until the line is quiet for ``quiet_s``; alarms as usual."""
        while self.next_reply(time.monotonic() + quiet_s, "drain") is not None:
            pass

    def next_reply(self, deadline: float, command: str) -> Reply | None:
        """The next reply that concerns the caller; pushes, alarms and noise handled here."""
        noise = 0
        while (line := self._read_line(deadline)) is not None:
            reply = classify(line)
            if reply.kind is ReplyKind.STATUS:
                try:
                    self.last_status = parse_status(line)
                except ValueError:
                    reply = Reply(ReplyKind.UNKNOWN, line)
                else:
                    return reply
            if reply.kind is ReplyKind.ALARM and reply.code is not None:
                self._on_alarm(reply.code, command)
            if reply.kind is ReplyKind.BANNER:
                self._take_banner(line)
                raise GrblResetError(
                    f"GRBL at {self.port} reset unexpectedly while waiting for the reply to "
                    f"{command!r} (banner {line!r}); queued motion and the light state are lost"
                )
            if reply.kind in (ReplyKind.MESSAGE, ReplyKind.STARTUP):
                self.messages.append(line)
            elif reply.kind is ReplyKind.UNKNOWN:
                noise += 1
                self.noise_lines += 1
                if noise > MAX_NOISE_LINES:
                    raise ProtocolError(
                        f"GRBL at {self.port}: more than {MAX_NOISE_LINES} unreadable lines "
                        f"while waiting for the reply to {command!r} (last {line!r})"
                    )
            elif reply.kind is not ReplyKind.EMPTY:
                return reply
        return None

    # -- resets and stops -------------------------------------------------------------------

    def soft_reset(self, attempts: int = 1) -> None:
        """Send 0x18 and wait (bounded) for the ``Grbl 1.1x`` banner and what follows it.

        Raises
        ------
        DeviceError
            No banner in ``attempts`` tries of ``timeout_s``, or not GRBL 1.1.
        """
        for _ in range(attempts):
            self._write(b"\x18", "soft reset")
            if self._await_banner(time.monotonic() + self.timeout_s):
                return
        raise DeviceError(
            f"no GRBL banner from {self.port} within {self.timeout_s} s after a soft reset "
            f"({attempts} tries): is it a GRBL 1.1 controller, at {self.baudrate} baud?"
        )

    def stop_after_unknown_outcome(self) -> str:
        """Halt the axes after a line whose outcome is unknown; returns what was done, in words.

        Feed hold first (a reset during motion loses the position), then, once GRBL has come
        to rest, a soft reset: it drops every buffered line, so no late reply can follow. The
        link may be slow right now (that is why the reply did not come), so this waits up to
        :data:`RECOVERY_S` for each step rather than one reply's timeout.
        """
        try:
            self._write(b"!", "!")
            deadline = time.monotonic() + max(RECOVERY_S, self.timeout_s)
            while time.monotonic() < deadline:
                try:
                    status = self.request_status()
                except GrblTimeoutError:
                    continue
                if not status.moving:
                    break
                time.sleep(0.05)
            for _ in range(2):
                self._write(b"\x18", "soft reset")
                if self._await_banner(time.monotonic() + max(RECOVERY_S, self.timeout_s)):
                    break
            else:
                raise DeviceError(f"no GRBL banner from {self.port} after the stop's soft reset")
        except RigError as error:
            return f"stopping the gantry failed too ({error}); check it before going on"
        return "the gantry was stopped (feed hold, then soft reset) and is ready again"

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

    def _take_banner(self, line: str) -> None:
        version = banner_version(line)
        self.messages.append(line)
        if version is None or not version.startswith("1.1"):
            raise DeviceError(f"{self.port} answers as GRBL {version}; this driver speaks 1.1")
        self.version = version
        self.resets += 1
        self.last_status = None

    def _await_banner(self, deadline: float) -> bool:
        """Read up to a banner and the pushes right after it; False when none came in time."""
        while (line := self._read_line(deadline)) is not None:
            kind = classify(line).kind
            if kind is not ReplyKind.BANNER:
                if kind in (ReplyKind.ALARM, ReplyKind.MESSAGE, ReplyKind.STARTUP):
                    self.messages.append(line)
                continue
            self._take_banner(line)
            # After the banner come the lock message, the startup lines' echoes, and (from a
            # controller still booting when it got the reset) a second banner: take them here.
            while (more := self._read_line(time.monotonic() + 0.05)) is not None:
                if classify(more).kind is ReplyKind.BANNER:
                    self._take_banner(more)
                elif classify(more).kind in (ReplyKind.MESSAGE, ReplyKind.STARTUP):
                    self.messages.append(more)
            return True
        return False

    def _await_message(self, message: str, deadline: float) -> bool:
        while (line := self._read_line(deadline)) is not None:
            if line.strip() == message:
                self.messages.append(line)
                return True
        return False

    def _on_alarm(self, code: int, command: str) -> None:
        self.messages.append(f"ALARM:{code}")
        if command in ("?", "drain", "wait for Idle") and self.activity:
            command = self.activity  # the alarm belongs to the motion, not to the poll
        detail = "; GRBL is locked: check the gantry, then home() or unlock()"
        if code in CRITICAL_ALARMS:
            # GRBL discards a reset until it has said it will take one; then it answers again
            # (still locked in Alarm, so this clears nothing).
            told = self._await_message(
                CRITICAL_ALARM_MESSAGE, time.monotonic() + self.alarm_message_timeout_s
            )
            try:
                self.soft_reset(attempts=2)
            except DeviceError:
                detail = "; GRBL gave no banner after the soft reset that follows this alarm"
            else:
                waited = "" if told else " (it never said 'Reset to continue')"
                detail = (
                    f"; GRBL was soft-reset{waited} and stays locked: check the gantry, then "
                    "home() or unlock()"
                )
        elif code in SELF_RESETTING_ALARMS:
            # A failed homing cycle: GRBL resets itself (after the same pause as a critical
            # alarm), and its banner is part of this alarm.
            wait = self.alarm_message_timeout_s + self.timeout_s
            if not self._await_banner(time.monotonic() + wait):
                detail = "; GRBL did not reset itself as it does after a homing failure"
        raise GrblAlarmError(self.port, command, code, detail)


def wait_for(
    link: GrblLink,
    done: Callable[[GrblStatus], bool],
    status: Callable[[], GrblStatus],
    timeout_s: float,
    command: str,
    *,
    first_poll_s: float = 0.0,
    poll_interval_s: float = 0.2,
) -> GrblStatus:
    """Poll status until ``done``: first after ``first_poll_s``, then at most every interval.

    Raises
    ------
    GrblTimeoutError
        Not done within ``timeout_s``.
    DeviceError
        GRBL is in Alarm.
    """
    start = time.monotonic()
    deadline = start + timeout_s
    if first_poll_s > 0:
        time.sleep(min(first_poll_s, timeout_s))
    while True:
        polled = time.monotonic()
        report = status()
        if done(report):
            return report
        if report.state == "Alarm":
            raise DeviceError(
                f"GRBL at {link.port} is in Alarm while waiting ({command!r}): "
                f"{report.raw}; check the gantry, then home() or unlock()"
            )
        if time.monotonic() > deadline:
            raise GrblTimeoutError(
                link.port, command, f"still {report.raw} after {timeout_s:.1f} s"
            )
        time.sleep(max(0.0, poll_interval_s - (time.monotonic() - polled)))
