"""GRBL 1.1's G-code subset: words, modal groups, the modal state, and what a block asks for.

:func:`interpret` checks a filtered line as ``gcode.c`` does, in GRBL's order, and refuses it
with :class:`Refused` (``error:N``) before changing anything; a valid line updates the
:class:`ModalState` and returns the :data:`Action` s the machine is to carry out, in GRBL's
order of execution. The subset: G0/G1 with F, G90/G91, G20/G21, G53, G92/G92.1, G4, G17-19,
G54-59 (offsets zero), G94, M3/M4/M5 with S, M7/M8/M9, T. Arcs, probing, G10/G28/G30, tool
length offsets and the other words are refused (``error:20``, or ``error:36`` for unused words).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from sim.grbl_motion import Vec

__all__ = [
    "NUMBER",
    "Action",
    "CoolantChange",
    "Dwell",
    "ModalState",
    "Move",
    "OffsetChange",
    "Refused",
    "SpindleChange",
    "interpret",
    "modal_report",
]

NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)")
"""A number as GRBL's ``read_float`` takes it (G-code words and ``$`` settings alike)."""

_VALUE_LETTERS = frozenset("FSPNTXYZIJKLR")
_M_GROUPS = {3: "spindle", 4: "spindle", 5: "spindle", 7: "coolant", 8: "coolant", 9: "coolant"}
_G_GROUPS = {
    0: "motion", 1: "motion", 80: "motion", 90: "distance", 91: "distance", 20: "units",
    21: "units", 17: "plane", 18: "plane", 19: "plane", 94: "feedmode", 4: "nonmodal",
    53: "nonmodal", 92: "nonmodal", 54: "wcs", 55: "wcs", 56: "wcs", 57: "wcs", 58: "wcs",
    59: "wcs",
}  # fmt: skip


class Refused(Exception):
    """A line GRBL answers with ``error:code`` instead of ``ok``.

    Parameters
    ----------
    code : GRBL's status code
    """

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


@dataclass
class ModalState:
    """The G-code parser's modal state (GRBL's ``gc_state``).

    Attributes
    ----------
    motion : 0, 1 or 80
    absolute : G90 (True) or G91
    inches : G20 (True) or G21
    plane : 17, 18 or 19
    wcs : 54..59
    feed : machine units/min (an F word under G20 is converted from inches)
    speed : the last S word
    tool : the last T word
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
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    g92: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


@dataclass(frozen=True)
class SpindleChange:
    """Switch the spindle (3 CW, 4 CCW, 5 off) at ``speed``, once the planner is empty."""

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

    ``target`` is a machine position, units; ``rate_min`` is in units/min (``inf`` for G0).
    """

    target: Vec
    rate_min: float


Action = SpindleChange | CoolantChange | Dwell | OffsetChange | Move
"""What one G-code line asks of the machine."""


def interpret(line: str, modal: ModalState, spindle: int) -> list[Action]:
    """Check one filtered G-code line, update the modal state and say what is to be done.

    Parameters
    ----------
    line : the filtered line (upper case, no spaces or comments), not a ``$`` command
    modal : the parser's modal state, updated in place when the line is valid
    spindle : the spindle's current mode (3, 4 or 5): an S word alone changes a running
        spindle's speed

    Returns
    -------
    The actions, in GRBL's order of execution.

    Raises
    ------
    Refused
        With GRBL's status code, before ``modal`` is changed.
    """
    groups: dict[str, float] = {}
    values: dict[str, float] = {}
    for letter, value in _words(line):
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
    return _execute(groups, values, modal, spindle)


def modal_report(modal: ModalState, spindle: int, mist: bool, flood: bool) -> str:
    """The ``$G`` line, ``[GC:...]``, with the spindle and coolant as they are switched."""
    p = modal
    spindle_word = {3: "M3", 4: "M4"}.get(spindle, "M5")
    coolant = " ".join(m for m, on in (("M7", mist), ("M8", flood)) if on) or "M9"
    return (
        f"[GC:G{p.motion} G{p.wcs} G{p.plane} {'G20' if p.inches else 'G21'} "
        f"{'G90' if p.absolute else 'G91'} G94 {spindle_word} {coolant} T{p.tool} "
        f"F{p.feed:.0f} S{p.speed:.0f}]"
    )


def _execute(
    groups: dict[str, float], values: dict[str, float], p: ModalState, spindle: int
) -> list[Action]:
    if "N" in values and values["N"] > 9999999:
        raise Refused(27)
    if "T" in values and values["T"] > 255:
        raise Refused(38)
    for letter in "IJKLR":
        if letter in values:
            raise Refused(36)
    nonmodal = groups.get("nonmodal")
    if "P" in values and nonmodal != 4:
        raise Refused(36)
    if nonmodal == 4 and "P" not in values:
        raise Refused(28)
    axes = {letter: values[letter] for letter in "XYZ" if letter in values}
    motion = int(groups.get("motion", p.motion))
    inches = groups["units"] == 20 if "units" in groups else p.inches
    scale = 25.4 if inches else 1.0
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
    if moving and motion == 1 and feed <= 0:
        raise Refused(22)
    # Everything checked: change the modal state (GRBL's order of execution).
    actions: list[Action] = []
    p.feed = feed
    if "S" in values:
        speed = values["S"]
        if speed != p.speed and spindle != 5 and "spindle" not in groups:
            actions.append(SpindleChange(spindle, speed))
        p.speed = speed
    if "T" in values:
        p.tool = int(values["T"])
    if "spindle" in groups:
        actions.append(SpindleChange(int(groups["spindle"]), p.speed))
    if "coolant" in groups:
        actions.append(CoolantChange(int(groups["coolant"])))
    if nonmodal == 4:
        actions.append(Dwell(values["P"]))
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
        actions.append(OffsetChange())
    elif nonmodal == 92.1:
        p.g92 = [0.0, 0.0, 0.0]
        actions.append(OffsetChange())
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
        actions.append(Move((target[0], target[1], target[2]), rate))
    return actions


def _words(line: str) -> list[tuple[str, float]]:
    words: list[tuple[str, float]] = []
    i = 0
    while i < len(line):
        letter = line[i]
        if not "A" <= letter <= "Z":
            raise Refused(1)
        number = NUMBER.match(line, i + 1)
        if not number:
            raise Refused(2)
        words.append((letter, float(number.group())))
        i = number.end()
    return words


def _g_group(value: float) -> str:
    if abs(value - 92.1) < 1e-6:
        return "nonmodal"
    code = int(value)
    if code not in _G_GROUPS:
        raise Refused(20)
    if value != code:
        raise Refused(23)
    return _G_GROUPS[code]
