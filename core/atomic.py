"""Atomic file output: a file named by the project is never seen half-written.

Every write is checked: a temporary file beside the target is written, flushed to the disk
(``fsync``) and only then renamed onto the target, so a failed write (a full disk, a file
size limit, a quota) is an :class:`~core.errors.InputError` naming the target and leaves any
earlier file under that name as it was.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import stat
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from core.errors import InputError
from core.file_kinds import long_name_problem, name_max

__all__ = [
    "atomic_path",
    "output_problem",
    "write_bytes_atomic",
    "write_json_atomic",
    "write_problem",
    "writer_tag",
]

#: Why a write failed, in words, by errno (the rest say the system's words).
_WRITE_FAILURES = {
    errno.ENOSPC: "no space left on the device; free some space or choose another place",
    errno.EDQUOT: "the disk quota is exceeded; free some space or choose another place",
    errno.EFBIG: "the file is larger than this process may write (a file size limit)",
    errno.EROFS: "the file system is read-only; choose another place",
    errno.EACCES: "permission denied; choose another place",
}


def _path_problem(target: Path, error: OSError) -> str:
    """Why ``target`` cannot be looked up, from the error of a ``stat`` on it or a parent."""
    if error.errno == errno.ELOOP:
        return (
            f"{target}: the path runs through a loop of symbolic links ({error.filename}); "
            "fix the link or choose another path"
        )
    if error.errno == errno.ENAMETOOLONG:
        return f"{target}: the path is longer than the file system allows; choose a shorter one"
    return f"{target}: cannot be used as an output: {error.strerror or error}"


def _status(path: Path) -> os.stat_result | None:
    """``stat`` of ``path`` (through links); None when nothing is there, OSError else."""
    try:
        return path.stat()
    except FileNotFoundError:
        return None


def output_problem(path: str | os.PathLike[str], *, directory: bool = False) -> str | None:
    """Why ``path`` cannot be written as a file (or, with ``directory``, a folder), or None.

    Checked before any work starts, so that a long render or capture does not end in an
    ``IsADirectoryError``: a folder where a file is wanted (or a file where a folder is), a
    file standing where a parent folder must be, a parent that cannot be written, a name
    longer than the file system allows, a loop of symbolic links.
    """
    target = Path(path)
    try:
        return _output_problem(target, directory)
    except OSError as error:
        return _path_problem(target, error)


def _output_problem(target: Path, directory: bool) -> str | None:
    too_long = long_name_problem(target)
    if too_long is not None:
        return too_long
    nearest = Path(".")
    for parent in reversed(target.parents):
        found = _status(parent)
        if found is None:
            break
        if not stat.S_ISDIR(found.st_mode):
            return f"{target}: {parent} is a file, not a directory"
        nearest = parent
    status = _status(target)  # a loop of symbolic links raises here
    is_dir = status is not None and stat.S_ISDIR(status.st_mode)
    if directory and status is not None and not is_dir:
        return f"{target}: exists and is a file, not a directory; choose another path"
    if not directory and is_dir:
        return f"{target}: is a directory; name a file to write"
    writable = target if status is not None else nearest
    if not os.access(writable, os.W_OK):
        return f"{target}: cannot write in {writable} (permission denied)"
    return None


def writer_tag() -> str:
    """``PID.TID``: names a file or folder a writer makes beside its target, its own.

    Two threads of one process (a viewer's session and its light view both saving a field's
    fit) would otherwise write, rename or remove each other's temporary files.
    """
    return f"{os.getpid()}.{threading.get_native_id()}"


def _temporary(target: Path, longest: int) -> Path:
    """The hidden name beside ``target`` written first, ``.STEM.PID.TID.partial.SUFFIX``.

    Its own for each process and thread (:func:`writer_tag`). It keeps the suffix, so writers
    that pick a format by extension work unchanged; a long stem is shortened to keep the name
    within the file system's limit.
    """
    tail = f".{writer_tag()}.partial{target.suffix}"
    room = longest - len(os.fsencode(tail)) - 1
    stem = os.fsencode(target.stem)[: max(room, 0)].decode("utf-8", errors="ignore")
    return target.with_name(f".{stem}{tail}")


def write_problem(target: str | os.PathLike[str], error: OSError) -> str:
    """Why writing ``target`` failed, in words (a full disk, a size limit, a quota...)."""
    target = Path(target)
    why = _WRITE_FAILURES.get(error.errno or 0, error.strerror or str(error))
    kept = "the earlier file is kept as it was" if target.exists() else "nothing was written"
    return f"{target}: cannot write: {why} ({kept})"


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success fsync it and rename it onto ``path``.

    The temporary name keeps the suffix, so writers that pick a format by extension (OpenCV,
    OpenEXR) work unchanged. On an exception the temporary file is removed and ``path`` is left
    as it was. A path that cannot be written (see :func:`output_problem`), and a write that
    fails (an ``OSError`` in the block, no file written, a failed ``fsync`` or rename: a full
    disk), are an :class:`~core.errors.InputError` naming it.
    """
    target = Path(path)
    problem = output_problem(target)
    if problem is not None:
        raise InputError(problem)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"{target}: cannot create its folder: {error.strerror}") from None
    temporary = _temporary(target, name_max(target.parent))
    try:
        try:
            yield temporary
            if not temporary.is_file():
                raise InputError(f"{target}: the writer wrote no file; nothing was written")
            with open(temporary, "rb+") as handle:
                os.fsync(handle.fileno())  # a write the disk cannot hold fails here at last
            os.replace(temporary, target)
        except OSError as error:  # a full disk, a size limit, a folder made there meanwhile
            raise InputError(write_problem(target, error)) from None
    finally:
        temporary.unlink(missing_ok=True)
    # The rename is durable only once the directory entry is on disk.
    folder = os.open(target.parent, os.O_RDONLY)
    try:
        os.fsync(folder)
    finally:
        os.close(folder)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically, checking that every byte reached the file.

    What a library encoded in memory (an image, an animation) is written here rather than by
    the library, whose own file writing may not report a failed write (OpenCV's ``imwrite``
    returns True on a full disk and leaves a cut file).
    """
    target = Path(path)
    with atomic_path(target) as temporary:
        with open(temporary, "wb") as handle:
            handle.write(data)
        written = temporary.stat().st_size
        if written != len(data):
            raise InputError(
                f"{target}: cannot write: {written} of {len(data)} bytes reached the file; "
                "nothing was replaced"
            )


def write_json_atomic(path: str | os.PathLike[str], document: Any) -> None:
    """Write ``document`` as indented JSON to ``path`` atomically."""
    write_bytes_atomic(path, (json.dumps(document, indent=2) + "\n").encode("utf-8"))
