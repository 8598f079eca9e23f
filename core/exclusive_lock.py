"""An exclusive lock held by one process, naming its holder: a dataset, a serial port.

Two processes driving one rig's ports (two ``rig capture``, or a capture and a ``rig doctor``)
interleave their commands on the wire; two captures of one dataset interleave their journals.
The lock is a file locked with ``flock``: the kernel releases it when its process ends, however
it ends (SIGKILL included), so a dead holder never blocks the next. The file says who holds it
(pid, host, command, since when) for the message the next process gets. A lock taken on
another host through a network file system that does not carry ``flock`` cannot be seen; the
message says how to clear such a file.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sys
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import IO

from core.errors import RigError

__all__ = ["ExclusiveLock"]


class ExclusiveLock:
    """``with ExclusiveLock(path, ...):`` holds the lock at ``path``; reentrant within one object.

    Parameters
    ----------
    path : the lock file (created if absent; left in place on release: removing it would race
        a new holder)
    what : what is locked, for messages ("dataset/ is in use by ...")
    noun : its kind ("dataset", "serial port"), for messages
    rule : why one holder at a time, for messages ("one capture at a time per dataset")
    advice : what to do about a live holder ("wait for it to finish")
    error : the :class:`RigError` subclass raised

    Raises
    ------
    error
        Another process holds the lock (the message names it, the rule, and how to clear a
        stale lock), or the lock file cannot be opened.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        what: str,
        noun: str,
        rule: str,
        advice: str,
        error: type[RigError] = RigError,
    ) -> None:
        self.path = Path(path)
        self.what = what
        self.noun = noun
        self.rule = rule
        self.advice = advice
        self.error = error
        self._file: IO[str] | None = None
        self._depth = 0

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._depth > 0

    def acquire(self) -> None:
        """Take the lock, or raise naming its holder."""
        if self._depth:
            self._depth += 1
            return
        try:
            handle = open(self.path, "a+", encoding="utf-8")  # held until release
        except OSError as error:
            raise self.error(f"{self.path}: cannot lock the {self.noun}: {error}") from error
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = describe_holder(handle.read())
            handle.close()
            raise self.error(
                f"{self.what} is in use by {holder}: {self.rule}. {self.advice}. If no such "
                f"process is running (a lock held from another machine), delete {self.path}"
            ) from None
        except OSError as error:
            handle.close()
            raise self.error(f"{self.path}: cannot lock the {self.noun}: {error}") from error
        handle.seek(0)
        handle.truncate()
        program = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "python"
        command = " ".join([program, *sys.argv[1:2]]) if program == "rig" else program
        handle.write(
            json.dumps(
                {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "command": command,
                    "since": datetime.now(UTC).isoformat(timespec="seconds"),
                }
            )
        )
        handle.flush()
        self._file = handle
        self._depth = 1

    def release(self) -> None:
        """Give the lock back."""
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

    # The context-manager protocol with its typed signature, alike in shape to every device's
    # (duplicates pairs it with rig.hardware.Rig's); entering and leaving differ in each.
    def __enter__(self) -> ExclusiveLock:
        self.acquire()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


def describe_holder(text: str) -> str:
    """The holder a lock file names, in words: process 12 on host (rig capture, since ...)."""
    try:
        holder = json.loads(text)
        command = f"{holder['command']}, " if holder.get("command") else ""
        return f"process {holder['pid']} on {holder['host']} ({command}since {holder['since']})"
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
        return "another process"
