"""GRBL 1.1's machine states and alarms, and the events that drive parser, planner and lines.

No I/O and no clock of its own: the emulator (:mod:`sim.grbl_emulator`) passes the time of every
event, and the machine writes its output lines through an ``emit(text, kind, source)`` callback
(``kind`` is ``"response"`` for ``ok``/``error:N``, ``"status"`` or ``"push"``; ``source`` the
line it answers), so fault injection can act on them. Its parts: the line filter
(:mod:`sim.grbl_lines`), the G-code subset (:mod:`sim.grbl_gcode`), the settings
(:mod:`sim.grbl_settings`), motion (:mod:`sim.grbl_motion`), a line's steps
(:mod:`sim.grbl_steps`) and status reports (:mod:`sim.grbl_report`).

Behaviour follows GRBL 1.1h (``protocol.c``, ``gcode.c``, ``limits.c``, ``report.c``):

- motion lines are answered ``ok`` as soon as they are planned; the planner holds 15 blocks
  and line processing stops while it is full; G4, spindle and coolant changes first wait for
  the planner to empty (GRBL's buffer synchronisation);
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

from collections.abc import Mapping

from sim.grbl_gcode import (
    Action,
    CoolantChange,
    Dwell,
    ModalState,
    Move,
    OffsetChange,
    Refused,
    SpindleChange,
    interpret,
    modal_report,
)
from sim.grbl_motion import EPS, PLANNER_BLOCKS, Block, Planner, Vec, within_travel
from sim.grbl_report import StatusReporter, axes_text
from sim.grbl_settings import setting_lines, settings_with, store_setting
from sim.grbl_steps import Emit, LineSteps, Step

__all__ = ["BANNER", "GrblMachine"]

BANNER = "Grbl 1.1h ['$' for help]"


class GrblMachine:
    """GRBL 1.1 state, parser and motion; see the module docstring for what is emulated.

    Parameters
    ----------
    settings : overrides of :data:`sim.grbl_settings.DEFAULT_SETTINGS`
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
        self.settings = settings_with(settings)
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
        self._planner = Planner(position)
        self._steps = LineSteps(emit)
        self._parser = ModalState()
        self._reports = StatusReporter()
        self._soft_limit_pending = False
        self._ok_after_reset = ""
        self._hard_limit_after = hard_limit_after_moves
        self._hard_limit_at: float | None = None

    # -- observation ------------------------------------------------------------------------

    @property
    def accepting_lines(self) -> bool:
        """True when GRBL would read the next line (no line in progress, not locked up)."""
        return not self._steps.pending and not self.critical

    @property
    def responsive(self) -> bool:
        """True when GRBL answers status requests (not in a critical alarm, not homing)."""
        return not self.critical and self.state != "Home"

    @property
    def planner_free(self) -> int:
        """Free planner blocks."""
        return self._planner.free

    def position(self, now: float) -> Vec:
        """Machine position at ``now`` (call :meth:`update` first)."""
        block = self._active_block()
        if block is None or block.profile is None:
            return self._planner.rest
        return block.position(now)

    def speed(self, now: float) -> float:
        """Current feed rate along the path, units/min."""
        block = self._active_block()
        if block is None or block.profile is None:
            return 0.0
        return 60.0 * block.speed(now)

    def state_text(self) -> str:
        """The state as a status report names it (``Hold:0`` once a hold has stopped)."""
        if self.state == "Hold":
            return "Hold:0" if self.hold_complete else "Hold:1"
        return self.state

    def wco(self) -> Vec:
        """The work coordinate offset (G92; the G54-59 offsets are zero), units."""
        g92 = self._parser.g92
        return (g92[0], g92[1], g92[2])

    def status_report(self, now: float, rx_free: int) -> str:
        """A ``<...>`` report as GRBL 1.1 formats it, with its WCO/Ov refresh counters."""
        return self._reports.report(
            state=self.state_text(),
            busy=self.state in ("Run", "Hold", "Home"),
            mask=int(self.settings[10]),
            position=self.position(now),
            wco=self.wco(),
            buffers=(self.planner_free, rx_free),
            feed=self.speed(now),
            spindle=self.spindle,
            spindle_speed=self.spindle_speed,
            flood=self.flood,
            mist=self.mist,
            pins=self.pins,
        )

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
        self._planner.clear(self.position(now))
        self._steps.clear()
        self._soft_limit_pending = False
        self._hard_limit_at = None
        self.critical = False
        if self._ok_after_reset:
            self._emit("ok", "response", self._ok_after_reset)
            self._ok_after_reset = ""
        self.spindle, self.spindle_speed, self.flood, self.mist = 5, 0.0, False, False
        self._parser = ModalState(position=list(self._planner.rest))
        self._reports = StatusReporter()
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
        block = self._planner.blocks[0]
        self.state, self.hold_complete = "Hold", False
        if block.brake(now):
            self._hold_stopped(block, now)

    def cycle_start(self, now: float) -> None:
        """``~``: resume after a completed hold (ignored while still decelerating)."""
        if self.critical or self.state != "Hold" or not self.hold_complete:
            return
        self.update(now)
        self.hold_complete = False
        if self._planner.blocks:
            self.state = "Run"
            self._start(self._planner.blocks[0], now, count=False)
        else:
            self.state = "Idle"
        self._run_steps(now)

    def raise_alarm(self, code: int, now: float, *, advance: bool = True) -> None:
        """Stop at once and raise ``ALARM:code``; codes 1 and 2 lock GRBL until a reset."""
        if advance:
            self.update(now)
        self._halt(now)
        self.state = "Alarm"
        self._emit(f"ALARM:{code}", "push", self._steps.source)
        if code in (1, 2):
            self._emit("[MSG:Reset to continue]", "push", self._steps.source)
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
            block.run_out()
            if self.state == "Hold":
                self._hold_stopped(block, end)
                continue
            self._planner.finish(block)
            if self._planner.blocks:
                self._start(self._planner.blocks[0], end)
            elif self.state == "Run":
                self.state = "Idle"
            self._run_steps(end)
        self._run_steps(now)

    def execute_line(self, line: str, overflow: bool, now: float) -> None:
        """Execute one filtered line; its response comes now or when its steps are done."""
        self._steps.source = line
        self.update(now)
        try:
            if overflow:
                raise Refused(11)
            if not line:
                self._steps.respond("ok")
            elif line.startswith("$"):
                self._system(line, now)
            elif self.state == "Alarm":
                raise Refused(9)
            else:
                self._gcode(line)
        except Refused as refused:
            self._steps.clear()
            self._steps.respond(f"error:{refused.code}")
        self._run_steps(now)

    # -- internals: motion ------------------------------------------------------------------

    def _active_block(self) -> Block | None:
        if self.state in ("Run", "Hold", "Home") and self._planner.blocks:
            return self._planner.blocks[0]
        return None

    def _start(self, block: Block, t: float, *, count: bool = True) -> None:
        profile = block.start_at(t)
        if count and self.state != "Home":
            self.moves_started += 1
            if self.moves_started == self._hard_limit_after:
                self._hard_limit_at = t + 0.5 * profile.duration

    def _hold_stopped(self, block: Block, t: float) -> None:
        self._planner.settle(block)
        self.hold_complete = True
        if self._soft_limit_pending:
            self._soft_limit_alarm(t)

    def _halt(self, now: float) -> None:
        self._planner.clear(self.position(now))
        self._steps.clear()
        self.spindle, self.spindle_speed, self.flood, self.mist = 5, 0.0, False, False

    def _soft_limit_alarm(self, now: float) -> None:
        self._soft_limit_pending = False
        source = self._steps.source
        self.raise_alarm(2, now, advance=False)
        self._ok_after_reset = source or "?"  # GRBL answers the line only after the reset

    def _queue_move(self, target: Vec, rate_min: float) -> Step:
        def step(t: float) -> bool:
            if self._soft_limit_pending:
                return False
            if self.settings[20] and not within_travel(target, self.settings):
                if self.state in ("Run", "Hold") and self._planner.blocks:
                    self._soft_limit_pending = True
                    self.feed_hold(t)
                    if self.hold_complete:
                        self._soft_limit_alarm(t)
                else:
                    self._soft_limit_alarm(t)
                return False
            if self._planner.full:
                return False
            block = self._planner.block_to(target, rate_min, self.settings)
            if block.length <= EPS:
                return True  # GRBL drops zero-length blocks
            self._planner.blocks.append(block)
            if self.state == "Idle":
                self.state = "Run"
                self._start(block, t)
            return True

        return step

    def _sync(self, t: float) -> bool:
        return not self._planner.blocks and self.state not in ("Run", "Hold")

    def _run_steps(self, t: float) -> None:
        self._steps.run(t, lambda: self.critical)

    def _greet(self) -> None:
        self._emit(BANNER, "push", "")
        if self.state == "Alarm":
            self._emit("[MSG:'$H'|'$X' to unlock]", "push", "")

    # -- internals: system commands ---------------------------------------------------------

    def _system(self, line: str, now: float) -> None:
        idle = self.state in ("Idle", "Alarm")
        command = line[1:]
        push = self._steps.push
        if command == "":
            push("[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]")
        elif command == "$":
            if self.state in ("Run", "Hold"):
                raise Refused(8)
            for text in setting_lines(self.settings):
                push(text)
        elif command == "G":
            push(modal_report(self._parser, self.spindle, self.mist, self.flood))
        elif command == "X":
            if self.state == "Alarm":
                push("[MSG:Caution: Unlocked]")
                self._steps.do(lambda: setattr(self, "state", "Idle"))
        elif command[:1] in ("$", "G", "X", "C"):
            raise Refused(3)  # "$X1", "$GG", and check mode ($C, not emulated)
        elif not idle:
            raise Refused(8)
        elif command == "I":
            push("[VER:1.1h.20190830:]")
            push(f"[OPT:V,{PLANNER_BLOCKS},128]")
        elif command == "N":
            push("$N0=")
            push("$N1=")
        elif command == "#":
            for name in ("G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30"):
                push(f"[{name}:0.000,0.000,0.000]")
            push(f"[G92:{axes_text(self.wco())}]")
            push("[TLO:0.000]")
            push("[PRB:0.000,0.000,0.000:0]")
        elif command == "H":
            if not self.settings[22]:
                raise Refused(5)
            self._homing(now)
        elif not command[:1].isdigit():
            raise Refused(3)  # $J=, $SLP, $RST=...: not emulated
        else:
            store_setting(self.settings, command)
        self._steps.respond("ok")

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
                block = self._planner.block_to(
                    (target[0], target[1], target[2]), rate, self.settings
                )
                self._planner.blocks.append(block)
            self._start(self._planner.blocks[0], t)
            return True

        def finish(t: float) -> bool:
            if self._planner.blocks:
                return False
            self._planner.rest = (back[0], back[1], back[2])
            self._parser.position = list(self._planner.rest)
            self.state = "Idle"
            return True

        self._steps.add(self._sync)
        self._steps.add(begin)
        self._steps.add(finish)

    # -- internals: G-code ------------------------------------------------------------------

    def _gcode(self, line: str) -> None:
        for action in interpret(line, self._parser, self.spindle):
            self._apply(action)
        self._steps.respond("ok")

    def _apply(self, action: Action) -> None:
        match action:
            case SpindleChange():
                self._switch_spindle(action.mode, action.speed)
            case CoolantChange():
                self._switch_coolant(action.mode)
            case Dwell():
                self._steps.add(self._sync)
                self._steps.dwell(action.seconds)
            case OffsetChange():
                self._reports.refresh_offsets()
            case Move():
                self._steps.add(self._queue_move(action.target, action.rate_min))

    def _switch_spindle(self, mode: int, speed: float) -> None:
        def apply() -> None:
            self.spindle = mode
            self.spindle_speed = min(speed, self.settings[30]) if mode != 5 else 0.0
            self._reports.refresh_overrides()

        self._steps.add(self._sync)
        self._steps.do(apply)

    def _switch_coolant(self, mode: int) -> None:
        def apply() -> None:
            if mode == 9:
                self.flood = self.mist = False
            elif mode == 8:
                self.flood = True
            else:
                self.mist = True
            self._reports.refresh_overrides()

        self._steps.add(self._sync)
        self._steps.do(apply)
