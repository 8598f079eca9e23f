"""Fault injection for the emulated Dynamixel chain: what to inject, and when it strikes.

:class:`FaultConfig` says which faults to inject (lost instruction packets, dropped, corrupted
and delayed replies, a servo that falls silent, an overload after N moves); a
:class:`FaultInjector` applies one config to the chain's traffic, deterministically for its seed,
and logs the reply faults. Reply faults act on status packets after the instruction was
executed, so a dropped reply to a WRITE leaves the write done.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from sim.dynamixel.protocol import Packet

__all__ = ["FaultConfig", "FaultInjector"]


@dataclass(frozen=True)
class FaultConfig:
    """Faults to inject; the defaults inject none. Deterministic for a given ``seed``.

    ``lose_first`` = N: the first N instruction packets are lost on the way in (neither
    executed nor answered). Reply faults (drop, corrupt, delay) act on status packets after
    the instruction was executed, so a dropped reply to a WRITE leaves the write done: an
    "unknown outcome". The ``*_first`` counts hit the first N replies; the probabilities then
    apply to every reply. ``instructions`` restricts lost packets and reply faults to those
    instruction codes (empty: all).
    A servo in ``silent_ids`` answers ``silent_after`` instructions, then neither executes nor
    answers anything. ``overload_after_moves`` = N: each servo (or those in ``overload_ids``)
    completes N moves, then overloads half-way through the next (torque off, alert bit set,
    Hardware Error Status 0x20 until a reboot).
    """

    seed: int = 0
    lose_first: int = 0
    drop_first: int = 0
    drop_probability: float = 0.0
    corrupt_first: int = 0
    corrupt_probability: float = 0.0
    delay_s: float = 0.0
    delay_first: int = 0
    delay_probability: float = 0.0
    instructions: frozenset[int] = frozenset()
    silent_ids: frozenset[int] = frozenset()
    silent_after: int = 0
    overload_after_moves: int | None = None
    overload_ids: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        for name in ("drop_probability", "corrupt_probability", "delay_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"FaultConfig.{name} must be in [0, 1]")
        if self.delay_s < 0.0:
            raise ValueError("FaultConfig.delay_s must be >= 0")


class FaultInjector:
    """One :class:`FaultConfig` at work: its random stream, its counts and its log.

    Parameters
    ----------
    config
        The faults to inject; a fresh injector starts their counts and random stream anew.

    Attributes
    ----------
    config
        The faults injected.
    log
        (reply index, "dropped" | "corrupted" | "delayed") for every reply fault so far.
    """

    def __init__(self, config: FaultConfig) -> None:
        self.config = config
        self._rng = random.Random(config.seed)
        self._replies = 0
        self._lost = 0
        self.log: list[tuple[int, str]] = []

    def overload_after(self, servo_id: int) -> int | None:
        """The moves after which servo ``servo_id`` overloads; None when it never does."""
        faults = self.config
        targeted = not faults.overload_ids or servo_id in faults.overload_ids
        return faults.overload_after_moves if targeted else None

    def silences(self, servo_id: int, instructions_seen: int) -> bool:
        """Whether servo ``servo_id``, at its ``instructions_seen``-th instruction, is silent."""
        faults = self.config
        return servo_id in faults.silent_ids and instructions_seen > faults.silent_after

    def lose(self, packet: Packet) -> bool:
        """Whether ``packet`` is lost on the way in (neither executed nor answered)."""
        faults = self.config
        if self._lost >= faults.lose_first:
            return False
        if faults.instructions and packet.instruction not in faults.instructions:
            return False
        self._lost += 1
        return True

    def reply(self, instruction: int, reply: bytes) -> tuple[bytes, float]:
        """Return (bytes to send, delay before sending); empty bytes for a dropped reply."""
        faults = self.config
        if faults.instructions and instruction not in faults.instructions:
            return reply, 0.0
        index = self._replies
        self._replies += 1
        rng = self._rng
        if index < faults.drop_first or (
            faults.drop_probability and rng.random() < faults.drop_probability
        ):
            self.log.append((index, "dropped"))
            return b"", 0.0
        if index < faults.corrupt_first or (
            faults.corrupt_probability and rng.random() < faults.corrupt_probability
        ):
            self.log.append((index, "corrupted"))
            reply = reply[:-2] + bytes([reply[-2] ^ 0xFF, reply[-1]])
        delayed = index < faults.delay_first or (
            faults.delay_probability and rng.random() < faults.delay_probability
        )
        if delayed:
            self.log.append((index, "delayed"))
        return reply, faults.delay_s if delayed else 0.0
