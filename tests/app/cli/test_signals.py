"""Ctrl-C and SIGTERM stop ``rig`` cleanly: no traceback, and nothing left in the temp folder.

Each command runs as a user runs it, in a process of its own with ``TMPDIR`` pointed at a
folder of the test, and is sent the signal while it works: ``rig view`` once it serves (an
RTI capture imported into a temporary store, the viewer's uploads beside it), ``rig
evaluate`` while it trains on such an import. The waits are generous (importing and fitting
take a minute on a loaded machine) and nothing is timed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[3]
RTI = ROOT / "core" / "data" / "rti" / "loewenkopf"
#: Seconds allowed for a stage on a loaded 2-core machine (a bound on a hang, not a timing).
PATIENCE_S = 300.0
SIGNALS = [pytest.param(signal.SIGINT, id="SIGINT"), pytest.param(signal.SIGTERM, id="SIGTERM")]


def _rig(args: list[str], scratch: Path, logs: Path) -> subprocess.Popen[bytes]:
    scratch.mkdir()
    with open(logs / "stdout.txt", "wb") as stdout, open(logs / "stderr.txt", "wb") as stderr:
        return subprocess.Popen(
            [sys.executable, "-m", "app.cli", *args],
            cwd=ROOT,
            env={**os.environ, "TMPDIR": str(scratch)},
            stdin=subprocess.DEVNULL,
            stdout=stdout,
            stderr=stderr,
        )


def _until(condition: Callable[[], object], process: subprocess.Popen[bytes], what: str) -> None:
    deadline = time.monotonic() + PATIENCE_S
    while not condition():
        if process.poll() is not None:
            raise AssertionError(f"rig ended ({process.returncode}) before {what}")
        if time.monotonic() > deadline:
            process.kill()
            raise AssertionError(f"no {what} within {PATIENCE_S:.0f} s")
        time.sleep(0.2)


def _stacks(process: subprocess.Popen[bytes], logs: Path) -> str:
    """Every thread's stack of a stuck ``rig`` (SIGUSR1, see app.cli.main), then kill it."""
    process.send_signal(signal.SIGUSR1)
    time.sleep(2.0)  # a bound on nothing: the stacks are read, whatever was written by then
    process.kill()
    process.wait()
    return (logs / "stderr.txt").read_text(errors="replace")[-6000:]


def _stopped_cleanly(
    process: subprocess.Popen[bytes], number: int, scratch: Path, logs: Path
) -> str:
    """Send ``number``; the process ends without a traceback and leaves no temporary."""
    process.send_signal(number)
    try:
        process.wait(timeout=PATIENCE_S)
    except subprocess.TimeoutExpired:
        raise AssertionError(
            f"rig did not stop within {PATIENCE_S:.0f} s of the signal; its threads:\n"
            + _stacks(process, logs)
        ) from None
    stderr = (logs / "stderr.txt").read_text(errors="replace")
    assert "Traceback" not in stderr, stderr[-3000:]
    left = sorted(path.name for path in scratch.iterdir())
    assert left == [], f"left in the temp folder: {left}"
    return stderr


@pytest.mark.parametrize("number", SIGNALS)
def test_rig_view_stops_and_removes_its_temporaries(tmp_path: Path, number: int) -> None:
    scratch = tmp_path / "tmp"
    process = _rig(["view", str(RTI), "--port", "0"], scratch, tmp_path)
    stdout = tmp_path / "stdout.txt"
    try:
        _until(lambda: "open http" in stdout.read_text(), process, "URL printed")
        url = stdout.read_text().split("open ", 1)[1].split()[0]
        with urllib.request.urlopen(url, timeout=PATIENCE_S) as page:  # it serves
            assert page.status == 200
        assert any(path.name.startswith("rig-rti-") for path in scratch.iterdir())
        _stopped_cleanly(process, number, scratch, tmp_path)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    # rig view treats a stop as its normal end (0); a signal's default would be -number.
    assert process.returncode in (0, 128 + number)


@pytest.mark.parametrize("number", SIGNALS)
def test_a_command_stopped_while_it_works_says_so(tmp_path: Path, number: int) -> None:
    scratch = tmp_path / "tmp"
    # Training the learned rung takes a minute or more: the signal comes while it trains.
    args = ["evaluate", str(RTI), "--split", "every-other", "--methods", "learned"]
    process = _rig(args, scratch, tmp_path)
    stderr = tmp_path / "stderr.txt"
    try:
        _until(lambda: "rti: 100%" in stderr.read_text(errors="replace"), process,
               "the capture imported")  # fmt: skip
        said = _stopped_cleanly(process, number, scratch, tmp_path)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 128 + number
    word = "terminated" if number == signal.SIGTERM else "interrupted"
    assert f"rig evaluate: {word}" in said
