"""GRBL 1.1's G-code subset: words, modal groups, the modal state, and what a block asks for.

:func:`interpret` checks a filtered line as ``gcode.c`` does, in GRBL's order, and refuses it
with :class:`sim.grbl.words.Refused` (``error:N``) before changing anything; a valid line
updates the :class:`ModalState` and returns the :data:`Action` s the machine is to carry out,
in GRBL's order of execution. The subset: G0/G1 with F, G2/G3 arcs (:mod:`sim.grbl.arcs`),
G90/G91, G20/G21, G53, G92/G92.1, G4, G17-19, G54-59 (offsets zero), G94, M3/M4/M5 with S,
M7/M8/M9, T. Probing, G10/G28/G30, tool length offsets and the other words are refused
(``error:20``, or ``error:36`` for unused words).

Spindle and coolant changes are synchronised (the machine waits for the planner to empty)
only when they change the modal state, as ``gcode.c`` does: a second ``M8`` answers at once.
In laser mode (``$32=1``) a block carries its laser power to the planner and the power is
applied as the block runs; motion modes other than G1/G2/G3 carry zero power (``gcode.c``'s
``GC_PARSER_LASER_*`` flags).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sim.grbl.arcs import arc_offset, arc_points
from sim.grbl.motion import Vec
from sim.grbl.words import Refused, words

__all__ = [
    "Action",
    "CoolantChange",
    "Dwell",
    "ModalState",
    "Move",
    "OffsetChange",
    "SpindleChange",
    "interpret",
    "modal_report",
]

_VALUE_LETTERS = frozenset("FSPNTXYZIJKLR")
_M_GROUPS = {3: "spindle", 4: "spindle", 5: "spindle", 7: "coolant", 8: "coolant", 9: "coolant"}
_G_GROUPS = {
    0: "motion", 1: "motion", 2: "motion", 3: "motion", 80: "motion", 90: "distance",
    91: "distance", 20: "units", 21: "units", 17: "plane", 18: "plane", 19: "plane",
    94: "feedmode", 4: "nonmodal", 53: "nonmodal", 92: "nonmodal", 54: "wcs", 55: "wcs",
    56: "wcs", 57: "wcs", 58: "wcs", 59: "wcs",
}  # fmt: skip
_FEED_MOTIONS = frozenset({1, 2, 3})  # need F; the only laser-powered ones
_MM_PER_INCH = 25.4


@dataclass
class ModalState:
    """The G-code parser's modal state (GRBL's ``gc_state``).

    Attributes
    ----------
    motion : 0, 1, 2, 3 or 80
    absolute : G90 (True) or G91
    inches : G20 (True) or G21
    plane : 17, 18 or 19
    wcs : 54..59
    feed : machine units/min (an F word under G20 is converted from inches)
    speed : the last S word
    tool : the last T word
    spindle : M3 (3), M4 (4) or M5 (5), as programmed (the output may differ: laser mode)
    mist, flood : M7, M8 (M9 clears both)
    position : the parser's machine position, the target of the last planned move, units
    g92 : the G92 offset, units
    """

    motion: int = 0
    absolute: bool = True
    inches: bool = False
    plane: int = 17
    wcs: int = 54
    feed: float = 0.0
    speed: float = 0.0
    tool: int = 0
    spindle: int = 5
    mist: bool = False
    flood: bool = False
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    g92: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


@dataclass(frozen=True)
class SpindleChange:
    """Set the spindle (3 CW, 4 CCW, 5 off) to ``speed``, once the planner is empty.

    ``speed`` is what ``spindle_sync`` is passed: zero for a laser-disabled motion mode.
    """

    mode: int
    speed: float


@dataclass(frozen=True)
class CoolantChange:
    """Switch coolant (7 mist on, 8 flood on, 9 both off), once the planner is empty."""

    mode: int


@dataclass(frozen=True)
class Dwell:
    """G4: wait ``seconds`` once the planner is empty."""

    seconds: float


@dataclass(frozen=True)
class OffsetChange:
    """G92 or G92.1 changed the work offset (the next status report shows ``WCO``)."""


@dataclass(frozen=True)
class Move:
    """Plan a straight move to ``target`` at ``rate_min``.

    ``target`` is a machine position, units; ``rate_min`` is in units/min (``inf`` for G0);
    ``spindle`` and ``power`` are the spindle state and speed the block carries (laser mode
    applies them as the block runs).
    """

    target: Vec
    rate_min: float
    spindle: int = 5
    power: float = 0.0


Action = SpindleChange | CoolantChange | Dwell | OffsetChange | Move
"""What one G-code line asks of the machine."""


def interpret(
    line: str, modal: ModalState, *, laser: bool = False, arc_tolerance: float = 0.002
) -> list[Action]:
    """Check one filtered G-code line, update the modal state and say what is to be done.

    Parameters
    ----------
    line : the filtered line (upper case, no spaces or comments), not a ``$`` command
    modal : the parser's modal state, updated in place when the line is valid
    laser : laser mode (``$32=1``)
    arc_tolerance : ``$12``, for cutting arcs into segments, units

    Returns
    -------
    The actions, in GRBL's order of execution (an arc is one :class:`Move` per segment).

    Raises
    ------
    Refused
        With GRBL's status code, before ``modal`` is changed.
    """
    groups: dict[str, float] = {}
    values: dict[str, float] = {}
    for letter, value in words(line):
        if letter == "G":
            group = _g_group(value)
            if group in groups:
                raise Refused(21)
            groups[group] = value
        elif letter == "M":
            if value != int(value):
                raise Refused(23)
            m_group = _M_GROUPS.get(int(value))
            if m_group is None:
                raise Refused(20)
            if m_group in groups:
                raise Refused(21)
            groups[m_group] = value
        elif letter in _VALUE_LETTERS:
            if letter in values:
                raise Refused(25)
            if letter in "FNPST" and value < 0:
                raise Refused(4)
            values[letter] = value
        else:
            raise Refused(20)
    return _execute(groups, values, modal, laser, arc_tolerance)


def modal_report(modal: ModalState, *, report_inches: bool = False) -> str:
    """The ``$G`` line, ``[GC:...]``; F in inch/min with ``$13=1`` (``report_inches``)."""
    p = modal
    spindle_word = {3: "M3", 4: "M4"}.get(p.spindle, "M5")
    coolant = " ".join(m for m, on in (("M7", p.mist), ("M8", p.flood)) if on) or "M9"
    feed = f"{p.feed / _MM_PER_INCH:.1f}" if report_inches else f"{p.feed:.0f}"
    return (
        f"[GC:G{p.motion} G{p.wcs} G{p.plane} {'G20' if p.inches else 'G21'} "
        f"{'G90' if p.absolute else 'G91'} G94 {spindle_word} {coolant} T{p.tool} "
        f"F{feed} S{p.speed:.0f}]"
    )


def _execute(
    groups: dict[str, float],
    values: dict[str, float],
    p: ModalState,
    laser: bool,
    arc_tolerance: float,
) -> list[Action]:
    if "N" in values and values["N"] > 9999999:
        raise Refused(27)
    if "T" in values and values["T"] > 255:
        raise Refused(38)
    nonmodal = groups.get("nonmodal")
    if nonmodal == 4 and "P" not in values:
        raise Refused(28)
    axes = {letter: values[letter] for letter in "XYZ" if letter in values}
    motion = int(groups.get("motion", p.motion))
    inches = groups["units"] == 20 if "units" in groups else p.inches
    scale = _MM_PER_INCH if inches else 1.0
    if nonmodal == 92 and "motion" in groups and axes:
        raise Refused(24)
    if nonmodal == 92 and not axes:
        raise Refused(26)
    moving = nonmodal not in (92, 92.1) and (bool(axes) or "motion" in groups)
    if nonmodal == 53 and motion not in (0, 1):
        raise Refused(30)
    if moving and motion == 80 and axes:
        raise Refused(31)
    feed = values["F"] * scale if "F" in values else p.feed
    if moving and motion in _FEED_MOTIONS and feed <= 0:
        raise Refused(22)
    absolute = groups["distance"] == 90 if "distance" in groups else p.absolute
    target = _target(axes, nonmodal, absolute, p, scale)
    plane = int(groups.get("plane", p.plane))
    used = set("NFSTXYZ")
    if nonmodal == 4:
        used.add("P")
    arc: tuple[Vec, float] | None = None
    if moving and motion in (2, 3):
        radius = values["R"] * scale if "R" in values else None
        offsets = {i: values[c] * scale for i, c in enumerate("IJK") if c in values}
        used.update("R" if radius is not None else "IJK")
        axis_words = frozenset("XYZ".index(letter) for letter in axes)
        arc = arc_offset(_vec(p.position), target, plane, axis_words, offsets, radius, motion == 2)
    if set(values) - used:
        raise Refused(36)
    # Everything checked: change the modal state (GRBL's order of execution).
    laser_off, laser_motion, force_sync = _laser_flags(laser, motion, p, moving and bool(axes))
    actions: list[Action] = []
    p.feed = feed
    speed = values.get("S", p.speed)
    if (speed != p.speed or force_sync) and p.spindle != 5 and not laser_motion:
        actions.append(SpindleChange(p.spindle, 0.0 if laser_off else speed))
    p.speed = speed
    power = 0.0 if laser_off else speed
    if "T" in values:
        p.tool = int(values["T"])
    if "spindle" in groups and int(groups["spindle"]) != p.spindle:
        p.spindle = int(groups["spindle"])
        actions.append(SpindleChange(p.spindle, power))
    if "coolant" in groups:
        mode = int(groups["coolant"])
        mist, flood = (False, False) if mode == 9 else (p.mist or mode == 7, p.flood or mode == 8)
        if (mist, flood) != (p.mist, p.flood):
            p.mist, p.flood = mist, flood
            actions.append(CoolantChange(mode))
    if nonmodal == 4:
        actions.append(Dwell(values["P"]))
    p.plane = plane
    p.inches = inches
    if "wcs" in groups:
        p.wcs = int(groups["wcs"])
    p.absolute = absolute
    if "motion" in groups:
        p.motion = motion
    if nonmodal == 92:
        for letter, value in axes.items():
            i = "XYZ".index(letter)
            p.g92[i] = p.position[i] - value * scale
        actions.append(OffsetChange())
    elif nonmodal == 92.1:
        p.g92 = [0.0, 0.0, 0.0]
        actions.append(OffsetChange())
    elif arc is not None:
        points = arc_points(
            _vec(p.position), target, arc[0], arc[1], plane, motion == 2, arc_tolerance
        )
        actions.extend(Move(point, feed, p.spindle, power) for point in points)
        p.position = list(target)
    elif moving and axes and motion in (0, 1):
        p.position = list(target)
        rate = math.inf if motion == 0 else feed
        actions.append(Move(target, rate, p.spindle, power))
    return actions


def _target(
    axes: dict[str, float], nonmodal: float | None, absolute: bool, p: ModalState, scale: float
) -> Vec:
    target = list(p.position)
    for letter, value in axes.items():
        i = "XYZ".index(letter)
        if nonmodal == 53:
            target[i] = value * scale
        elif absolute:
            target[i] = value * scale + p.g92[i]
        else:
            target[i] = p.position[i] + value * scale
    return _vec(target)


def _laser_flags(
    laser: bool, motion: int, p: ModalState, with_axes: bool
) -> tuple[bool, bool, bool]:
    """``gcode.c``'s laser flags: (laser disabled, motion carries power, force a sync)."""
    if not laser:
        return False, False, False
    disabled = motion not in _FEED_MOTIONS
    if with_axes:
        return disabled, True, False
    # M3 keeps a constant power, so switching between a powered and an unpowered motion mode
    # without moving has to set the output now.
    force = p.spindle == 3 and (disabled if p.motion in _FEED_MOTIONS else not disabled)
    return disabled, False, force


def _vec(values: list[float]) -> Vec:
    return (values[0], values[1], values[2])


def _g_group(value: float) -> str:
    if abs(value - 92.1) < 1e-6:
        return "nonmodal"
    code = int(value)
    if code not in _G_GROUPS:
        raise Refused(20)
    if value != code:
        raise Refused(23)
    return _G_GROUPS[code]
