"""GRBL 1.1's limit switch inputs: what ``Pn:`` shows and when a switch raises a hard limit.

``limits.c``: with hard limits on (``$21=1``) the pin-change interrupt fires on every edge of a
switch, pressed or released, and outside the Alarm state (and outside homing, which disables
the interrupt) it raises ALARM:1. After a reset GRBL checks the switches (``CHECK_LIMITS_AT_INIT``,
on by default): one still pressed with ``$21=1`` leaves it in Alarm with ``[MSG:Check Limits]``.
Switches are not inverted here (``$5`` is ignored).
"""

from __future__ import annotations

__all__ = ["AXIS_LETTERS", "LimitPins"]

AXIS_LETTERS = "XYZ"


class LimitPins:
    """The X/Y/Z limit inputs.

    Besides the switches a test presses and releases, a tripped pin can be marked (an injected
    hard limit) and is shown until the next reset, as the switch that caused the alarm.
    """

    def __init__(self) -> None:
        self._pressed: set[str] = set()
        self._tripped: set[str] = set()

    @property
    def engaged(self) -> bool:
        """True while a switch is pressed (what ``CHECK_LIMITS_AT_INIT`` reads)."""
        return bool(self._pressed)

    def text(self) -> str:
        """The limit letters of the ``Pn:`` field, in GRBL's order (empty for none)."""
        shown = self._pressed | self._tripped
        return "".join(letter for letter in AXIS_LETTERS if letter in shown)

    def set(self, letter: str, pressed: bool) -> bool:
        """Press or release the switch of axis ``letter``; True when that is an edge."""
        letter = _axis(letter)
        if (letter in self._pressed) == pressed:
            return False
        if pressed:
            self._pressed.add(letter)
        else:
            self._pressed.discard(letter)
        return True

    def trip(self, letter: str) -> None:
        """Show ``letter`` as the switch of an injected hard limit until the next reset."""
        self._tripped.add(_axis(letter))

    def reset(self) -> None:
        """A soft reset: injected trips are gone; pressed switches stay pressed."""
        self._tripped.clear()


def _axis(letter: str) -> str:
    upper = letter.upper()
    if len(upper) != 1 or upper not in AXIS_LETTERS:
        raise ValueError(f"no limit switch on axis {letter!r}: X, Y or Z")
    return upper
