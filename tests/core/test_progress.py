"""The progress hook: the library counts, the caller shows (core.progress)."""

from __future__ import annotations

import contextvars
import io
import threading

import pytest

import core.progress as progress
from core.progress import ProgressEvent, TerminalBars, drawing_bars, progress_bar, reporting_to


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
    assert rti[0].done == 2 and rti[-1] == ProgressEvent("rti", 5, 6, "image", True, bar.key)
    assert str(rti[-1]) == "rti 5/6 images"
    assert fit[0].bar != rti[0].bar and {e.bar for e in fit} == {fit[0].bar}  # one key a bar
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


def test_events_are_throttled_but_the_first_changes_and_last_are_sent() -> None:
    events: list[ProgressEvent] = []
    with reporting_to(events.append), progress_bar(total=1000, desc="many") as bar:
        for _ in range(1000):
            bar.update()
        bar.set_description("renamed")
    assert len(events) < 10  # a thousand quick steps: not a thousand events
    assert [(e.what, e.done, e.finished) for e in events[-2:]] == [
        ("renamed", 1000, False),
        ("renamed", 1000, True),
    ]


def test_work_shorter_than_the_delay_is_not_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    events: list[ProgressEvent] = []
    with reporting_to(events.append):
        list(progress_bar(range(3), desc="quick", delay=60.0))
    assert events == []
    now = [0.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: now[0])
    with reporting_to(events.append), progress_bar(total=3, desc="slow", delay=1.0) as bar:
        bar.update()
        now[0] = 2.0  # past the delay: the next step is the bar's first event
        bar.update()
    assert [(e.done, e.finished) for e in events] == [(2, False), (2, True)]


def test_a_hook_that_raises_abandons_the_work(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(progress, "EVENT_INTERVAL_S", 0.0)  # every step sends its event

    class Stop(Exception):
        pass

    def stop(event: ProgressEvent) -> None:
        if event.done >= 1:
            raise Stop

    done = []
    with reporting_to(stop), pytest.raises(Stop):
        for i in progress_bar(range(5), desc="x"):
            done.append(i)
    assert done == [0]


# --- the terminal hook ----------------------------------------------------------------------


def test_the_terminal_hook_draws_a_tqdm_bar_from_the_events() -> None:
    out = io.StringIO()
    with drawing_bars(out) as bars:
        assert list(progress_bar(range(3), desc="fit", unit="block")) == [0, 1, 2]
        assert bars.running == 0  # closed at its last event
    text = out.getvalue()
    assert "fit:   0%" in text and "0/3" in text
    assert "fit: 100%" in text and "3/3" in text and "block/s" in text
    assert text.endswith("\n")  # the outermost bar stays, on its own line


def test_the_terminal_hook_follows_a_renamed_bar_and_a_new_total() -> None:
    out = io.StringIO()
    with drawing_bars(out), progress_bar(desc="training", unit="step") as bar:
        bar.set_total(4)
        bar.update(2)
        bar.set_description("training again")
        bar.update(2)
    text = out.getvalue()
    assert "training: " in text and "training again: 100%" in text and "4/4" in text


def test_nested_bars_each_have_their_tqdm() -> None:
    out = io.StringIO()
    bars = TerminalBars(out)
    with reporting_to(bars):
        outer = progress_bar(total=2, desc="outer", unit="camera")
        for _ in range(2):
            with progress_bar(total=3, desc="inner", unit="slab") as inner:
                assert bars.running == 2
                inner.update(3)
            outer.update()
        outer.close()
    assert bars.running == 0
    text = out.getvalue()
    assert "outer: 100%" in text and "2/2" in text
    # Each inner bar had its own line, cleared when it finished (only the outermost stays).
    assert text.count("inner:   0%") == 2 and "0/3" in text


def test_concurrent_bars_of_one_hook_do_not_mix() -> None:
    out = io.StringIO()
    bars = TerminalBars(out)
    ready = threading.Barrier(2)

    def work(name: str) -> None:
        with progress_bar(total=50, desc=name, unit="step") as bar:
            ready.wait()
            for _ in range(50):
                bar.update()

    with reporting_to(bars):
        # The workers run in copies of this context: both report to the same hook.
        threads = [
            threading.Thread(target=contextvars.copy_context().run, args=(work, name))
            for name in ("left", "right")
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert bars.running == 0
    text = out.getvalue()
    assert "left:   0%" in text and "right:   0%" in text  # a line each
    assert "left: 100%" in text or "right: 100%" in text  # the one left on the terminal


def test_bars_left_open_by_an_exception_are_closed() -> None:
    out = io.StringIO()
    with pytest.raises(RuntimeError), drawing_bars(out) as bars:
        progress_bar(total=5, desc="abandoned").update(2)  # never closed by its work
        for i in progress_bar(range(5), desc="loop"):
            if i == 1:
                assert bars.running == 2
                raise RuntimeError("stop")
    assert bars.running == 0
    text = out.getvalue()
    assert "abandoned:" in text and "loop:" in text
    bars.close()  # idempotent


def test_a_bar_closed_through_its_iterator_ends_on_the_terminal_too() -> None:
    out = io.StringIO()
    with drawing_bars(out) as bars:
        with pytest.raises(RuntimeError):
            for _ in progress_bar(range(5), desc="loop"):
                raise RuntimeError("stop")
        # The generator's clean-up (its frame is released with the traceback) closed it.
        assert bars.running in (0, 1)
    assert bars.running == 0
