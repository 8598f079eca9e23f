"""An exclusive lock on a dataset: one process at a time captures into it.

Two captures of one dataset would both drive the rig's ports and interleave their runs in the
journal, after which nothing can trust it. The lock is ``DATASET/.lock``, locked with
``flock``: the kernel releases it when its process ends, however it ends (a SIGKILL included),
so a dead holder never blocks a resume (:class:`core.exclusive_lock.ExclusiveLock`: the file
names its holder for the message a second process gets).
"""

from __future__ import annotations

import os
from pathlib import Path

from core.errors import DatasetError
from core.exclusive_lock import ExclusiveLock

__all__ = ["LOCK_NAME", "DatasetLock"]

LOCK_NAME = ".lock"


class DatasetLock(ExclusiveLock):
    """``with DatasetLock(path):`` holds the dataset's lock; reentrant within one object.

    Raises
    ------
    DatasetError
        Another process holds the lock (the message names it and how to clear a stale one).
    """

    def __init__(self, dataset: str | os.PathLike[str]) -> None:
        self.dataset = Path(dataset)
        super().__init__(
            self.dataset / LOCK_NAME,
            what=str(self.dataset),
            noun="dataset",
            rule="one capture at a time per dataset",
            advice="Wait for it to finish (or stop it with Ctrl-C and resume later)",
            error=DatasetError,
        )
