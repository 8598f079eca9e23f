"""The progress hook: the library counts, the caller shows (core.progress)."""

from __future__ import annotations

import threading

import pytest

from core.progress import ProgressEvent, progress_bar, reporting_to


def test_a_hook_sees_every_bar_in_its_context_and_the_bar_still_counts() -> None:
    events: list[ProgressEvent] = []
    with reporting_to(events.append):
        assert list(progress_bar(range(3), desc="fit", unit="block")) == [0, 1, 2]
        with progress_bar(total=5, desc="rti", unit="image", initial=2) as bar:
            bar.update(3)
            bar.set_total(6)
    fit = [e for e in events if e.what == "fit"]
    assert (fit[0].done, fit[0].total, fit[0].finished) == (0, 3, False)
    assert (fit[-1].done, fit[-1].finished) == (3, True)  # the last event is always sent
    rti = [e for e in events if e.what == "rti"]
    assert rti[0].done == 2 and rti[-1] == ProgressEvent("rti", 5, 6, "image", True)
    assert str(rti[-1]) == "rti 5/6 images"
    events.clear()
    list(progress_bar(range(2), desc="outside", unit="step"))
    assert events == []  # the hook is gone with its context


def test_hooks_do_not_cross_threads() -> None:
    mine: list[ProgressEvent] = []
    theirs: list[ProgressEvent] = []

    def other() -> None:
        with reporting_to(theirs.append):
            list(progress_bar(range(2), desc="theirs"))

    with reporting_to(mine.append):
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
        list(progress_bar(range(2), desc="mine"))
    assert {e.what for e in mine} == {"mine"} and {e.what for e in theirs} == {"theirs"}


def test_a_bar_without_an_iterable_cannot_be_iterated() -> None:
    with pytest.raises(TypeError, match="without an iterable"):
        list(progress_bar(total=2, desc="x"))
