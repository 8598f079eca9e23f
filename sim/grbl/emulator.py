"""A GRBL 1.1 controller on a pseudo-terminal, for the real ``pyserial`` to talk to.

::

    with GrblEmulator(settings={110: 36000, 111: 36000}, faults=GrblFaults(seed=1)) as grbl:
        gantry = GrblGantry(grbl.port, 115200, axes)   # any serial client works
        ...
        grbl.light              # LightState(on=True, intensity=0.5, source="spindle")
        grbl.position_deg()     # (azimuth, inclination) with X, Y = 1 degree per unit

A thread serves the pty's master side like GRBL's serial interrupt and main loop: real-time
bytes (``?``, ``!``, ``~``, 0x18) act at once wherever they come, even mid-line; bytes >= 0x80
(overrides) are picked off and ignored; other bytes go into a 128-byte receive buffer, and bytes
arriving while it is full are lost, as on the hardware. The buffer only fills while GRBL cannot
read it (planner full, waiting for a G4/M-code synchronisation, homing, after an alarm, asleep),
so a host that counts characters never loses any and one that does not may; a reset (a soft
one, or GRBL's own after a failed homing) empties it and drops a pending status request. The
machine itself (parser, motion, states) is :class:`sim.grbl.machine.GrblMachine`.

Faults (:class:`GrblFaults`) are deterministic for a seed: each kind draws from its own random
stream, so one kind does not shift another. Limit switches are pressed and released with
:meth:`GrblEmulator.press_limit` and :meth:`GrblEmulator.release_limit`.
"""

from __future__ import annotations

import os
import random
import re
import select
import threading
import time
import tty
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType

from rig.grbl import GantryAxes, GantryAxisConfig
from sim.grbl.lines import LineAssembler
from sim.grbl.machine import GrblMachine

__all__ = ["FaultRule", "GrblEmulator", "GrblFaults", "LightState"]

_TICK_S = 0.002


@dataclass(frozen=True)
class FaultRule:
    """When a fault strikes: with ``probability``, on lines matching ``pattern``, up to ``limit``.

    ``pattern`` is a regular expression searched in the filtered line GRBL answers (None for
    any); ``limit`` is the most times the fault strikes (None for no limit).
    """

    probability: float = 1.0
    pattern: str | None = None
    limit: int | None = None


@dataclass(frozen=True)
class GrblFaults:
    """Fault injection for :class:`GrblEmulator`.

    Attributes
    ----------
    seed : seeds every fault's random stream
    drop_reply : the ``ok``/``error:N`` of a line is lost on the wire (the line is executed)
    drop_status : a status report is lost
    delay_reply : the ``ok``/``error:N`` of a line (and all output after it) comes ``delay_s``
        late
    garbage : a line of noise bytes comes before an output line
    hard_limit_after_moves : ALARM:1 (hard limit) half-way through this motion block (1-based,
        counted from start; homing moves not counted)
    homing_fails : ``$H`` fails with this alarm: 8 (the pull-off leaves the switch pressed) or
        9 (no switch within the search distance); GRBL then resets itself
    """

    seed: int = 0
    drop_reply: FaultRule | None = None
    drop_status: FaultRule | None = None
    delay_reply: FaultRule | None = None
    delay_s: float = 0.5
    garbage: FaultRule | None = None
    hard_limit_after_moves: int | None = None
    homing_fails: int | None = None


@dataclass(frozen=True)
class LightState:
    """The light as the emulated controller drives it.

    ``intensity`` is the spindle PWM duty (the output speed / $30, in [0, 1]) while the PWM is
    on, else 1.0 when the flood coolant pin is on, else 0.0. In laser mode (``$32=1``) the PWM
    follows the motion (see :mod:`sim.grbl.spindle`).
    """

    on: bool
    intensity: float
    source: str  # "spindle", "coolant" or "off"


class _Fault:
    def __init__(self, rule: FaultRule | None, seed: int, name: str) -> None:
        self.rule = rule
        self.rng = random.Random(f"{seed}:{name}")
        self.pattern = re.compile(rule.pattern) if rule and rule.pattern is not None else None
        self.count = 0

    def strikes(self, source: str) -> bool:
        rule = self.rule
        if rule is None or (rule.limit is not None and self.count >= rule.limit):
            return False
        if self.pattern is not None and not self.pattern.search(source):
            return False
        if self.rng.random() >= rule.probability:
            return False
        self.count += 1
        return True


