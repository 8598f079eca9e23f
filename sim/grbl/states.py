"""GRBL 1.1's machine states and the events that change them: motion, holds, alarms, resets.

The part of the machine that real-time commands and inputs act on, below the lines
(:class:`sim.grbl.machine.GrblMachine` adds those): the planner's blocks running on a clock the
caller passes, feed hold and cycle start, alarms, soft resets and their banner, the limit
switches (:mod:`sim.grbl.limits`), the spindle and coolant outputs (:mod:`sim.grbl.spindle`) and
the status report (:mod:`sim.grbl.report`). Output lines go through ``emit(text, kind, source)``.

As GRBL 1.1h (``protocol.c``, ``limits.c``, ``motion_control.c``, ``report.c``):

- feed hold decelerates at the block's acceleration (``Hold:1``, then ``Hold:0``); ``~``
  resumes; in laser mode a completed hold switches the laser off and ``~`` prints
  ``[MSG:Restoring spindle]`` (the next block switches it on again);
- an ``ALARM:N`` line is followed by GRBL's 500 ms pause (``report_alarm_message``,
  ``critical_message_delay_s`` here) in which nothing is served. After ALARM:1 (hard limit) or
  ALARM:2 (soft limit) comes ``[MSG:Reset to continue]``; a soft reset before it is discarded,
  one after it resets. ALARM:3 and ALARM:6 (a reset cutting motion or homing) are followed by
  the banner at once: a simplification;
- a soft reset stops everything, keeps the position, prints the banner, then ``[MSG:Check
  Limits]`` if a switch is pressed with ``$21=1``, then ``[MSG:'$H'|'$X' to unlock]`` in Alarm
  (also after Sleep, which wakes as Alarm), or else runs the startup lines;
- with ``$21=1`` every edge of a limit switch outside Alarm and homing raises ALARM:1.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from sim.grbl.gcode import ModalState
from sim.grbl.limits import LimitPins
from sim.grbl.motion import Block, Planner, Vec
from sim.grbl.report import StatusReporter
from sim.grbl.settings import settings_with
from sim.grbl.spindle import SpindleOutput
from sim.grbl.steps import Emit, LineSteps

__all__ = ["BANNER", "MachineStates"]

BANNER = "Grbl 1.1h ['$' for help]"

_LOCKED = "[MSG:'$H'|'$X' to unlock]"


class MachineStates:
    """GRBL's states, motion, alarms and resets; see the module docstring.

    Parameters
    ----------
    settings : overrides of :data:`sim.grbl.settings.DEFAULT_SETTINGS`
    emit : ``emit(text, kind, source)`` receives every output line
    hard_limit_after_moves : raise ALARM:1 half-way through this motion block (1-based count
        since start; fault injection), or None
    position : machine position at power-up (where the gantry was left; GRBL does not know it
        until homed, and takes it as is), units
    critical_message_delay_s : GRBL's pause after an ALARM line before it goes on (500 ms)
    """

    def __init__(
        self,
        settings: Mapping[int, float] | None,
        emit: Emit,
        *,
        hard_limit_after_moves: int | None = None,
        position: Vec = (0.0, 0.0, 0.0),
        critical_message_delay_s: float = 0.5,
    ) -> None:
        self.settings = settings_with(settings)
        self._emit = emit
        self.state = "Idle"  # Idle, Run, Hold, Home, Alarm, Sleep
        self.hold_complete = False
        self.critical = False
        """True while nothing but a soft reset (and, after the pause, not even that) is served."""
        self.spindle = SpindleOutput(self.settings)
        self.flood = False
        self.mist = False
        self.limits = LimitPins()
        self.moves_started = 0
        self.resets = 0
        """Soft resets so far, GRBL's own after a failed homing included."""
        self._planner = Planner(position)
        self._steps = LineSteps(emit)
        self._parser = ModalState(position=list(position))
        self._reports = StatusReporter()
        self._soft_limit_pending = False
        self._ok_after_reset = ""
        self._hard_limit_after = hard_limit_after_moves
        self._hard_limit_at: float | None = None
        self._alarm_pause = critical_message_delay_s
        self._after_pause: tuple[float, Callable[[float], None]] | None = None
        self._reset_blocked = False
        self._laser_held = False

    # -- observation ------------------------------------------------------------------------

    @property
    def accepting_lines(self) -> bool:
        """True when GRBL would read the next line (none in progress, not locked up, awake)."""
        return not self._steps.pending and not self.critical and self.state != "Sleep"

    @property
    def responsive(self) -> bool:
        """True when GRBL answers status requests (not after an alarm, not homing)."""
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
        spindle, spindle_speed = self.spindle.state(now)
        return self._reports.report(
            state=self.state_text(),
            busy=self.state in ("Run", "Hold", "Home"),
            mask=int(self.settings[10]),
            position=self.position(now),
            wco=self.wco(),
            buffers=(self.planner_free, rx_free),
            feed=self.speed(now),
            spindle=spindle,
            spindle_speed=spindle_speed,
            flood=self.flood,
            mist=self.mist,
            pins=self.limits.text(),
            inches=bool(self.settings[13]),
        )

    # -- events -----------------------------------------------------------------------------

    def power_up(self, now: float) -> None:
        """Start as GRBL does: Alarm when homing is enabled (HOMING_INIT_LOCK)."""
        if self.settings[22]:
            self.state = "Alarm"
        self._greet(now)

    def soft_reset(self, now: float) -> bool:
        """Ctrl-X: stop everything, keep the position, alarm if motion was cut.

        Returns
        -------
        False when GRBL discards the reset: during the pause after an alarm, before it serves
        resets again (``protocol.c`` clears any pending reset then).
        """
        self.update(now)
        if self._reset_blocked:
            return False
        if self.state == "Home":
            self._emit("ALARM:6", "push", "")
            self.state = "Alarm"
        elif self.state == "Run" or (self.state == "Hold" and not self.hold_complete):
            self._emit("ALARM:3", "push", "")
            self.state = "Alarm"
        self._reset(now)
        return True

    def feed_hold(self, now: float) -> None:
        """``!``: decelerate to a stop at the block's acceleration."""
        if self.critical or self.state in ("Alarm", "Home", "Hold", "Sleep"):
            return
        self.update(now)
        if self.state == "Idle":
            self.state, self.hold_complete = "Hold", True
            self._hold_done()
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
        if self._laser_held:
            self._laser_held = False
            self._emit("[MSG:Restoring spindle]", "push", "")
        if self._planner.blocks:
            self.state = "Run"
            self._start(self._planner.blocks[0], now, count=False)
        else:
            self.state = "Idle"
        self._run_steps(now)

    def limit_switch(self, letter: str, pressed: bool, now: float) -> None:
        """A limit switch changes: with ``$21=1`` an edge outside Alarm and homing is ALARM:1."""
        if not self.limits.set(letter, pressed):
            return
        self.update(now)
        if self.settings[21] and self.state not in ("Alarm", "Home"):
            self.raise_alarm(1, now, advance=False)

    def raise_alarm(self, code: int, now: float, *, advance: bool = True) -> None:
        """Stop at once and raise ``ALARM:code``; codes 1 and 2 lock GRBL until a reset."""
        if advance:
            self.update(now)
        self._halt(now)
        self.state = "Alarm"
        self._emit(f"ALARM:{code}", "push", self._steps.source)
        if code in (1, 2):
            self._lock_up(now, self._critical_message)

    def update(self, now: float) -> None:
        """Advance the pause after an alarm, motion, dwells and waiting lines to ``now``."""
        if self._after_pause is not None:
            due, then = self._after_pause
            if now < due:
                return
            self._after_pause = None
            then(due)
        while not self.critical:
            block = self._active_block()
            if block is None or block.profile is None:
                break
            end = block.t0 + block.profile.duration
            if self._hard_limit_at is not None and self._hard_limit_at <= min(end, now):
                at, self._hard_limit_at = self._hard_limit_at, None
                self.limits.trip("X")
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
                self.spindle.motion_ended()
            self._run_steps(end)
        self._run_steps(now)

    # -- internals --------------------------------------------------------------------------

    def _run_startup_lines(self) -> None:
        """Run the startup lines after a reset into Idle (the lines' machine adds them)."""

    def _lock_up(self, now: float, then: Callable[[float], None]) -> None:
        """Serve nothing, resets included, for GRBL's pause after an ALARM line; then ``then``."""
        self.critical = True
        self._reset_blocked = True
        self._after_pause = (now + self._alarm_pause, then)
        self.update(now)

    def _critical_message(self, t: float) -> None:
        self._emit("[MSG:Reset to continue]", "push", self._steps.source)
        self._reset_blocked = False

    def _reset(self, now: float) -> None:
        self.resets += 1
        self._planner.clear(self.position(now))
        self._steps.clear()
        self._soft_limit_pending = False
        self._hard_limit_at = None
        self._after_pause = None
        self.critical = self._reset_blocked = self._laser_held = False
        if self._ok_after_reset:
            self._emit("ok", "response", self._ok_after_reset)
            self._ok_after_reset = ""
        self._outputs_off()
        self._parser = ModalState(position=list(self._planner.rest))
        self._reports = StatusReporter()
        self.limits.reset()
        if self.state not in ("Alarm", "Sleep"):
            self.state = "Idle"
        self.hold_complete = False
        self._greet(now)

    def _greet(self, now: float) -> None:
        self._emit(BANNER, "push", "")
        if self.settings[21] and self.limits.engaged:
            self.state = "Alarm"
            self._emit("[MSG:Check Limits]", "push", "")
        if self.state in ("Alarm", "Sleep"):
            self.state = "Alarm"  # sleep loses the position: GRBL wakes locked
            self._emit(_LOCKED, "push", "")
        else:
            self._run_startup_lines()
            self._run_steps(now)

    def _active_block(self) -> Block | None:
        if self.state in ("Run", "Hold", "Home") and self._planner.blocks:
            return self._planner.blocks[0]
        return None

    def _start(self, block: Block, t: float, *, count: bool = True) -> None:
        profile = block.start_at(t)
        self.spindle.block_started(block)
        if count and self.state != "Home":
            self.moves_started += 1
            if self.moves_started == self._hard_limit_after:
                self._hard_limit_at = t + 0.5 * profile.duration

    def _hold_stopped(self, block: Block, t: float) -> None:
        self._planner.settle(block)
        self.hold_complete = True
        self._hold_done()
        if self._soft_limit_pending:
            self._soft_limit_alarm(t)

    def _hold_done(self) -> None:
        # DISABLE_LASER_DURING_HOLD (on by default): a stopped laser must not burn.
        if self.spindle.laser and self._parser.spindle != 5:
            self.spindle.set(5, 0.0)
            self._laser_held = True
            self._reports.refresh_overrides()

    def _halt(self, now: float) -> None:
        self._planner.clear(self.position(now))
        self._steps.clear()
        self._outputs_off()
        self._parser.spindle, self._parser.mist, self._parser.flood = 5, False, False

    def _outputs_off(self) -> None:
        self.spindle.set(5, 0.0)
        self.flood = self.mist = False

    def _soft_limit_alarm(self, now: float) -> None:
        self._soft_limit_pending = False
        source = self._steps.source
        self.raise_alarm(2, now, advance=False)
        self._ok_after_reset = source or "?"  # GRBL answers the line only after the reset

    def _run_steps(self, t: float) -> None:
        self._steps.run(t, lambda: self.critical)
