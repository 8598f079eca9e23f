"""Atomic file output: a file named by the project is never seen half-written."""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from core.errors import InputError

__all__ = ["atomic_path", "output_problem", "write_json_atomic"]


def output_problem(path: str | os.PathLike[str], *, directory: bool = False) -> str | None:
    """Why ``path`` cannot be written as a file (or, with ``directory``, a folder), or None.

    Checked before any work starts, so that a long render or capture does not end in an
    ``IsADirectoryError``: a folder where a file is wanted (or a file where a folder is), a
    file standing where a parent folder must be, a parent that cannot be written.
    """
    target = Path(path)
    for parent in reversed(target.parents):
        if parent.exists() and not parent.is_dir():
            return f"{target}: {parent} is a file, not a directory"
    if directory and target.exists() and not target.is_dir():
        return f"{target}: exists and is a file, not a directory; choose another path"
    if not directory and target.is_dir():
        return f"{target}: is a directory; name a file to write"
    nearest = next((p for p in (target, *target.parents) if p.exists()), Path("."))
    if not os.access(nearest, os.W_OK):
        return f"{target}: cannot write in {nearest} (permission denied)"
    return None


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success fsync it and rename it onto ``path``.

    The temporary name keeps the suffix, so writers that pick a format by extension (OpenCV,
    OpenEXR) work unchanged. On an exception the temporary file is removed and ``path`` is left
    as it was. A path that cannot be written (see :func:`output_problem`) is an
    :class:`~core.errors.InputError` naming it.
    """
    target = Path(path)
    problem = output_problem(target)
    if problem is not None:
        raise InputError(problem)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"{target}: cannot create its folder: {error.strerror}") from None
    temporary = target.with_name(f".{target.stem}.{os.getpid()}.partial{target.suffix}")
    try:
        yield temporary
        with open(temporary, "rb+") as handle:
            os.fsync(handle.fileno())
        try:
            os.replace(temporary, target)
        except OSError as error:  # a folder made at the target meanwhile, a full disk
            raise InputError(f"{target}: cannot write: {error.strerror}") from None
    finally:
        temporary.unlink(missing_ok=True)
    # The rename is durable only once the directory entry is on disk.
    directory = os.open(target.parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


def write_json_atomic(path: str | os.PathLike[str], document: Any) -> None:
    """Write ``document`` as indented JSON to ``path`` atomically."""
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
