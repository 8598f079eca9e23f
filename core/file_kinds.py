"""What a path names: a regular file, a folder, or something reading could wait on forever.

A FIFO (named pipe) blocks the ``open`` of a reader until something writes into it, a
character device (``/dev/zero``) never ends, a socket cannot be opened at all: given where a
file is wanted, each is refused by name before anything opens it (:func:`special_file_problem`),
and :func:`read_regular_bytes` reads a file only once the opened descriptor is known to be a
regular file (opened without blocking, so a FIFO swapped in meanwhile cannot hang it either).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from core.errors import InputError

__all__ = [
    "NAME_MAX",
    "long_name_problem",
    "name_max",
    "read_regular_bytes",
    "special_file_problem",
]

#: Longest file name (bytes) when the file system does not say (Linux file systems' limit).
NAME_MAX = 255

_KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str | None:
    """The words for a special file's ``st_mode``; None for a regular file or a folder."""
    return next((words for test, words in _KINDS if test(mode)), None)


def _refusal(path: Path, kind: str) -> str:
    return f"{path}: is {kind}, not a regular file; name a regular file"


def name_max(folder: str | os.PathLike[str]) -> int:
    """The longest file name (bytes) the file system of ``folder`` holds."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return NAME_MAX


def long_name_problem(path: str | os.PathLike[str]) -> str | None:
    """Why a name in ``path`` is longer than its file system allows, or None."""
    target = Path(path)
    longest = name_max(next((p for p in target.parents if os.path.isdir(p)), Path(".")))
    for part in target.parts:
        size = len(os.fsencode(part))
        if size > longest:
            return (
                f"{target}: the name {part[:24]}... is {size} bytes long, the file system "
                f"allows {longest}; choose a shorter name"
            )
    return None


def special_file_problem(path: str | os.PathLike[str]) -> str | None:
    """Why ``path`` is no file to read or replace, or None (a file, a folder, nothing there).

    A FIFO, a device or a socket (followed through links); a path no lookup can follow (a
    loop of symbolic links, a name too long, a NUL byte). A path that does not exist is left
    to the reader, whose message says what it wanted.
    """
    target = Path(path)
    try:
        mode = os.stat(target).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None
    except ValueError:  # an embedded NUL byte
        return f"{str(target)!r}: a path cannot hold a NUL byte"
    except OSError as error:
        if error.errno == errno.ELOOP:
            return f"{target}: the path runs through a loop of symbolic links"
        if error.errno == errno.ENAMETOOLONG:
            return long_name_problem(target) or (
                f"{target}: the path is longer than the file system allows; choose a shorter one"
            )
        return None  # permission and the like: the reader says it in its words
    kind = _kind(mode)
    return None if kind is None else _refusal(target, kind)


def read_regular_bytes(path: str | os.PathLike[str]) -> bytes:
    """The bytes of the regular file ``path``; InputError for a FIFO, a device, a socket.

    Checked by name first (a socket cannot be opened), then opened without blocking and
    checked again on the open descriptor, so nothing swapped in meanwhile can make the read
    wait for a writer. Other ``OSError`` (missing, permission, a folder) propagate.
    """
    target = Path(path)
    problem = special_file_problem(target)
    if problem is not None:
        raise InputError(problem)
    descriptor = os.open(target, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        mode = os.fstat(descriptor).st_mode
        kind = _kind(mode)
        if kind is not None:
            raise InputError(_refusal(target, kind))
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(target))
        handle = open(descriptor, "rb", closefd=True)
    except BaseException:
        os.close(descriptor)
        raise
    with handle:
        return handle.read()
