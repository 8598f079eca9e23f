"""How much memory a stage may hold at once: sizes as people write them, and a default.

The heavy stages (model fitting, held-out evaluation, batch relighting) work on chunks of
samples; their ``memory_bytes`` bounds the chunks in flight, so the peak is about that plus the
outputs, whatever the field's size. ``--max-memory`` on the command line reads a size with
:func:`parse_size`; without it :func:`default_memory_budget` takes a share of what the machine
has free when the run starts.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from core.errors import InputError

__all__ = ["available_memory", "default_memory_budget", "format_size", "parse_size"]

#: Share of the available memory a stage takes by default: the rest is for the outputs, the
#: store's caches, the other stages and the machine.
DEFAULT_SHARE = 0.25
#: Bounds on the default: below the floor chunks get too small to keep two cores busy; above the
#: ceiling a bigger chunk no longer speeds anything up.
DEFAULT_FLOOR, DEFAULT_CEILING = 256 << 20, 4 << 30

_UNITS = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}
_SIZE = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*([kmgt]?)(?:i?b)?\s*$", re.IGNORECASE)


def parse_size(text: str) -> int:
    """Bytes in a size such as ``"512M"``, ``"2G"``, ``"1.5GiB"`` or ``"1000000"``.

    Units are powers of 1024 (K, M, G, T, with an optional ``B`` or ``iB``); no unit is bytes.

    Raises
    ------
    InputError
        Not a size, or zero.
    """
    match = _SIZE.match(text)
    if match is None:
        raise InputError(f"memory size {text!r} is not a size; write it as e.g. 512M or 2G")
    size = int(float(match.group(1)) * _UNITS[match.group(2).lower()])
    if size <= 0:
        raise InputError(f"memory size {text!r} must be more than zero bytes")
    return size


def format_size(size: int) -> str:
    """``size`` bytes in the largest unit that keeps it at 1 or more, e.g. ``"1.5 GiB"``."""
    value, unit = float(size), "B"
    for name in ("KiB", "MiB", "GiB", "TiB"):
        if value < 1024:
            break
        value, unit = value / 1024, name
    if unit == "B":
        return f"{size} B"
    digits = f"{value:.3g}"
    return f"{digits if 'e' not in digits else f'{value:.0f}'} {unit}"


def available_memory() -> int:
    """Bytes the machine can give a process now (``MemAvailable``, or free pages elsewhere)."""
    meminfo = Path("/proc/meminfo")
    if meminfo.is_file():
        for line in meminfo.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def default_memory_budget() -> int:
    """The default ``memory_bytes`` of a stage.

    ``DEFAULT_SHARE`` of :func:`available_memory`, between ``DEFAULT_FLOOR`` and
    ``DEFAULT_CEILING``.
    """
    share = int(available_memory() * DEFAULT_SHARE)
    return min(max(share, DEFAULT_FLOOR), DEFAULT_CEILING)
