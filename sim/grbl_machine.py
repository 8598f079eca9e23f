"""The GRBL 1.1 machine behind the emulator: line filter, G-code subset, settings, motion, states.

No I/O and no clock of its own: the emulator (:mod:`sim.grbl_emulator`) passes the time of every
event, and the machine writes its output lines through an ``emit(text, kind, source)`` callback
(``kind`` is ``"response"`` for ``ok``/``error:N``, ``"status"`` or ``"push"``; ``source`` the
line it answers), so fault injection can act on them.

Behaviour follows GRBL 1.1h (``protocol.c``, ``gcode.c``, ``limits.c``, ``report.c``):

- motion lines are answered ``ok`` as soon as they are planned; the planner holds 15 blocks
  and line processing stops while it is full; G4, spindle and coolant changes first wait for
  the planner to empty (GRBL's buffer synchronisation);
- each block runs a trapezoidal profile along its straight line, with GRBL's per-axis limits
  (rate ``min(F, $11x / |u_i|)``, acceleration ``min($12x / |u_i|)``), from rest to rest
  (no junction speed between blocks: a simplification);
- feed hold decelerates at the block's acceleration (``Hold:1``, then ``Hold:0``); ``~`` resumes;
- ``$20=1`` soft limits (machine space ``-$13x .. 0``) on a target: feed hold, then ``ALARM:2``,
  ``[MSG:Reset to continue]`` and nothing but a soft reset is served (status requests included);
  after the reset the offending line gets its ``ok``, then the banner and
  ``[MSG:'$H'|'$X' to unlock]``. ALARM:1 (hard limit) stops at once, with the same lock-up;
- in Alarm every G-code line gets ``error:9``; ``$X`` or ``$H`` clear it; power-up with ``$22=1``
  starts in Alarm; a soft reset during motion raises ALARM:3 (Hold:0 does not);
- not emulated: arcs, probing, jogging, check mode, safety door, sleep, overrides, tool length
  offsets, G10/G28/G30, inch reports; their commands get ``error:20`` (G-code) or ``error:3``.
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

__all__ = [
    "BANNER",
    "DEFAULT_SETTINGS",
    "PLANNER_BLOCKS",
    "GrblMachine",
    "LineAssembler",
    "Profile",
]

BANNER = "Grbl 1.1h ['$' for help]"
PLANNER_BLOCKS = 15  # BLOCK_BUFFER_SIZE 16, one always free
LINE_BUFFER_SIZE = 80

DEFAULT_SETTINGS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0,
    30: 1000, 31: 0, 32: 0,
    100: 250.0, 101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0,
    120: 10.0, 121: 10.0, 122: 10.0, 130: 200.0, 131: 200.0, 132: 200.0,
}  # fmt: skip
"""GRBL 1.1's default settings (``$$`` of a fresh controller)."""

_INTEGER_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32})
_ZERO_DECIMAL_SETTINGS = frozenset({30, 31})
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)")
_VALUE_LETTERS = frozenset("FSPNTXYZIJKLR")
_EPS = 1e-9

Vec = tuple[float, float, float]
Emit = Callable[[str, str, str], None]


class LineAssembler:
    """GRBL's character filter: whitespace and control characters dropped, ``()`` and ``;``
    comments removed, letters upper-cased, ``/`` ignored, overflow past 79 characters flagged.
    """

    def __init__(self) -> None:
        self._chars: list[str] = []
        self._comment = ""  # "(" or ";" while in a comment
        self._overflow = False

    def reset(self) -> None:
        self._chars.clear()
        self._comment, self._overflow = "", False

    def feed(self, byte: int) -> tuple[str, bool] | None:
        """Take one byte; at an end of line return ``(line, overflowed)``."""
        if byte in (0x0A, 0x0D):
            line, overflow = "".join(self._chars), self._overflow
            self.reset()
            return line, overflow
        char = chr(byte)
        if self._comment or self._overflow:
            if char == ")" and self._comment == "(":
                self._comment = ""
        elif byte <= 0x20 or char == "/":
            pass
        elif char in "(;":
            self._comment = char
        elif len(self._chars) >= LINE_BUFFER_SIZE - 1:
            self._overflow = True
        else:
            self._chars.append(char.upper())
        return None


