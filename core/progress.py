"""Progress of long library work, reported through one small hook.

The library counts its work with :func:`progress_bar` (fit blocks, imported images, trained
steps) and never draws anything itself: what shows the count is the caller's, which installs
a hook with :func:`reporting_to` around the call. The command line installs
:class:`TerminalBars` (a tqdm bar on stderr for each running bar, see :func:`drawing_bars`)
unless ``--quiet``; the viewer shows the events on its page; a Dask run counts its finished
tasks with a bar of its own (:func:`core.cluster.compute_each`), seen by the caller's hook.

A hook is a callable of one :class:`ProgressEvent`; it is installed for the current context
(a thread, or an asyncio task), so two viewers' sessions or two Dask tasks do not see each
other's work (a new thread starts with no hook). A hook must be quick: it runs inside the
library's loop. It may raise to abandon the work (a viewer that stops, say): the exception
leaves the library's call as any other.

Events are throttled at their source, for every hook alike: a bar sends its first event, every
change of its total or name, and its last (finished) one, and between them at most one event
each :data:`EVENT_INTERVAL_S`. That is 5 redraws a second, as often as a person reads a
terminal bar (tqdm's own limit, ``mininterval``, is 0.1 s, so the terminal hook draws every
event it is sent; its count and rate are right at each, and exact at the end).
"""

from __future__ import annotations

import itertools
import sys
import threading
import time
from collections.abc import Iterable, Iterator, Sized
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, Protocol, TextIO, TypeVar

__all__ = [
    "EVENT_INTERVAL_S",
    "ProgressBar",
    "ProgressEvent",
    "ProgressHook",
    "TerminalBars",
    "drawing_bars",
    "progress_bar",
    "reporting_to",
]

T = TypeVar("T")

#: Seconds between two events of one bar (its first and last are always sent).
EVENT_INTERVAL_S = 0.2

_KEYS = itertools.count(1)


@dataclass(frozen=True)
class ProgressEvent:
    """One step of a piece of work.

    Attributes
    ----------
    what : str, the work ("fit", "rti", "training", ...), as the terminal bar names it
    done : int, steps done
    total : int or None, steps planned (None: not known)
    unit : str, what a step is ("block", "image", ...)
    finished : bool, the bar was closed (the work ended, or was abandoned)
    bar : int, which bar sent it: unique to the bar in the process (work nested in other
        work, or running beside it, has its own); 0 for an event not sent by a bar
    """

    what: str
    done: int
    total: int | None
    unit: str
    finished: bool = False
    bar: int = 0

    def __str__(self) -> str:
        count = f"{self.done}/{self.total}" if self.total else str(self.done)
        return f"{self.what} {count} {self.unit}{'s' if (self.total or self.done) != 1 else ''}"


class ProgressHook(Protocol):
    """What receives the events of the bars in its context."""

    def __call__(self, event: ProgressEvent, /) -> None:
        """Take one event (quickly; raising abandons the work)."""


_HOOKS: ContextVar[tuple[ProgressHook, ...]] = ContextVar("progress_hooks", default=())


@contextmanager
def reporting_to(hook: ProgressHook) -> Iterator[None]:
    """Send the events of every bar opened in this context, and in what it calls, to ``hook``."""
    token = _HOOKS.set((*_HOOKS.get(), hook))
    try:
        yield
    finally:
        _HOOKS.reset(token)


