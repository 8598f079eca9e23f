"""GRBL 1.1's motion: the planner's blocks, their trapezoidal timing, and where the gantry is.

Each block runs a trapezoidal profile along its straight line, with GRBL's per-axis limits
(rate ``min(F, $11x / |u_i|)``, acceleration ``min($12x / |u_i|)``), from rest to rest (no
junction speed between blocks: a simplification). The planner holds :data:`PLANNER_BLOCKS`
blocks. Positions are in units (mm); GRBL counts steps, so a new steps/mm setting rescales the
rest position (:meth:`Planner.rescale`). Nothing here knows the machine's states:
:class:`sim.grbl.machine.GrblMachine` decides when a block starts, holds or is dropped.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["EPS", "PLANNER_BLOCKS", "Block", "Planner", "Profile", "Vec", "within_travel"]

PLANNER_BLOCKS = 15  # BLOCK_BUFFER_SIZE 16, one always free
EPS = 1e-9
"""Lengths, distances and speeds below this count as zero (units, units/s)."""

Vec = tuple[float, float, float]


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
        """From speed ``v0`` to rest over ``length``, cruising at most at ``v_nominal``.

        Parameters
        ----------
        length : distance to cover, units
        v0 : speed at the start, units/s
        v_nominal : the highest cruising speed, units/s
        accel : acceleration and deceleration, units/s^2

        Returns
        -------
        The profile; a uniform deceleration when ``v0`` is already too fast to accelerate.
        """
        if length <= EPS:
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
        """Decelerate uniformly from ``v0`` (units/s) to rest over ``distance`` (units)."""
        decel = v0 * v0 / (2 * distance)
        return Profile(v0, v0, decel, decel, 0.0, 0.0, distance, 0.0, 0.0, v0 / decel)

    @property
    def duration(self) -> float:
        """Time from the start to rest, s."""
        return self.t1 + self.t2 + self.t3

    @property
    def length(self) -> float:
        """Distance from the start to rest, units."""
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
class Block:
    """One planned straight move, and how far along it the gantry has come.

    Attributes
    ----------
    start, end : machine positions, units
    v_nominal : cruising speed, units/s
    accel : acceleration, units/s^2
    done : distance covered before the current profile (a hold ends one profile mid-block)
    profile : the profile in progress, None while the block stands
    t0 : when the current profile started, s
    spindle : the spindle state the block runs with (3 CW, 4 CCW, 5 off: the planner's condition
        flags)
    power : the spindle speed the block carries (0 for a laser-disabled motion: G0)
    programmed : the programmed rate, units/s (``inf`` for a rapid); laser mode's M4 scales the
        power by the speed over it
    """

    start: Vec
    end: Vec
    v_nominal: float
    accel: float
    done: float = 0.0
    profile: Profile | None = None
    t0: float = 0.0
    spindle: int = 5
    power: float = 0.0
    programmed: float = math.inf

    @property
    def length(self) -> float:
        """Distance from start to end, units."""
        return math.dist(self.start, self.end)

    def point(self, s: float) -> Vec:
        """The position ``s`` units from the start (clamped at the end)."""
        length = self.length
        f = 1.0 if length <= EPS else min(1.0, s / length)
        a, b = self.start, self.end
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))

    def start_at(self, t: float) -> Profile:
        """Set off from rest at time ``t`` over what is left of the block; returns the profile."""
        self.t0 = t
        self.profile = Profile.plan(self.length - self.done, 0.0, self.v_nominal, self.accel)
        return self.profile

    def position(self, now: float) -> Vec:
        """Position at ``now``."""
        s = 0.0 if self.profile is None else self.profile.at(now - self.t0)[0]
        return self.point(self.done + s)

    def speed(self, now: float) -> float:
        """Speed along the block at ``now``, units/s."""
        return 0.0 if self.profile is None else self.profile.at(now - self.t0)[1]

    def brake(self, now: float) -> bool:
        """Decelerate from ``now`` at the block's acceleration (a feed hold).

        Returns
        -------
        True when the block is at rest at once (it was not moving); False while braking,
        including when the profile already stops at the block's end, which it then keeps.
        """
        assert self.profile is not None
        s, v = self.profile.at(now - self.t0)
        remaining = self.length - self.done - s
        stopping = v * v / (2 * self.accel)
        if stopping >= remaining - EPS:
            return False
        self.done += s
        self.t0 = now
        self.profile = Profile.stop(v, stopping) if v > EPS else None
        return self.profile is None

    def run_out(self) -> None:
        """The profile has ended: count its distance as done and stand."""
        assert self.profile is not None
        self.done += self.profile.length
        self.profile = None


class Planner:
    """GRBL's planner buffer: the blocks in order, the first one in motion.

    Also the position the gantry rests at when none moves.

    Parameters
    ----------
    position : machine position at rest, units
    """

    def __init__(self, position: Vec) -> None:
        self.rest = position
        self.blocks: deque[Block] = deque()

    @property
    def free(self) -> int:
        """Free planner blocks (the ``Bf:`` field)."""
        return PLANNER_BLOCKS - len(self.blocks)

    @property
    def full(self) -> bool:
        """True when one more block does not fit (GRBL stops reading lines)."""
        return len(self.blocks) >= PLANNER_BLOCKS

    def block_to(
        self,
        target: Vec,
        rate_min: float,
        settings: Mapping[int, float],
        *,
        spindle: int = 5,
        power: float = 0.0,
    ) -> Block:
        """A block from the last planned target to ``target``, not yet queued.

        Parameters
        ----------
        target : machine position, units
        rate_min : requested feed rate, units/min (``inf`` for a rapid)
        settings : GRBL settings, for the per-axis rates ``$11x`` and accelerations ``$12x``
        spindle, power : the spindle state and speed the block carries (see :class:`Block`)
        """
        start = tuple(self.blocks[-1].end if self.blocks else self.rest)
        delta = [t - s for s, t in zip(start, target, strict=True)]
        length = math.hypot(*delta)
        rate, accel = rate_min / 60.0, math.inf
        for axis, d in enumerate(delta):
            if abs(d) > EPS:
                share = abs(d) / length
                rate = min(rate, settings[110 + axis] / 60.0 / share)
                accel = min(accel, settings[120 + axis] / share)
        return Block(
            (start[0], start[1], start[2]),
            target,
            rate,
            accel,
            spindle=spindle,
            power=power,
            programmed=rate_min / 60.0,
        )

    def finish(self, block: Block) -> None:
        """``block``, the first, has reached its end: rest there and drop it."""
        self.rest = block.end
        self.blocks.popleft()

    def settle(self, block: Block) -> None:
        """``block``, the first, has stopped in a hold: rest there, and drop it if at its end."""
        self.rest = block.point(block.done)
        if block.done >= block.length - EPS:
            self.blocks.popleft()

    def rescale(self, axis: int, factor: float) -> None:
        """Multiply the rest position of ``axis`` by ``factor`` (its steps/mm changed).

        GRBL keeps the position in steps, so a new ``$10x`` changes what the same steps mean
        in units; only done at rest (``$`` settings need Idle or Alarm).
        """
        rest = list(self.rest)
        rest[axis] *= factor
        self.rest = (rest[0], rest[1], rest[2])

    def clear(self, position: Vec) -> None:
        """Drop every block and rest at ``position`` (an alarm or a reset)."""
        self.rest = position
        self.blocks.clear()


def within_travel(target: Vec, settings: Mapping[int, float]) -> bool:
    """True when ``target`` is inside the soft limits of the ``$13x`` travels."""
    # GRBL's machine space is -max_travel .. 0 on every axis (homing toward +, the default).
    return all(-settings[130 + i] - EPS <= target[i] <= EPS for i in range(3))
