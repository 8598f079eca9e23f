"""GRBL 1.1's words: how it reads a number, splits a line into words, and refuses a line.

Shared by the G-code parser (:mod:`sim.grbl.gcode`), its arcs (:mod:`sim.grbl.arcs`) and the
``$`` settings (:mod:`sim.grbl.settings`): every check there ends in :class:`Refused`, which the
machine answers ``error:N``.
"""

from __future__ import annotations

import re

__all__ = ["NUMBER", "Refused", "words"]

NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)")
"""A number as GRBL's ``read_float`` takes it (G-code words and ``$`` settings alike)."""


class Refused(Exception):
    """A line GRBL answers with ``error:code`` instead of ``ok``.

    Parameters
    ----------
    code : GRBL's status code
    """

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def words(line: str) -> list[tuple[str, float]]:
    """The ``(letter, value)`` words of a filtered line, in order.

    Raises
    ------
    Refused
        ``error:1`` for a character that is not a letter where a word starts, ``error:2`` for a
        letter without a number.
    """
    found: list[tuple[str, float]] = []
    i = 0
    while i < len(line):
        letter = line[i]
        if not "A" <= letter <= "Z":
            raise Refused(1)
        number = NUMBER.match(line, i + 1)
        if not number:
            raise Refused(2)
        found.append((letter, float(number.group())))
        i = number.end()
    return found