@dataclass(frozen=True)
class Profile:
    """A trapezoidal speed profile along one straight block: accelerate, cruise, decelerate.

    Distances in units, speeds in units/s, accelerations in units/s^2, times in s.
    """

    v0: float
    vp: float
    accel: float
    decel: float
    d1: float
    d2: float
    d3: float
    t1: float
    t2: float
    t3: float

    @staticmethod
    def plan(length: float, v0: float, v_nominal: float, accel: float) -> Profile:
        """From speed ``v0`` to rest over ``length``, cruising at most at ``v_nominal``."""
        if length <= _EPS:
            return Profile(0.0, 0.0, accel, accel, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        vp = min(v_nominal, math.sqrt(accel * length + 0.5 * v0 * v0))
        if vp < v0:
            return Profile.stop(v0, length)
        d1 = (vp * vp - v0 * v0) / (2 * accel)
        d3 = vp * vp / (2 * accel)
        d2 = max(0.0, length - d1 - d3)
        return Profile(v0, vp, accel, accel, d1, d2, d3, (vp - v0) / accel, d2 / vp, vp / accel)

    @staticmethod
    def stop(v0: float, distance: float) -> Profile:
        """Decelerate uniformly from ``v0`` to rest over ``distance``."""
        decel = v0 * v0 / (2 * distance)
        return Profile(v0, v0, decel, decel, 0.0, 0.0, distance, 0.0, 0.0, v0 / decel)

    @property
    def duration(self) -> float:
        return self.t1 + self.t2 + self.t3

    @property
    def length(self) -> float:
        return self.d1 + self.d2 + self.d3

    def at(self, t: float) -> tuple[float, float]:
        """(distance, speed) at time ``t`` after the start."""
        if t <= 0:
            return 0.0, self.v0
        if t < self.t1:
            return self.v0 * t + 0.5 * self.accel * t * t, self.v0 + self.accel * t
        t -= self.t1
        if t < self.t2:
            return self.d1 + self.vp * t, self.vp
        t -= self.t2
        if t < self.t3:
            return self.d1 + self.d2 + self.vp * t - 0.5 * self.decel * t * t, (
                self.vp - self.decel * t
            )
        return self.length, 0.0


@dataclass
class _Block:
    start: Vec
    end: Vec
    v_nominal: float  # units/s
    accel: float
    done: float = 0.0  # distance covered before the current profile
    profile: Profile | None = None
    t0: float = 0.0

    @property
    def length(self) -> float:
        return math.dist(self.start, self.end)

    def point(self, s: float) -> Vec:
        length = self.length
        f = 1.0 if length <= _EPS else min(1.0, s / length)
        a, b = self.start, self.end
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


@dataclass
class _Parser:
    """The G-code parser's modal state (GRBL's ``gc_state``)."""

    motion: int = 0
    absolute: bool = True
    inches: bool = False
    plane: int = 17
    wcs: int = 54
    feed: float = 0.0  # units/min
    speed: float = 0.0
    tool: int = 0
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    g92: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


class _Refused(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


Step = Callable[[float], bool]


class GrblMachine:
    """GRBL 1.1 state, parser and motion; see the module docstring for what is emulated.

    Parameters
    ----------
    settings : overrides of :data:`DEFAULT_SETTINGS`
    emit : ``emit(text, kind, source)`` receives every output line
    hard_limit_after_moves : raise ALARM:1 half-way through this motion block (1-based count
        since start; fault injection), or None
    position : machine position at power-up (where the gantry was left; GRBL does not know it
        until homed, and takes it as is)
    """

    def __init__(
        self,
        settings: Mapping[int, float] | None,
        emit: Emit,
        *,
        hard_limit_after_moves: int | None = None,
        position: Vec = (0.0, 0.0, 0.0),
    ) -> None:
        self.settings = dict(DEFAULT_SETTINGS)
        self.settings.update({int(k): float(v) for k, v in (settings or {}).items()})
        self._emit = emit
        self.state = "Idle"  # Idle, Run, Hold, Home, Alarm
        self.hold_complete = False
        self.critical = False
        self.spindle = 5  # 3 CW, 4 CCW, 5 off
        self.spindle_speed = 0.0
        self.flood = False
        self.mist = False
        self.pins = ""
        self.moves_started = 0
        self._position: Vec = position
        self._planner: deque[_Block] = deque()
        self._steps: deque[Step] = deque()
        self._source = ""
        self._parser = _Parser()
        self._dwell_until: float | None = None
        self._soft_limit_pending = False
        self._ok_after_reset = ""
        self._wco_counter = 0
        self._ovr_counter = 0
        self._hard_limit_after = hard_limit_after_moves
        self._hard_limit_at: float | None = None

    # -- observation ------------------------------------------------------------------------

    @property
    def accepting_lines(self) -> bool:
        """True when GRBL would read the next line (no line in progress, not locked up)."""
        return not self._steps and not self.critical

    @property
    def responsive(self) -> bool:
        """True when GRBL answers status requests (not in a critical alarm, not homing)."""
        return not self.critical and self.state != "Home"

    @property
    def planner_free(self) -> int:
        return PLANNER_BLOCKS - len(self._planner)

    def position(self, now: float) -> Vec:
        """Machine position at ``now`` (call :meth:`update` first)."""
        block = self._active_block()
        if block is None or block.profile is None:
            return self._position
        s, _ = block.profile.at(now - block.t0)
        return block.point(block.done + s)

    def speed(self, now: float) -> float:
        """Current feed rate along the path, units/min."""
        block = self._active_block()
        if block is None or block.profile is None:
            return 0.0
        return 60.0 * block.profile.at(now - block.t0)[1]

    def state_text(self) -> str:
        if self.state == "Hold":
            return "Hold:0" if self.hold_complete else "Hold:1"
        return self.state

    def wco(self) -> Vec:
        g92 = self._parser.g92
        return (g92[0], g92[1], g92[2])

    def status_report(self, now: float, rx_free: int) -> str:
        """A ``<...>`` report as GRBL 1.1 formats it, with its WCO/Ov refresh counters."""
        mask = int(self.settings[10])
        position, wco = self.position(now), self.wco()
        if not mask & 1:
            position = (position[0] - wco[0], position[1] - wco[1], position[2] - wco[2])
        parts = [self.state_text(), ("MPos:" if mask & 1 else "WPos:") + _axes(position)]
        if mask & 2:
            parts.append(f"Bf:{self.planner_free},{rx_free}")
        speed = self.spindle_speed if self.spindle != 5 else 0.0
        parts.append(f"FS:{self.speed(now):.0f},{speed:.0f}")
        if self.pins:
            parts.append(f"Pn:{self.pins}")
        busy = self.state in ("Run", "Hold", "Home")
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = 29 if busy else 9
            self._ovr_counter = self._ovr_counter or 1
            parts.append("WCO:" + _axes(wco))
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = 19 if busy else 9
            parts.append("Ov:100,100,100")
            accessories = ("S" if self.spindle == 3 else "C" if self.spindle == 4 else "") + (
                ("F" if self.flood else "") + ("M" if self.mist else "")
            )
            if accessories:
                parts.append(f"A:{accessories}")
        return "<" + "|".join(parts) + ">"

    # -- events -----------------------------------------------------------------------------

    def power_up(self) -> None:
        """Start as GRBL does: Alarm when homing is enabled (HOMING_INIT_LOCK)."""
        if self.settings[22]:
            self.state = "Alarm"
        self._greet()

    def soft_reset(self, now: float) -> None:
        """Ctrl-X: stop everything, keep the position, alarm if motion was cut."""
        self.update(now)
        if self.state == "Home":
            self._emit("ALARM:6", "push", "")
            self.state = "Alarm"
        elif self.state == "Run" or (self.state == "Hold" and not self.hold_complete):
            self._emit("ALARM:3", "push", "")
            self.state = "Alarm"
        self._position = self.position(now)
        self._planner.clear()
        self._steps.clear()
        self._dwell_until = None
        self._soft_limit_pending = False
        self._hard_limit_at = None
        self.critical = False
        if self._ok_after_reset:
            self._emit("ok", "response", self._ok_after_reset)
            self._ok_after_reset = ""
        self.spindle, self.spindle_speed, self.flood, self.mist = 5, 0.0, False, False
        position = list(self._position)
        self._parser = _Parser(position=position)
        self._wco_counter = self._ovr_counter = 0
        if self.state != "Alarm":
            self.state = "Idle"
        self.hold_complete = False
        self._greet()

    def feed_hold(self, now: float) -> None:
        """``!``: decelerate to a stop at the block's acceleration."""
        if self.critical or self.state in ("Alarm", "Home", "Hold"):
            return
        self.update(now)
        if self.state == "Idle":
            self.state, self.hold_complete = "Hold", True
            return
        block = self._planner[0]
        assert block.profile is not None
        s, v = block.profile.at(now - block.t0)
        remaining = block.length - block.done - s
        self.state, self.hold_complete = "Hold", False
        stopping = v * v / (2 * block.accel)
        if stopping >= remaining - _EPS:
            return  # already braking to the end of the block; the hold completes there
        block.done += s
        block.t0 = now
        block.profile = Profile.stop(v, stopping) if v > _EPS else None
        if block.profile is None:
            self._hold_stopped(block, now)

    def cycle_start(self, now: float) -> None:
        """``~``: resume after a completed hold (ignored while still decelerating)."""
        if self.critical or self.state != "Hold" or not self.hold_complete:
            return
        self.update(now)
        self.hold_complete = False
        if self._planner:
            self.state = "Run"
            self._start(self._planner[0], now, count=False)
        else:
            self.state = "Idle"
        self._run_steps(now)

    def raise_alarm(self, code: int, now: float, *, advance: bool = True) -> None:
        """Stop at once and raise ``ALARM:code``; codes 1 and 2 lock GRBL until a reset."""
        if advance:
            self.update(now)
        self._halt(now)
        self.state = "Alarm"
        self._emit(f"ALARM:{code}", "push", self._source)
        if code in (1, 2):
            self._emit("[MSG:Reset to continue]", "push", self._source)
            self.critical = True

    def update(self, now: float) -> None:
        """Advance motion, dwells and waiting lines to ``now``."""
        while not self.critical:
            block = self._active_block()
            if block is None or block.profile is None:
                break
            end = block.t0 + block.profile.duration
            if self._hard_limit_at is not None and self._hard_limit_at <= min(end, now):
                at, self._hard_limit_at = self._hard_limit_at, None
                self.pins = "X"  # the switch that tripped, shown until the next reset
                self.raise_alarm(1, at, advance=False)
                return
            if end > now:
                break
            block.done += block.profile.length
            block.profile = None
            if self.state == "Hold":
                self._hold_stopped(block, end)
                continue
            self._position = block.end
            self._planner.popleft()
            if self._planner:
                self._start(self._planner[0], end)
            elif self.state == "Run":
                self.state = "Idle"
            self._run_steps(end)
        self._run_steps(now)

    def execute_line(self, line: str, overflow: bool, now: float) -> None:
        """Execute one filtered line; its response comes now or when its steps are done."""
        self._source = line
        self.update(now)
        try:
            if overflow:
                raise _Refused(11)
            if not line:
                self._respond("ok")
            elif line.startswith("$"):
                self._system(line, now)
            elif self.state == "Alarm":
                raise _Refused(9)
            else:
                self._gcode(line)
        except _Refused as refused:
            self._steps.clear()
            self._respond(f"error:{refused.code}")
        self._run_steps(now)

    # -- internals: motion ------------------------------------------------------------------

    def _active_block(self) -> _Block | None:
        if self.state in ("Run", "Hold", "Home") and self._planner:
            return self._planner[0]
        return None

    def _start(self, block: _Block, t: float, *, count: bool = True) -> None:
        block.t0 = t
        block.profile = Profile.plan(block.length - block.done, 0.0, block.v_nominal, block.accel)
        if count and self.state != "Home":
            self.moves_started += 1
            if self.moves_started == self._hard_limit_after:
                self._hard_limit_at = t + 0.5 * block.profile.duration

    def _hold_stopped(self, block: _Block, t: float) -> None:
        self._position = block.point(block.done)
        if block.done >= block.length - _EPS:
            self._planner.popleft()
        self.hold_complete = True
        if self._soft_limit_pending:
            self._soft_limit_alarm(t)

    def _halt(self, now: float) -> None:
        self._position = self.position(now)
        self._planner.clear()
        self._steps.clear()
        self._dwell_until = None
        self.spindle, self.spindle_speed, self.flood, self.mist = 5, 0.0, False, False

    def _soft_limit_alarm(self, now: float) -> None:
        self._soft_limit_pending = False
        source = self._source
        self.raise_alarm(2, now, advance=False)
        self._ok_after_reset = source or "?"  # GRBL answers the line only after the reset

    def _block(self, target: Vec, rate_min: float) -> _Block:
        start = tuple(self._parser_last_target())
        delta = [t - s for s, t in zip(start, target, strict=True)]
        length = math.hypot(*delta)
        rate, accel = rate_min / 60.0, math.inf
        for axis, d in enumerate(delta):
            if abs(d) > _EPS:
                share = abs(d) / length
                rate = min(rate, self.settings[110 + axis] / 60.0 / share)
                accel = min(accel, self.settings[120 + axis] / share)
        return _Block((start[0], start[1], start[2]), target, rate, accel)

    def _parser_last_target(self) -> Vec:
        return self._planner[-1].end if self._planner else self._position

    def _queue_move(self, target: Vec, rate_min: float) -> Step:
        def step(t: float) -> bool:
            if self._soft_limit_pending:
                return False
            if self.settings[20] and not _within_travel(target, self.settings):
                if self.state in ("Run", "Hold") and self._planner:
                    self._soft_limit_pending = True
                    self.feed_hold(t)
                    if self.hold_complete:
                        self._soft_limit_alarm(t)
                else:
                    self._soft_limit_alarm(t)
                return False
            if len(self._planner) >= PLANNER_BLOCKS:
                return False
            block = self._block(target, rate_min)
            if block.length <= _EPS:
                return True  # GRBL drops zero-length blocks
            self._planner.append(block)
            if self.state == "Idle":
                self.state = "Run"
                self._start(block, t)
            return True

        return step

    def _sync(self, t: float) -> bool:
        return not self._planner and self.state not in ("Run", "Hold")

    def _dwell(self, seconds: float) -> Step:
        def step(t: float) -> bool:
            if self._dwell_until is None:
                self._dwell_until = t + seconds
            if t < self._dwell_until:
                return False
            self._dwell_until = None
            return True

        return step

    def _run_steps(self, t: float) -> None:
        while self._steps and not self.critical:
            if not self._steps[0](t):
                return
            if self._steps:  # an alarm inside the step may have cleared them
                self._steps.popleft()

    def _respond(self, text: str) -> None:
        source = self._source

        def step(t: float) -> bool:
            self._emit(text, "response", source)
            return True

        self._steps.append(step)

    def _do(self, action: Callable[[], None]) -> None:
        def step(t: float) -> bool:
            action()
            return True

        self._steps.append(step)

    def _greet(self) -> None:
        self._emit(BANNER, "push", "")
        if self.state == "Alarm":
            self._emit("[MSG:'$H'|'$X' to unlock]", "push", "")

    # -- internals: system commands ---------------------------------------------------------

    def _system(self, line: str, now: float) -> None:
        idle = self.state in ("Idle", "Alarm")
        command = line[1:]
        if command == "":
            self._push("[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]")
        elif command == "$":
            if self.state in ("Run", "Hold"):
                raise _Refused(8)
            for number in sorted(self.settings):
                self._push(f"${number}={_setting_text(number, self.settings[number])}")
        elif command == "G":
            self._push(self._gc_state())
        elif command == "X":
            if self.state == "Alarm":
                self._push("[MSG:Caution: Unlocked]")
                self._do(lambda: setattr(self, "state", "Idle"))
        elif command[:1] in ("$", "G", "X", "C"):
            raise _Refused(3)  # "$X1", "$GG", and check mode ($C, not emulated)
        elif not idle:
            raise _Refused(8)
        elif command == "I":
            self._push("[VER:1.1h.20190830:]")
            self._push(f"[OPT:V,{PLANNER_BLOCKS},128]")
        elif command == "N":
            self._push("$N0=")
            self._push("$N1=")
        elif command == "#":
            for name in ("G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30"):
                self._push(f"[{name}:0.000,0.000,0.000]")
            self._push(f"[G92:{_axes(self.wco())}]")
            self._push("[TLO:0.000]")
            self._push("[PRB:0.000,0.000,0.000:0]")
        elif command == "H":
            if not self.settings[22]:
                raise _Refused(5)
            self._homing(now)
        elif not command[:1].isdigit():
            raise _Refused(3)  # $J=, $SLP, $RST=...: not emulated
        else:
            self._store_setting(command)
        self._respond("ok")

    def _push(self, text: str) -> None:
        source = self._source

        def step(t: float) -> bool:
            self._emit(text, "push", source)
            return True

        self._steps.append(step)

    def _store_setting(self, command: str) -> None:
        number = _NUMBER.match(command)
        if not number:
            raise _Refused(2)
        rest = command[number.end() :]
        if not rest.startswith("="):
            raise _Refused(3)
        value = _NUMBER.match(rest, 1)
        if not value:
            raise _Refused(2)
        parameter, amount = float(number.group()), float(value.group())
        if value.end() != len(rest) or parameter > 255 or parameter != int(parameter):
            raise _Refused(3)
        key = int(parameter)
        if amount < 0:
            raise _Refused(4)
        if key not in self.settings:
            raise _Refused(3)
        if key in _INTEGER_SETTINGS:
            amount = float(int(amount))
        if key == 0 and amount < 3:
            raise _Refused(6)
        if key == 20 and amount and not self.settings[22]:
            raise _Refused(10)
        self.settings[key] = amount
        if key == 22 and not amount:
            self.settings[20] = 0.0  # GRBL clears soft limits with homing

    def _homing(self, now: float) -> None:
        """$H: seek the switches at $25, pull off, locate at $24, pull off (all axes at once)."""
        travel = [self.settings[130 + i] for i in range(3)]
        pulloff = self.settings[27]
        negative = [bool(int(self.settings[23]) & (1 << i)) for i in range(3)]
        switch = tuple(-travel[i] if negative[i] else 0.0 for i in range(3))
        back = tuple(switch[i] + (pulloff if negative[i] else -pulloff) for i in range(3))
        phases = (
            (switch, self.settings[25]),
            (back, self.settings[25]),
            (switch, self.settings[24]),
            (back, self.settings[25]),
        )

        def begin(t: float) -> bool:
            self.state = "Home"
            for target, rate in phases:
                block = self._block((target[0], target[1], target[2]), rate)
                self._planner.append(block)
            self._start(self._planner[0], t)
            return True

        def finish(t: float) -> bool:
            if self._planner:
                return False
            self._position = (back[0], back[1], back[2])
            self._parser.position = list(self._position)
            self.state = "Idle"
            return True

        self._steps.append(self._sync)
        self._steps.append(begin)
        self._steps.append(finish)

    def _gc_state(self) -> str:
        p = self._parser
        spindle = {3: "M3", 4: "M4"}.get(self.spindle, "M5")
        coolant = " ".join(m for m, on in (("M7", self.mist), ("M8", self.flood)) if on) or "M9"
        return (
            f"[GC:G{p.motion} G{p.wcs} G{p.plane} {'G20' if p.inches else 'G21'} "
            f"{'G90' if p.absolute else 'G91'} G94 {spindle} {coolant} T{p.tool} "
            f"F{p.feed:.0f} S{p.speed:.0f}]"
        )

    # -- internals: G-code ------------------------------------------------------------------

    def _gcode(self, line: str) -> None:
        words = _words(line)
        groups: dict[str, float] = {}
        values: dict[str, float] = {}
        for letter, value in words:
            if letter == "G":
                group = _g_group(value)
                if group in groups:
                    raise _Refused(21)
                groups[group] = value
            elif letter == "M":
                if value != int(value):
                    raise _Refused(23)
                m_group = _M_GROUPS.get(int(value))
                if m_group is None:
                    raise _Refused(20)
                if m_group in groups:
                    raise _Refused(21)
                groups[m_group] = value
            elif letter in _VALUE_LETTERS:
                if letter in values:
                    raise _Refused(25)
                if letter in "FNPST" and value < 0:
                    raise _Refused(4)
                values[letter] = value
            else:
                raise _Refused(20)
        self._plan_block(groups, values)

    def _plan_block(self, groups: dict[str, float], values: dict[str, float]) -> None:
        p = self._parser
        if "N" in values and values["N"] > 9999999:
            raise _Refused(27)
        if "T" in values and values["T"] > 255:
            raise _Refused(38)
        for letter in "IJKLR":
            if letter in values:
                raise _Refused(36)
        nonmodal = groups.get("nonmodal")
        if "P" in values and nonmodal != 4:
            raise _Refused(36)
        if nonmodal == 4 and "P" not in values:
            raise _Refused(28)
        axes = {letter: values[letter] for letter in "XYZ" if letter in values}
        motion = int(groups.get("motion", p.motion))
        inches = groups["units"] == 20 if "units" in groups else p.inches
        scale = 25.4 if inches else 1.0
        if nonmodal == 92 and "motion" in groups and axes:
            raise _Refused(24)
        if nonmodal == 92 and not axes:
            raise _Refused(26)
        moving = nonmodal not in (92, 92.1) and (bool(axes) or "motion" in groups)
        if nonmodal == 53 and motion not in (0, 1):
            raise _Refused(30)
        if moving and motion == 80 and axes:
            raise _Refused(31)
        feed = values["F"] * scale if "F" in values else p.feed
        if moving and motion == 1 and feed <= 0:
            raise _Refused(22)
        # Everything checked: change the modal state (GRBL's order of execution).
        p.feed = feed
        if "S" in values:
            speed = values["S"]
            if speed != p.speed and self.spindle != 5 and "spindle" not in groups:
                self._switch_spindle(self.spindle, speed)
            p.speed = speed
        if "T" in values:
            p.tool = int(values["T"])
        if "spindle" in groups:
            self._switch_spindle(int(groups["spindle"]), p.speed)
        if "coolant" in groups:
            self._switch_coolant(int(groups["coolant"]))
        if nonmodal == 4:
            self._steps.append(self._sync)
            self._steps.append(self._dwell(values["P"]))
        if "plane" in groups:
            p.plane = int(groups["plane"])
        p.inches = inches
        if "wcs" in groups:
            p.wcs = int(groups["wcs"])
        if "distance" in groups:
            p.absolute = groups["distance"] == 90
        if "motion" in groups:
            p.motion = motion
        if nonmodal == 92:
            for letter, value in axes.items():
                i = "XYZ".index(letter)
                p.g92[i] = p.position[i] - value * scale
            self._wco_counter = 0
        elif nonmodal == 92.1:
            p.g92 = [0.0, 0.0, 0.0]
            self._wco_counter = 0
        elif moving and axes and motion in (0, 1):
            target = list(p.position)
            for letter, value in axes.items():
                i = "XYZ".index(letter)
                if nonmodal == 53:
                    target[i] = value * scale
                elif p.absolute:
                    target[i] = value * scale + p.g92[i]
                else:
                    target[i] = p.position[i] + value * scale
            p.position = target
            rate = math.inf if motion == 0 else feed
            self._steps.append(self._queue_move((target[0], target[1], target[2]), rate))
        self._respond("ok")

    def _switch_spindle(self, mode: int, speed: float) -> None:
        def apply() -> None:
            self.spindle = mode
            self.spindle_speed = min(speed, self.settings[30]) if mode != 5 else 0.0
            self._ovr_counter = 0  # GRBL shows Ov and A in the next report after a change

        self._steps.append(self._sync)
        self._do(apply)

    def _switch_coolant(self, mode: int) -> None:
        def apply() -> None:
            if mode == 9:
                self.flood = self.mist = False
            elif mode == 8:
                self.flood = True
            else:
                self.mist = True
            self._ovr_counter = 0

        self._steps.append(self._sync)
        self._do(apply)


def _axes(values: Vec) -> str:
    return ",".join("0.000" if f"{v:.3f}" == "-0.000" else f"{v:.3f}" for v in values)


def _setting_text(number: int, value: float) -> str:
    if number in _INTEGER_SETTINGS or number in _ZERO_DECIMAL_SETTINGS:
        return f"{value:.0f}"
    return f"{value:.3f}"


def _within_travel(target: Vec, settings: Mapping[int, float]) -> bool:
    # GRBL's machine space is -max_travel .. 0 on every axis (homing toward +, the default).
    return all(-settings[130 + i] - _EPS <= target[i] <= _EPS for i in range(3))


def _words(line: str) -> list[tuple[str, float]]:
    words: list[tuple[str, float]] = []
    i = 0
    while i < len(line):
        letter = line[i]
        if not "A" <= letter <= "Z":
            raise _Refused(1)
        number = _NUMBER.match(line, i + 1)
        if not number:
            raise _Refused(2)
        words.append((letter, float(number.group())))
        i = number.end()
    return words


_M_GROUPS = {3: "spindle", 4: "spindle", 5: "spindle", 7: "coolant", 8: "coolant", 9: "coolant"}
_G_GROUPS = {
    0: "motion", 1: "motion", 80: "motion", 90: "distance", 91: "distance", 20: "units",
    21: "units", 17: "plane", 18: "plane", 19: "plane", 94: "feedmode", 4: "nonmodal",
    53: "nonmodal", 92: "nonmodal", 54: "wcs", 55: "wcs", 56: "wcs", 57: "wcs", 58: "wcs",
    59: "wcs",
}  # fmt: skip


def _g_group(value: float) -> str:
    if abs(value - 92.1) < 1e-6:
        return "nonmodal"
    code = int(value)
    if code not in _G_GROUPS:
        raise _Refused(20)
    if value != code:
        raise _Refused(23)
    return _G_GROUPS[code]
