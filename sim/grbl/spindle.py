"""GRBL 1.1's spindle output: what the PWM pin runs at, and how laser mode (``$32=1``) drives it.

``spindle_control.c`` turns a programmed speed into the output: ``$30`` and above is full
speed, zero is off, anything between ``0`` and ``$31`` runs at ``$31``; that speed is what a
status report's ``FS`` shows, and the ``A:S``/``A:C`` field appears only while the PWM is on.

Without laser mode the output follows every (synchronised) spindle command. In laser mode the
step generator (``stepper.c``) sets the output from each planner block as it starts: M3 keeps
that constant power (also after the motion stops), M4 scales it with the current speed over
the programmed rate and goes dark when motion ends, and a spindle command while idle sets M4
dark (and M3 to the power of the motion mode: zero under G0). A completed feed hold switches a
laser off (``DISABLE_LASER_DURING_HOLD``); the next block switches it on again.
"""

from __future__ import annotations

from collections.abc import Mapping

from sim.grbl.motion import Block

__all__ = ["SpindleOutput", "pwm_speed"]


def pwm_speed(rpm: float, settings: Mapping[int, float]) -> tuple[float, bool]:
    """``spindle_compute_pwm_value``: (the speed the output runs at, whether the PWM is on)."""
    top, bottom = settings[30], settings[31]
    if bottom >= top or rpm >= top:
        return top, True
    if rpm <= bottom:
        return (0.0, False) if rpm == 0 else (bottom, True)
    return rpm, True


class SpindleOutput:
    """The spindle's direction pin and PWM, as ``spindle_get_state`` and ``sys.spindle_speed``.

    Parameters
    ----------
    settings : the machine's settings (read live: ``$30``, ``$31``, ``$32``)
    """

    def __init__(self, settings: Mapping[int, float]) -> None:
        self._settings = settings
        self._direction = 5  # 3 CW, 4 CCW; 5 when stopped
        self._speed = 0.0
        self._on = False
        self._dynamic: Block | None = None  # the M4 laser block setting the power now

    @property
    def laser(self) -> bool:
        """Laser mode (``$32=1``)."""
        return bool(self._settings[32])

    def state(self, now: float) -> tuple[int, float]:
        """(3 CW, 4 CCW or 5 when the PWM is off; ``sys.spindle_speed``) at ``now``."""
        block = self._dynamic
        if block is not None:
            speed, on = pwm_speed(block.power * block.speed(now) / block.programmed, self._settings)
            return (4 if on else 5), speed
        return (self._direction if self._on else 5), self._speed

    def set(self, mode: int, rpm: float) -> None:
        """``spindle_set_state``: M5 stops it, M3/M4 run at ``rpm`` (a laser's M4 at zero)."""
        self._dynamic = None
        if mode == 5:
            self._direction, self._speed, self._on = 5, 0.0, False
            return
        if self.laser and mode == 4:
            rpm = 0.0  # dynamic power: dark until a block moves
        self._direction = mode
        self._speed, self._on = pwm_speed(rpm, self._settings)

    def block_started(self, block: Block) -> None:
        """A block starts (or resumes): in laser mode its power sets the output."""
        if not self.laser:
            return
        if block.spindle == 5:
            self.set(5, 0.0)
        elif block.spindle == 4:
            self._direction = 4
            self._dynamic = block
        else:
            self.set(3, block.power)

    def motion_ended(self) -> None:
        """The planner ran empty: an M4 laser goes dark (its power had fallen to zero)."""
        if self._dynamic is not None:
            self._dynamic = None
            self._speed, self._on = 0.0, False