class GrblEmulator:
    """GRBL 1.1 on a pty; ``port`` is the device path a client opens.

    Parameters
    ----------
    settings : overrides of GRBL's defaults (``{22: 1, 110: 36000, ...}``)
    faults : fault injection (none by default)
    rx_buffer_size : GRBL's serial receive buffer, 128 bytes on the Uno
    position : machine position at power-up, machine units
    critical_message_delay_s : GRBL's pause after an ALARM line (500 ms): ``[MSG:Reset to
        continue]`` comes that long after ALARM:1/2, and resets before it are discarded
    startup_lines : the ``$N0``/``$N1`` lines stored at power-up (as GRBL filters them:
        upper case, no spaces)
    """

    def __init__(
        self,
        *,
        settings: Mapping[int, float] | None = None,
        faults: GrblFaults | None = None,
        rx_buffer_size: int = 128,
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        critical_message_delay_s: float = 0.5,
        startup_lines: Sequence[str] = (),
    ) -> None:
        self.faults = faults or GrblFaults()
        self.rx_buffer_size = rx_buffer_size
        self.rx_overflow_bytes = 0
        """Bytes lost because the receive buffer was full."""
        self.tx_dropped_bytes = 0
        """Output bytes lost because nobody read the pty."""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self._master = self._slave = -1
        self.port = ""
        self._received = bytearray()
        self._lines: list[str] = []
        self._rx = bytearray()
        self._assembler = LineAssembler()
        self._status_pending = False
        self._resets = 0
        self._out: list[tuple[float, bytes]] = []
        self._now = time.monotonic()
        seed = self.faults.seed
        self._drop_reply = _Fault(self.faults.drop_reply, seed, "drop_reply")
        self._drop_status = _Fault(self.faults.drop_status, seed, "drop_status")
        self._delay_reply = _Fault(self.faults.delay_reply, seed, "delay_reply")
        self._garbage = _Fault(self.faults.garbage, seed, "garbage")
        self._noise_rng = random.Random(f"{seed}:noise")
        self._machine = GrblMachine(
            settings,
            self._emit,
            hard_limit_after_moves=self.faults.hard_limit_after_moves,
            position=position,
            critical_message_delay_s=critical_message_delay_s,
            startup_lines=startup_lines,
            homing_fails=self.faults.homing_fails,
        )

    # -- life cycle -------------------------------------------------------------------------

    def start(self) -> GrblEmulator:
        """Create the pty, power GRBL up (banner) and start serving."""
        if self._thread is not None:
            return self
        self._master, self._slave = os.openpty()
        # Raw: no echo, no newline translation, as a USB serial line.
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        with self._lock:
            self._now = time.monotonic()
            self._machine.power_up(self._now)
        self._thread = threading.Thread(target=self._serve, name="grbl-emulator", daemon=True)
        self._thread.start()
        # Once the power-up banner is on the pty, a client's open discards it (pyserial flushes
        # input on open), so every client starts from the same, quiet line.
        self._ready.wait(1.0)
        return self

    def close(self) -> None:
        """Stop serving and remove the pty."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1

    def __enter__(self) -> GrblEmulator:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- what a test or a simulated camera reads --------------------------------------------

    @property
    def received(self) -> bytes:
        """Every byte received so far, real-time bytes included."""
        with self._lock:
            return bytes(self._received)

    @property
    def lines(self) -> list[str]:
        """Every line GRBL read, after its filtering (upper case, no spaces or comments)."""
        with self._lock:
            return list(self._lines)

    @property
    def state(self) -> str:
        """The machine state as a status report shows it (``Idle``, ``Hold:0``...)."""
        with self._lock:
            self._advance()
            return self._machine.state_text()

    @property
    def settings(self) -> dict[int, float]:
        """A copy of GRBL's ``$`` settings, ``{number: value}``."""
        with self._lock:
            return dict(self._machine.settings)

    @property
    def light(self) -> LightState:
        """The light: spindle PWM or flood coolant pin."""
        with self._lock:
            self._advance()
            machine = self._machine
            spindle, speed = machine.spindle.state(self._now)
            if spindle != 5:
                top = machine.settings[30]
                duty = min(1.0, speed / top) if top > 0 else 0.0
                return LightState(duty > 0, duty, "spindle")
            if machine.flood:
                return LightState(True, 1.0, "coolant")
            return LightState(False, 0.0, "off")

    def machine_position(self) -> tuple[float, float, float]:
        """Machine position (GRBL units) now, from the motion model."""
        with self._lock:
            self._advance()
            return self._machine.position(self._now)

    def position_deg(self, axes: GantryAxes | None = None) -> tuple[float, float]:
        """(light azimuth, light inclination) in degrees; by default X and Y, 1 unit = 1 deg."""
        if axes is None:
            axes = GantryAxes(GantryAxisConfig("X", -1e9, 1e9), GantryAxisConfig("Y", -1e9, 1e9))
        return axes.angles(self.machine_position())

    @property
    def startup_lines(self) -> list[str]:
        """The stored startup lines, ``$N0`` and ``$N1`` (empty strings when not set)."""
        with self._lock:
            return list(self._machine.startup_lines)

    def inject_alarm(self, code: int = 1) -> None:
        """Raise ``ALARM:code`` now (1: a hard limit switch tripped, shown until the reset)."""
        with self._lock:
            self._advance()
            if code == 1:
                self._machine.limits.trip("X")
            self._machine.raise_alarm(code, self._now)

    def press_limit(self, letter: str) -> None:
        """Press the limit switch of axis ``letter`` (``Pn:`` shows it; an edge with $21=1)."""
        self._limit(letter, True)

    def release_limit(self, letter: str) -> None:
        """Release the limit switch of axis ``letter`` (also an edge: ALARM:1 with $21=1)."""
        self._limit(letter, False)

    def _limit(self, letter: str, pressed: bool) -> None:
        with self._lock:
            self._advance()
            self._machine.limit_switch(letter, pressed, self._now)

    # -- serving ----------------------------------------------------------------------------

    def _advance(self) -> None:
        self._now = time.monotonic()
        self._machine.update(self._now)
        self._note_reset()

    def _note_reset(self) -> None:
        """After a reset (a soft one, or GRBL's own) the receive buffer and requests are gone."""
        if self._machine.resets != self._resets:
            self._resets = self._machine.resets
            self._rx.clear()
            self._assembler.reset()
            self._status_pending = False

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], _TICK_S)
            except (OSError, ValueError):
                return
            data = b""
            if ready:
                try:
                    data = os.read(self._master, 4096)
                except BlockingIOError:
                    pass
                except OSError:
                    time.sleep(_TICK_S)  # EIO: no client has the pty open just now
            with self._lock:
                self._advance()
                for byte in data:
                    self._on_byte(byte)
                    if byte in (0x0A, 0x0D):
                        # GRBL parses while bytes still arrive, so a line ends before the next
                        # bytes can overflow the buffer behind it.
                        self._read_lines()
                self._read_lines()
                self._advance()
                self._read_lines()
                if self._status_pending and self._machine.responsive:
                    self._status_pending = False
                    free = self.rx_buffer_size - len(self._rx)
                    self._emit(self._machine.status_report(self._now, free), "status", "?")
                self._flush()
            self._ready.set()

    def _on_byte(self, byte: int) -> None:
        """GRBL's serial receive interrupt: real-time bytes act now, others are buffered."""
        self._received.append(byte)
        machine = self._machine
        if byte == 0x18:
            machine.soft_reset(self._now)
            self._note_reset()
        elif byte == ord("?"):
            self._status_pending = True  # several '?' before the report give one report
        elif byte == ord("!"):
            machine.feed_hold(self._now)
        elif byte == ord("~"):
            machine.cycle_start(self._now)
        elif byte >= 0x80:
            pass  # extended real-time commands (overrides, door, jog cancel): not emulated
        elif len(self._rx) >= self.rx_buffer_size:
            self.rx_overflow_bytes += 1
        else:
            self._rx.append(byte)

    def _read_lines(self) -> None:
        """GRBL's main loop: take characters while it is free to parse the next line."""
        taken = 0
        while taken < len(self._rx) and self._machine.accepting_lines:
            done = self._assembler.feed(self._rx[taken])
            taken += 1
            if done is not None:
                line, overflow = done
                self._lines.append(line)
                self._machine.execute_line(line, overflow, self._now)
        del self._rx[:taken]

    def _emit(self, text: str, kind: str, source: str) -> None:
        release = self._now
        if kind == "response":
            if self._drop_reply.strikes(source):
                return
            if self._delay_reply.strikes(source):
                release += self.faults.delay_s
        elif kind == "status" and self._drop_status.strikes(source):
            return
        if self._out:
            release = max(release, self._out[-1][0])  # a serial line keeps its order
        if self._garbage.strikes(source):
            self._out.append((release, self._noise()))
        self._out.append((release, text.encode("ascii") + b"\r\n"))

    def _noise(self) -> bytes:
        rng = self._noise_rng
        size = rng.randint(2, 12)
        # At least one byte >= 0x80 so noise never reads as a valid reply by chance.
        body = [rng.choice(b"<>|:!ok#@$%") for _ in range(size)] + [rng.randint(0x80, 0xFF)]
        rng.shuffle(body)
        return bytes(body) + b"\r\n"

    def _flush(self) -> None:
        sent = 0
        for release, data in self._out:
            if release > self._now:
                break
            sent += 1
            try:
                written = os.write(self._master, data)
            except BlockingIOError:
                written = 0
            except OSError:
                written = 0
            self.tx_dropped_bytes += len(data) - written
        del self._out[:sent]
