"""A benchmark stage run as its own process, its memory watched: time, peak, a stop.

:func:`run_watched` runs a command as a child process (in a process group of its own), polls
the resident memory of the group, and stops it (SIGTERM, then SIGKILL) above a bound, after a
time, or once it says it is ready and has done what was asked; it reports the wall time and
each process's own peak resident memory (``VmHWM``). Used by :mod:`bench.scale_rti`, whose
stages must not take the machine down when one does not stream.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["POLL_SECONDS", "run_watched"]


def run_watched(
    argv: list[str],
    *,
    stop_above: int,
    timeout: float,
    ready: str | None = None,
    until: Callable[[str], bool] | None = None,
    linger: float = 0.0,
) -> dict[str, Any]:
    """Run ``argv`` as a child process and watch its memory; its time and peaks.

    The child's resident memory (with its children's) is polled every
    :data:`POLL_SECONDS`; above ``stop_above`` bytes, after ``timeout`` seconds, or
    ``linger`` seconds after it is ready, it is stopped (SIGTERM, then SIGKILL). Ready: a
    line of its output contains ``ready`` (a server's address) and then ``until`` (given the
    output so far, asked at every poll; None: at once) says so: a server has done what was
    asked of it.

    The peak reported is each process's own peak resident set (``VmHWM`` in ``/proc``, which
    the kernel keeps: polling misses only what grows in the last interval before a process
    ends), summed over the stage's processes (exact for one process; for several, as if they
    peaked at once). ``wait4``'s count is kept beside it but measures nothing here: at
    ``exec`` Linux folds the peak of the memory the child was forked from (this process's)
    into the child's.

    Returns
    -------
    dict: ``seconds`` (wall, to the end or the stop), ``peak_bytes`` (VmHWM),
    ``wait4_peak_bytes``,
    ``returncode``, ``stopped`` (None, ``"memory"``, ``"timeout"`` or ``"ready"``),
    ``ready_seconds`` (when ``ready`` was seen, else None), ``until_seconds`` (when
    ``until`` said so, else None), ``output`` (its last 3000 characters, stdout and stderr
    together)
    """
    start = time.perf_counter()
    child = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             start_new_session=True)  # fmt: skip
    assert child.stdout is not None
    lines: list[str] = []
    seen_ready: list[float] = []

    def read(stream: Any) -> None:
        for line in stream:
            lines.append(line)
            if ready is not None and not seen_ready and ready in line:
                seen_ready.append(time.perf_counter() - start)

    reader = threading.Thread(target=read, args=(child.stdout,), daemon=True)
    reader.start()
    stopped: str | None = None
    done: float | None = None
    while not _ended(child.pid):
        time.sleep(POLL_SECONDS)
        resident = _group_resident(child.pid)
        elapsed = time.perf_counter() - start
        if seen_ready and done is None and (until is None or until("".join(lines))):
            done = elapsed
        if resident > stop_above:
            stopped = "memory"
        elif elapsed > timeout:
            stopped = "timeout"
        elif done is not None and elapsed > done + linger:
            stopped = "ready"
        if stopped is not None:
            _stop(child.pid)
            break
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    reader.join(timeout=5)
    child.stdout.close()
    return {
        "argv": argv,
        "seconds": wall,
        "peak_bytes": usage.ru_maxrss * 1024,
        "returncode": child.returncode,
        "stopped": stopped,
        "ready_seconds": seen_ready[0] if seen_ready else None,
        "until_seconds": done,
        "output": "".join(lines)[-3000:],
    }


#: Seconds between two readings of a watched stage's memory.
POLL_SECONDS = 0.25


def _ended(pid: int) -> bool:
    """Whether child ``pid`` has ended, asked without reaping it (wait4 reads its peak after).

    (``Popen.poll`` would reap it, and take its resource usage with it.)
    """
    return os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None


def _group_resident(group: int) -> int:
    """Resident bytes of every process in process group ``group`` (the stage and its children).

    Read from ``/proc``: a process that ends while it is read counts 0.
    """
    page = os.sysconf("SC_PAGE_SIZE")
    total = 0
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            # After the command's closing parenthesis: state, ppid, pgrp, ...
            if int(stat[stat.rindex(")") + 2 :].split()[2]) != group:
                continue
            total += int((entry / "statm").read_text().split()[1]) * page
        except (OSError, ValueError, IndexError):
            continue
    return total


def _stop(pid: int) -> None:
    """SIGTERM the process group of ``pid`` (the stage and its children), SIGKILL after 15 s."""
    try:
        os.killpg(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + 15.0
    while time.monotonic() < deadline:
        if _ended(pid):
            return
        time.sleep(0.2)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pid, signal.SIGKILL)
