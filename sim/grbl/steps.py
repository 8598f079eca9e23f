"""The steps a GRBL line runs through before its response, and GRBL reads the next line.

GRBL executes a line in its main loop and blocks there while the planner is full, while it
synchronises (G4, spindle and coolant changes wait for the planner to empty) and while it
dwells; only then does it answer and read on. The emulator has no loop to block, so a line
becomes a queue of steps, each tried at every event until it reports done: waits, actions,
pushed messages and, last, the ``ok``/``error:N``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager

__all__ = ["Emit", "LineSteps", "Step"]

Emit = Callable[[str, str, str], None]
"""``emit(text, kind, source)``: one output line; ``kind`` is ``"response"``, ``"status"`` or
``"push"``, ``source`` the line it answers."""

Step = Callable[[float], bool]
"""``step(t)``: try at time ``t``; True when done (the next step may run), False to wait."""


class LineSteps:
    """The queue of steps of the line being executed.

    Parameters
    ----------
    emit : receives the responses and pushed messages, with the line they belong to

    Attributes
    ----------
    source : the line being executed, the ``source`` of what its steps emit
    """

    def __init__(self, emit: Emit) -> None:
        self._emit = emit
        self._steps: deque[Step] = deque()
        self._dwell_until: float | None = None
        self._insert_at: int | None = None
        self.source = ""

    @property
    def pending(self) -> bool:
        """True while the line has steps left (GRBL reads no further line)."""
        return bool(self._steps)

    def add(self, step: Step) -> None:
        """Queue ``step`` (right after the running step, inside :meth:`inserting`)."""
        if self._insert_at is None:
            self._steps.append(step)
        else:
            self._steps.insert(self._insert_at, step)
            self._insert_at += 1

    @contextmanager
    def inserting(self) -> Iterator[None]:
        """Within the block, steps queued by the running step come right after it, in order.

        GRBL runs the startup lines inside ``$H`` before its ``ok``: the homing step queues
        their steps ahead of the ``ok`` already waiting.
        """
        self._insert_at = 1
        try:
            yield
        finally:
            self._insert_at = None

    def respond(self, text: str) -> None:
        """Queue the line's response, ``ok`` or ``error:N``."""
        source = self.source

        def step(t: float) -> bool:
            self._emit(text, "response", source)
            return True

        self.add(step)

    def push(self, text: str) -> None:
        """Queue a pushed message (a ``$`` report line, ``[MSG:...]``)."""
        source = self.source

        def step(t: float) -> bool:
            self._emit(text, "push", source)
            return True

        self.add(step)

    def do(self, action: Callable[[], None]) -> None:
        """Queue ``action``, run when the steps before it are done."""

        def step(t: float) -> bool:
            action()
            return True

        self.add(step)

    def dwell(self, seconds: float) -> None:
        """Queue a wait of ``seconds`` from when the steps before it are done."""

        def step(t: float) -> bool:
            if self._dwell_until is None:
                self._dwell_until = t + seconds
            if t < self._dwell_until:
                return False
            self._dwell_until = None
            return True

        self.add(step)

    def clear(self) -> None:
        """Drop every step (a refused line, an alarm, a reset)."""
        self._steps.clear()
        self._dwell_until = None

    def run(self, t: float, halted: Callable[[], bool]) -> None:
        """Run the steps at time ``t`` until one waits, none is left or ``halted()``."""
        while self._steps and not halted():
            if not self._steps[0](t):
                return
            if self._steps:  # an alarm inside the step may have cleared them
                self._steps.popleft()
