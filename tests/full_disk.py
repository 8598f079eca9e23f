"""A full disk for real, without root: a child process under a file size limit.

``RLIMIT_FSIZE`` caps the size of every file the child writes; with ``SIGXFSZ`` ignored, a write
past the cap fails with ``EFBIG`` as a write to a full disk fails with ``ENOSPC`` (partly
written, then an error), so a writer that does not check its write leaves a cut file. No mock:
the child's real writers meet a real failing ``write``.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["ROOT", "run_limited", "writes_under_limit"]

#: The project's folder (the children import it).
ROOT = Path(__file__).resolve().parents[1]

#: Seconds a child may take: far beyond a write or a small render, short of a stuck suite.
TIMEOUT = 120


def run_limited(
    argv: Sequence[str], limit: int, *, cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``argv`` with every file it writes capped at ``limit`` bytes."""

    def lower() -> None:  # in the child, between fork and exec
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # an ignored signal stays so across exec
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    environment = os.environ | {"PYTHONPATH": str(ROOT)}
    return subprocess.run(
        list(argv), preexec_fn=lower, capture_output=True, text=True, timeout=TIMEOUT,
        cwd=cwd or ROOT, env=environment, check=False,
    )  # fmt: skip


_CHILD = """
import json, sys, traceback
from core.errors import RigError
results = []
def attempt(name, write):
    try:
        write()
    except BaseException as error:
        results.append({"name": name, "error": type(error).__name__, "message": str(error),
                        "project": isinstance(error, RigError),
                        "traceback": traceback.format_exc()})
    else:
        results.append({"name": name, "error": None, "message": "", "project": False,
                        "traceback": ""})
"""


def writes_under_limit(code: str, limit: int) -> dict[str, dict[str, Any]]:
    """Run Python ``code`` under a ``limit``-byte file cap; what each ``attempt`` gave.

    ``code`` calls ``attempt(name, write)`` for each write to try (``write`` takes no
    argument); returns, by name, ``error`` (the exception's type name or None), ``message``,
    ``project`` (whether it is one of :mod:`core.errors`) and ``traceback``. Whatever the
    child prints on stderr (a library's "Exception ignored") is in the entry ``"stderr"``.
    """
    script = _CHILD + code + "\nprint(json.dumps(results))\n"
    done = run_limited([sys.executable, "-c", script], limit)
    if done.returncode != 0:
        raise AssertionError(f"the child failed ({done.returncode}):\n{done.stderr}")
    found: dict[str, dict[str, Any]] = {
        entry["name"]: entry for entry in json.loads(done.stdout.splitlines()[-1])
    }
    found["stderr"] = {"text": done.stderr}
    return found
