"""A Dask worker lost mid-task, as a crashed machine: for the tests of the --dask stages."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

Result = TypeVar("Result")


def kill_a_worker_mid_run(
    client: Any, run: Callable[[], Result], while_running: Callable[[], None] = lambda: None
) -> Result:
    """Run ``run`` in a thread, SIGKILL the first worker seen busy, and return its result.

    ``while_running`` is called once a task runs, before the kill (to look at what the stage
    leaves while it works). Fails if no task starts within a minute, if ``run`` raises, or
    if the cluster does not replace the killed worker.
    """
    before = client.run(os.getpid)
    outcome: dict[str, Any] = {}

    def target() -> None:
        try:
            outcome["value"] = run()
        except Exception as error:  # handed to the test's thread
            outcome["error"] = error

    thread = threading.Thread(target=target)
    thread.start()
    deadline = time.monotonic() + 60
    busy: list[str] = []
    while not busy and time.monotonic() < deadline:
        busy = [address for address, tasks in client.processing().items() if tasks]
        time.sleep(0.005)
    assert busy, "no task started within a minute"
    while_running()
    os.kill(before[busy[0]], signal.SIGKILL)
    thread.join(timeout=300)
    assert not thread.is_alive() and "error" not in outcome, outcome.get("error")
    client.wait_for_workers(len(before), timeout=60)
    assert set(client.run(os.getpid).values()) != set(before.values())  # one was replaced
    value: Result = outcome["value"]
    return value
