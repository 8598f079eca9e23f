"""GRBL 1.1's line filter: the received bytes, one at a time, assembled into the lines it parses.

As ``protocol.c`` reads them: whitespace and control characters dropped, ``()`` and ``;``
comments removed, letters upper-cased, ``/`` (block delete) ignored, and a line longer than the
80-byte line buffer flagged as overflowed (GRBL answers it ``error:11``). Real-time bytes never
reach this filter: the emulator (:mod:`sim.grbl.emulator`) picks them off first.
"""

from __future__ import annotations

__all__ = ["LINE_BUFFER_SIZE", "LineAssembler"]

LINE_BUFFER_SIZE = 80
"""GRBL's ``LINE_BUFFER_SIZE``: one byte of it is the terminator, so 79 characters fit."""


class LineAssembler:
    """GRBL's character filter: what the received bytes leave of each line.

    Whitespace and control characters dropped, ``()`` and ``;`` comments removed, letters
    upper-cased, ``/`` ignored, overflow past 79 characters flagged.
    """

    def __init__(self) -> None:
        self._chars: list[str] = []
        self._comment = ""  # "(" or ";" while in a comment
        self._overflow = False

    def reset(self) -> None:
        """Forget the line in progress (a soft reset)."""
        self._chars.clear()
        self._comment, self._overflow = "", False

    def feed(self, byte: int) -> tuple[str, bool] | None:
        r"""Take one byte.

        Parameters
        ----------
        byte : the received byte, 0..255

        Returns
        -------
        ``(line, overflowed)`` at an end of line (``\n`` or ``\r``), else None.
        """
        if byte in (0x0A, 0x0D):
            line, overflow = "".join(self._chars), self._overflow
            self.reset()
            return line, overflow
        char = chr(byte)
        if self._comment or self._overflow:
            if char == ")" and self._comment == "(":
                self._comment = ""
        elif byte <= 0x20 or char == "/":
            pass
        elif char in "(;":
            self._comment = char
        elif len(self._chars) >= LINE_BUFFER_SIZE - 1:
            self._overflow = True
        else:
            self._chars.append(char.upper())
        return None
