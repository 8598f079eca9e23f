"""Progress of long library work, reported through one small hook.

The library counts its work with :func:`progress_bar` (fit blocks, imported images, trained
steps); what shows the count is the caller's: the command line passes ``show=True`` for a
tqdm bar on the terminal, and a program that shows progress its own way (the viewer's page,
a Dask dashboard) installs a hook with :func:`reporting_to` around the call. The library's
signatures keep their ``progress: bool`` (whether to draw a terminal bar); the hook sees every
bar whether it is drawn or not.

A hook is a callable of one :class:`ProgressEvent`; it is installed for the current context
(a thread, or an asyncio task), so two viewers' sessions or two Dask tasks do not see each
other's work. A hook must be quick: it runs inside the library's loop. It may raise to abandon
the work (a viewer that stops, say): the exception leaves the library's call as any other.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator, Sized
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from tqdm import tqdm

__all__ = ["ProgressBar", "ProgressEvent", "ProgressHook", "progress_bar", "reporting_to"]

T = TypeVar("T")

#: Seconds between two events of one bar (its first and last are always sent).
EVENT_INTERVAL_S = 0.2


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
    """

    what: str
    done: int
    total: int | None
    unit: str
    finished: bool = False

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
    """A count of steps: a tqdm bar when shown, and events for the context's hooks.

    Use :func:`progress_bar` to open one. Iterate it (over the iterable it was given), or call
    :meth:`update`; :meth:`close` (or leaving a ``with`` block) ends it.
    """

    def __init__(
        self,
        iterable: Iterable[Any] | None,
        *,
        total: int | None,
        desc: str,
        unit: str,
        show: bool,
        delay: float,
        initial: int,
    ) -> None:
        if total is None and isinstance(iterable, Sized):
            total = len(iterable)
        self._iterable = iterable
        self._bar = tqdm(
            total=total, desc=desc, unit=unit, disable=not show, delay=delay, initial=initial
        )
        self._hooks = _HOOKS.get()
        self.desc, self.unit = desc, unit
        self.total, self.n = total, initial
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
        self._bar.update(steps)
        self._send()

    def set_total(self, total: int | None) -> None:
        """Change the steps planned (work whose length is learnt as it goes)."""
        self.total = total
        self._bar.total = total
        self._bar.refresh()
        self._send(force=True)

    def set_description(self, desc: str) -> None:
        """Rename the work under way."""
        self.desc = desc
        self._bar.set_description(desc)
        self._send(force=True)

    def close(self) -> None:
        """End the bar (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._bar.close()
        self._send(force=True)

    def _send(self, *, force: bool = False) -> None:
        if not self._hooks:
            return
        now = time.monotonic()
        if not force and now - self._sent < EVENT_INTERVAL_S:
            return
        self._sent = now
        event = ProgressEvent(self.desc, self.n, self.total, self.unit, self._closed)
        for hook in self._hooks:
            hook(event)


def progress_bar(
    iterable: Iterable[T] | None = None,
    *,
    total: int | None = None,
    desc: str,
    unit: str = "step",
    show: bool = False,
    delay: float = 0.0,
    initial: int = 0,
) -> ProgressBar:
    """Open a count of steps (see :class:`ProgressBar`).

    Parameters
    ----------
    iterable : optional, what the work iterates over (its length is the total when it has one)
    total : int, optional, the steps planned
    desc : str, the work's name
    unit : str, what a step is
    show : bool, draw a tqdm bar on the terminal (the library's ``progress`` argument)
    delay : float, seconds before the terminal bar appears (short work stays quiet)
    initial : int, steps already done (resumed work)
    """
    return ProgressBar(
        iterable, total=total, desc=desc, unit=unit, show=show, delay=delay, initial=initial
    )
