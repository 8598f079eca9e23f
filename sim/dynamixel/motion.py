"""An emulated X-series servo's motion: its velocity and acceleration units and trapezoidal moves.

:class:`TrapezoidMove` is one point-to-point move against a monotonic clock, as the servo's
Profile Velocity and Profile Acceleration shape it; the servo (:mod:`sim.dynamixel.servo`)
starts, stops and reads them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "ACCELERATION_UNIT_RPM2",
    "TICKS_PER_TURN",
    "VELOCITY_UNIT_RPM",
    "TrapezoidMove",
    "acceleration_ticks_per_s2",
    "velocity_ticks_per_s",
]

TICKS_PER_TURN = 4096
VELOCITY_UNIT_RPM = 0.229
ACCELERATION_UNIT_RPM2 = 214.577


def velocity_ticks_per_s(units: int) -> float:
    """An X-series velocity value (0.229 rpm per unit) in ticks per second."""
    return units * VELOCITY_UNIT_RPM * TICKS_PER_TURN / 60.0


def acceleration_ticks_per_s2(units: int) -> float:
    """An X-series acceleration value (214.577 rev/min^2 per unit) in ticks per second^2."""
    return units * ACCELERATION_UNIT_RPM2 * TICKS_PER_TURN / 3600.0


@dataclass(frozen=True)
class TrapezoidMove:
    """A point-to-point move: accelerate, cruise, decelerate; a triangle when too short to cruise.

    ``velocity`` in ticks/s (> 0) and ``acceleration`` in ticks/s^2 (``math.inf`` for a
    rectangular velocity profile) are the profile's limits; ``t0`` is the clock at the start.
    """

    start: float
    goal: float
    t0: float
    velocity: float
    acceleration: float

    @property
    def _shape(self) -> tuple[float, float, float]:
        """(acceleration time, cruise time, peak velocity)."""
        distance = abs(self.goal - self.start)
        if math.isinf(self.acceleration):
            return 0.0, distance / self.velocity, self.velocity
        t_acc = self.velocity / self.acceleration
        if self.acceleration * t_acc * t_acc >= distance:
            t_acc = math.sqrt(distance / self.acceleration)
            return t_acc, 0.0, self.acceleration * t_acc
        return t_acc, (distance - self.acceleration * t_acc * t_acc) / self.velocity, self.velocity

    @property
    def duration(self) -> float:
        """Seconds from start to standstill at the goal."""
        t_acc, t_cruise, _ = self._shape
        return 2.0 * t_acc + t_cruise

    @property
    def profile_bits(self) -> int:
        """Moving Status bits 4-5: 3 trapezoidal, 2 triangular, 1 rectangular."""
        t_acc, t_cruise, _ = self._shape
        return 0x10 if t_acc == 0.0 else (0x30 if t_cruise > 0.0 else 0x20)

    def position(self, t: float) -> float:
        """Position in ticks at clock ``t`` (held at the ends)."""
        t_acc, t_cruise, v_peak = self._shape
        tau = min(max(t - self.t0, 0.0), 2.0 * t_acc + t_cruise)
        a = self.acceleration
        if tau <= t_acc:
            s = 0.5 * a * tau * tau if t_acc > 0.0 else 0.0
        elif tau <= t_acc + t_cruise:
            s = 0.5 * v_peak * t_acc + v_peak * (tau - t_acc)
        else:
            rest = 2.0 * t_acc + t_cruise - tau
            s = abs(self.goal - self.start) - 0.5 * a * rest * rest
        return self.start + math.copysign(s, self.goal - self.start)

    def velocity_at(self, t: float) -> float:
        """Signed velocity in ticks/s at clock ``t``."""
        t_acc, t_cruise, v_peak = self._shape
        tau = t - self.t0
        if tau < 0.0 or tau >= 2.0 * t_acc + t_cruise:
            return 0.0
        if tau < t_acc:
            v = self.acceleration * tau
        elif tau < t_acc + t_cruise:
            v = v_peak
        else:
            v = self.acceleration * (2.0 * t_acc + t_cruise - tau)
        return math.copysign(v, self.goal - self.start)
