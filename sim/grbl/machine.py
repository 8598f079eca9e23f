"""GRBL 1.1's lines: ``$`` commands, G-code blocks, startup lines, homing and sleep.

No I/O and no clock of its own: the emulator (:mod:`sim.grbl.emulator`) passes the time of every
event, and the machine writes its output lines through an ``emit(text, kind, source)`` callback
(``kind`` is ``"response"`` for ``ok``/``error:N``, ``"status"`` or ``"push"``; ``source`` the
line it answers), so fault injection can act on them. Below the lines are the states, motion,
alarms and resets (:mod:`sim.grbl.states`); its other parts: the line filter
(:mod:`sim.grbl.lines`), the G-code subset (:mod:`sim.grbl.gcode`, arcs in
:mod:`sim.grbl.arcs`), the EEPROM settings and startup lines (:mod:`sim.grbl.settings`), motion
(:mod:`sim.grbl.motion`), a line's steps (:mod:`sim.grbl.steps`) and status reports
(:mod:`sim.grbl.report`).

Behaviour follows GRBL 1.1h (``protocol.c``, ``system.c``, ``gcode.c``, ``limits.c``):

- motion lines are answered ``ok`` as soon as they are planned; the planner holds 15 blocks
  and line processing stops while it is full; G4, and spindle and coolant changes, first wait
  for the planner to empty (GRBL's buffer synchronisation), so their ``ok`` comes only then;
- ``$20=1`` soft limits (machine space ``-$13x .. 0``) on a target: feed hold, then ``ALARM:2``,
  the critical lock-up (see :mod:`sim.grbl.states`); after the reset the offending line gets
  its ``ok``, then the banner and ``[MSG:'$H'|'$X' to unlock]``;
- in Alarm every G-code line gets ``error:9``; ``$X`` or ``$H`` clear it; power-up with ``$22=1``
  starts in Alarm; ``$H`` runs the startup lines before its ``ok``, ``$X`` does not;
- ``$Nx=line`` (Idle only) executes the line to validate it and stores it only if it is valid;
  after every power-up and soft reset into Idle each stored line runs and is echoed
  ``>line:ok`` or ``>line:error:N``;
- a failed homing (fault injection: ALARM:8, pull-off, or ALARM:9, no switch found) prints the
  alarm, pauses, answers the ``$H`` line ``ok`` (``system_execute_line`` returns OK after the
  abort, and ``protocol.c`` prints it before acting on the reset) and resets itself: banner and
  lock message;
- ``$SLP`` answers ``ok``, switches spindle and coolant off, prints ``[MSG:Sleeping]`` and
  reads no more lines (status requests are answered); only a soft reset wakes it, into Alarm;
- changing ``$100-$102`` keeps the position's steps: the machine position scales by old/new;
- not emulated: probing, jogging, check mode, safety door, overrides, tool length offsets,
  G10/G28/G30; their commands get ``error:20`` (G-code) or ``error:3``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from sim.grbl.gcode import (
    Action,
    CoolantChange,
    Dwell,
    Move,
    OffsetChange,
    SpindleChange,
    interpret,
    modal_report,
)
from sim.grbl.motion import EPS, PLANNER_BLOCKS, Vec, within_travel
from sim.grbl.report import ngc_parameter_lines
from sim.grbl.settings import (
    N_STARTUP_LINES,
    setting_lines,
    startup_line_command,
    startup_listing,
    store_setting,
)
from sim.grbl.states import BANNER, MachineStates
from sim.grbl.steps import Emit, Step
from sim.grbl.words import Refused

__all__ = ["BANNER", "GrblMachine"]

_HOMING_SEARCH_SCALAR = 1.5  # limits.c: the seek covers 1.5 times the max travel


class GrblMachine(MachineStates):
    """GRBL 1.1 state, parser and motion; see the module docstring for what is emulated.

    Parameters
    ----------
    settings : overrides of :data:`sim.grbl.settings.DEFAULT_SETTINGS`
    emit : ``emit(text, kind, source)`` receives every output line
    hard_limit_after_moves : raise ALARM:1 half-way through this motion block (1-based count
        since start; fault injection), or None
    position : machine position at power-up (where the gantry was left; GRBL does not know it
        until homed, and takes it as is), units
    critical_message_delay_s : GRBL's pause after an ALARM line (500 ms)
    startup_lines : the stored ``$N0``/``$N1`` lines at power-up (filtered: upper case, no
        spaces)
    homing_fails : make ``$H`` fail with this alarm (8: pull-off, 9: no switch found), or None
    """

    def __init__(
        self,
        settings: Mapping[int, float] | None,
        emit: Emit,
        *,
        hard_limit_after_moves: int | None = None,
        position: Vec = (0.0, 0.0, 0.0),
        critical_message_delay_s: float = 0.5,
        startup_lines: Sequence[str] = (),
        homing_fails: int | None = None,
    ) -> None:
        super().__init__(
            settings,
            emit,
            hard_limit_after_moves=hard_limit_after_moves,
            position=position,
            critical_message_delay_s=critical_message_delay_s,
        )
        if len(startup_lines) > N_STARTUP_LINES:
            raise ValueError(f"GRBL stores {N_STARTUP_LINES} startup lines, got {startup_lines}")
        if homing_fails not in (None, 8, 9):
            raise ValueError(f"a failed homing is ALARM:8 or ALARM:9, not {homing_fails}")
        self.startup_lines = [*startup_lines, *[""] * (N_STARTUP_LINES - len(startup_lines))]
        self._homing_fails = homing_fails

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

    # -- system commands --------------------------------------------------------------------

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
            push(modal_report(self._parser, report_inches=bool(self.settings[13])))
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
            for text in startup_listing(self.startup_lines):
                push(text)
        elif command.startswith("N"):
            self._store_startup_line(command)
        elif command == "#":
            for text in ngc_parameter_lines(self.wco(), inches=bool(self.settings[13])):
                push(text)
        elif command == "H":
            if not self.settings[22]:
                raise Refused(5)
            self._homing()
        elif command.startswith("S"):
            if command != "SLP":
                raise Refused(3)
            self._steps.respond("ok")
            self._steps.do(self._sleep)
            return
        elif not command[:1].isdigit():
            raise Refused(3)  # $J=, $RST=...: not emulated
        else:
            self._store_setting(command)
        self._steps.respond("ok")

    def _store_setting(self, command: str) -> None:
        before = [self.settings[100 + axis] for axis in range(3)]
        store_setting(self.settings, command)
        for axis in range(3):
            after = self.settings[100 + axis]
            if before[axis] > 0 and after > 0 and after != before[axis]:
                # GRBL counts the position in steps, which a new steps/mm leaves as they are.
                self._planner.rescale(axis, before[axis] / after)

    def _store_startup_line(self, command: str) -> None:
        if self.state != "Idle":
            raise Refused(8)
        index, text = startup_line_command(command)
        # GRBL validates the line by executing it: a stored G20 is in force at once.
        for action in self._interpret(text):
            self._apply(action)

        def store() -> None:
            if 0 <= index < N_STARTUP_LINES:
                self.startup_lines[index] = text

        self._steps.add(self._sync)
        self._steps.do(store)

    def _run_startup_lines(self) -> None:
        for text in self.startup_lines:
            if not text:
                continue
            self._steps.source = text
            try:
                actions = self._interpret(text)
            except Refused as refused:
                self._steps.push(f">{text}:error:{refused.code}")
                continue
            for action in actions:
                self._apply(action)
            self._steps.push(f">{text}:ok")

    def _sleep(self) -> None:
        self._outputs_off()
        self.state = "Sleep"
        self._emit("[MSG:Sleeping]", "push", self._steps.source)

    def _homing(self) -> None:
        """$H: seek the switches at $25, pull off, locate at $24, pull off (all axes at once)."""
        travel = [self.settings[130 + i] for i in range(3)]
        pulloff = self.settings[27]
        negative = [bool(int(self.settings[23]) & (1 << i)) for i in range(3)]
        switch = tuple(-travel[i] if negative[i] else 0.0 for i in range(3))
        back = tuple(switch[i] + (pulloff if negative[i] else -pulloff) for i in range(3))
        seek, feed = self.settings[25], self.settings[24]
        phases = [(switch, seek), (back, seek), (switch, feed), (back, seek)]
        if self._homing_fails == 8:
            phases = phases[:2]  # the switch still reads pressed after the first pull-off
        elif self._homing_fails == 9:
            here = self._planner.rest
            reach = [_HOMING_SEARCH_SCALAR * t for t in travel]
            end = tuple(here[i] + (-reach[i] if negative[i] else reach[i]) for i in range(3))
            phases = [(end, seek)]  # the whole search distance, and no switch on the way

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
            if self._homing_fails is not None:
                self._homing_failed(self._homing_fails, t)
                return True
            self._planner.rest = (back[0], back[1], back[2])
            self._parser.position = list(self._planner.rest)
            self.state = "Idle"
            with self._steps.inserting():
                self._run_startup_lines()
            return True

        self._steps.add(self._sync)
        self._steps.add(begin)
        self._steps.add(finish)

    def _homing_failed(self, code: int, t: float) -> None:
        source = self._steps.source
        self._halt(t)
        self.state = "Alarm"
        self._emit(f"ALARM:{code}", "push", source)

        def reset(at: float) -> None:
            self._emit("ok", "response", source)
            self._reset(at)

        self._lock_up(t, reset)

    # -- G-code -----------------------------------------------------------------------------

    def _interpret(self, line: str) -> list[Action]:
        laser, tolerance = bool(self.settings[32]), self.settings[12]
        return interpret(line, self._parser, laser=laser, arc_tolerance=tolerance)

    def _gcode(self, line: str) -> None:
        for action in self._interpret(line):
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
                self._steps.add(self._queue_move(action))

    def _switch_spindle(self, mode: int, speed: float) -> None:
        def apply() -> None:
            self.spindle.set(mode, speed)
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

    def _queue_move(self, move: Move) -> Step:
        target = move.target

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
            block = self._planner.block_to(
                target, move.rate_min, self.settings, spindle=move.spindle, power=move.power
            )
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
