"""An exclusive lock on a dataset: one process at a time captures into it.

Two captures of one dataset would both drive the rig's ports and interleave their runs in the
journal, after which nothing can trust it. The lock is ``DATASET/.lock``, locked with
``flock``: the kernel releases it when its process ends, however it ends (a SIGKILL included),
so a dead holder never blocks a resume. The file says who holds it (pid, host, since when), for
the message a second process gets. A lock taken on another host through a network file system
that does not carry ``flock`` cannot be seen; the message says how to clear such a file.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import IO

from core.errors import DatasetError

__all__ = ["LOCK_NAME", "DatasetLock"]

LOCK_NAME = ".lock"


class DatasetLock:
    """``with DatasetLock(path):`` holds the dataset's lock; reentrant within one object.

    Raises
    ------
    DatasetError
        Another process holds the lock (the message names it and how to clear a stale one).
    """

    def __init__(self, dataset: str | os.PathLike[str]) -> None:
        self.dataset = Path(dataset)
        self.path = self.dataset / LOCK_NAME
        self._file: IO[str] | None = None
        self._depth = 0

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._depth > 0

    def acquire(self) -> None:
        """Take the lock, or raise :class:`DatasetError` naming its holder."""
        if self._depth:
            self._depth += 1
            return
        try:
            handle = open(self.path, "a+", encoding="utf-8")  # held until release
        except OSError as error:
            raise DatasetError(f"{self.path}: cannot lock the dataset: {error}") from error
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = _describe(handle.read())
            handle.close()
            raise DatasetError(
                f"{self.dataset} is in use by {holder}: one capture at a time per dataset. "
                f"Wait for it to finish (or stop it with Ctrl-C and resume later). If no such "
                f"process is running (a lock held from another machine), delete {self.path}"
            ) from None
        except OSError as error:
            handle.close()
            raise DatasetError(f"{self.path}: cannot lock the dataset: {error}") from error
        handle.seek(0)
        handle.truncate()
        handle.write(
            json.dumps(
                {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "since": datetime.now(UTC).isoformat(timespec="seconds"),
                }
            )
        )
        handle.flush()
        self._file = handle
        self._depth = 1

    def release(self) -> None:
        """Give the lock back (the file stays: removing it would race a new holder)."""
        if not self._depth:
            return
        self._depth -= 1
        if self._depth or self._file is None:
            return
        try:
            self._file.seek(0)
            self._file.truncate()
            fcntl.flock(self._file.fileno(), fcntl.LOCK_UN)
        finally:
            self._file.close()
            self._file = None

    def __enter__(self) -> DatasetLock:
        self.acquire()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


def _describe(text: str) -> str:
    try:
        holder = json.loads(text)
        return f"process {holder['pid']} on {holder['host']} (since {holder['since']})"
    except (ValueError, KeyError, TypeError):
        return "another process"