class ProgressBar:
    """A count of steps, sent as events to the hooks of the context it was opened in.

    Use :func:`progress_bar` to open one. Iterate it (over the iterable it was given), or call
    :meth:`update`; :meth:`close` (or leaving a ``with`` block) ends it. Its events carry
    :attr:`key`, unique to it in the process.
    """

    def __init__(
        self,
        iterable: Iterable[Any] | None,
        *,
        total: int | None,
        desc: str,
        unit: str,
        delay: float,
        initial: int,
    ) -> None:
        if total is None and isinstance(iterable, Sized):
            total = len(iterable)
        self._iterable = iterable
        self._hooks = _HOOKS.get()
        self.key = next(_KEYS)
        self.desc, self.unit = desc, unit
        self.total, self.n = total, initial
        self._opened = time.monotonic()
        self._delay = delay
        self._started = False  # an event was sent (not before ``delay``)
        self._sent = 0.0
        self._closed = False
        self._send(force=True)

    def __iter__(self) -> Iterator[Any]:
        if self._iterable is None:
            raise TypeError("this progress bar was opened without an iterable")
        try:
            for item in self._iterable:
                yield item
                self.update()
        finally:
            self.close()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def update(self, steps: int = 1) -> None:
        """Count ``steps`` more steps done."""
        self.n += steps
        self._send()

    def set_total(self, total: int | None) -> None:
        """Change the steps planned (work whose length is learnt as it goes)."""
        self.total = total
        self._send(force=True)

    def set_description(self, desc: str) -> None:
        """Rename the work under way."""
        self.desc = desc
        self._send(force=True)

    def close(self) -> None:
        """End the bar (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._send(force=True)

    def _send(self, *, force: bool = False) -> None:
        if not self._hooks:
            return
        now = time.monotonic()
        if not self._started:
            # Work shorter than ``delay`` is not reported at all, not even its end.
            if now - self._opened < self._delay:
                return
            self._started = force = True
        if not force and now - self._sent < EVENT_INTERVAL_S:
            return
        self._sent = now
        event = ProgressEvent(self.desc, self.n, self.total, self.unit, self._closed, self.key)
        for hook in self._hooks:
            hook(event)


def progress_bar(
    iterable: Iterable[T] | None = None,
    *,
    total: int | None = None,
    desc: str,
    unit: str = "step",
    delay: float = 0.0,
    initial: int = 0,
) -> ProgressBar:
    """Open a count of steps (see :class:`ProgressBar`); the context's hooks are told of it.

    Parameters
    ----------
    iterable : optional, what the work iterates over (its length is the total when it has one)
    total : int, optional, the steps planned
    desc : str, the work's name
    unit : str, what a step is
    delay : float, seconds before the first event: work that ends sooner is not reported
        (short work stays quiet)
    initial : int, steps already done (resumed work)
    """
    return ProgressBar(iterable, total=total, desc=desc, unit=unit, delay=delay, initial=initial)


@dataclass
class _Drawn:
    """A tqdm bar on the terminal and the name it shows."""

    bar: Any
    what: str


class TerminalBars:
    """A hook that draws a tqdm bar for each running bar (the command line's renderer).

    One tqdm per bar, keyed by :attr:`ProgressEvent.bar`, opened at the bar's first event and
    closed at its last; nested or concurrent bars stack (tqdm gives each a free line, and
    clears a bar not on the first line when it finishes: the outermost stays). It draws
    every event it is sent (the source throttles, see :data:`EVENT_INTERVAL_S`), and is safe
    to call from several threads. :meth:`close` ends the bars still open (work abandoned by an
    exception before its bar was closed); :func:`drawing_bars` does it on leaving.

    Parameters
    ----------
    file : text stream, optional, where to draw (default: ``sys.stderr`` at each bar's opening)
    """

    def __init__(self, file: TextIO | None = None) -> None:
        self._file = file
        self._bars: dict[int, _Drawn] = {}
        self._lock = threading.Lock()

    def __call__(self, event: ProgressEvent, /) -> None:
        """Draw ``event`` on its bar."""
        from tqdm import tqdm

        with self._lock:
            drawn = self._bars.get(event.bar)
            if drawn is None:
                bar = tqdm(
                    total=event.total,
                    desc=event.what,
                    unit=event.unit,
                    initial=event.done,
                    leave=None,  # a nested bar goes when done; the outermost stays
                    file=self._file or sys.stderr,
                )
                drawn = self._bars[event.bar] = _Drawn(bar, event.what)
            bar = drawn.bar
            changed = event.what != drawn.what or event.total != bar.total
            if changed:
                drawn.what = event.what
                bar.set_description(event.what, refresh=False)
                bar.total = event.total
            if event.done != bar.n:
                bar.update(event.done - bar.n)
            if changed:
                bar.refresh()
            if event.finished:
                del self._bars[event.bar]
                bar.close()

    @property
    def running(self) -> int:
        """Bars drawn and not finished yet."""
        with self._lock:
            return len(self._bars)

    def close(self) -> None:
        """Close the bars still open (idempotent)."""
        with self._lock:
            drawn, self._bars = list(self._bars.values()), {}
        for one in drawn:
            one.bar.close()


@contextmanager
def drawing_bars(file: TextIO | None = None) -> Iterator[TerminalBars]:
    """Draw the bars of this context, and of what it calls, on the terminal (stderr).

    Installs a :class:`TerminalBars` with :func:`reporting_to`; on leaving, by an exception
    too, the bars left open are closed.
    """
    bars = TerminalBars(file)
    try:
        with reporting_to(bars):
            yield bars
    finally:
        bars.close()
