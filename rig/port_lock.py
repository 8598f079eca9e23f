"""One program at a time on a serial port: the lock a device takes before its port opens.

Two programs on one rig (two ``rig capture``, or a capture and a ``rig doctor``) would send
their commands down the same wire: one parks the gantry while the other moves it, GRBL refuses
what it cannot follow, and the light's state is no longer known. Each device locks its port
(:class:`core.exclusive_lock.ExclusiveLock`) before a byte is sent; the second program is told
who holds it. The lock file lives in the system's temporary folder, named after the port's
real path, so two names of one device (a ``/dev/serial/by-id`` link and ``/dev/ttyUSB0``) share
one lock.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from core.errors import DeviceError
from core.exclusive_lock import ExclusiveLock

__all__ = ["port_lock"]


def port_lock(port: str) -> ExclusiveLock:
    """The lock of serial port ``port`` (not taken: ``with port_lock(p):`` or ``acquire``)."""
    real = os.path.realpath(port)
    name = "rig-port-" + real.strip("/").replace("/", "%") + ".lock"
    return ExclusiveLock(
        Path(tempfile.gettempdir()) / name,
        what=f"the serial port {port}" + (f" ({real})" if real != port else ""),
        noun="serial port",
        rule="one program at a time drives a rig's devices",
        advice="Wait for it to finish or stop it (Ctrl-C)",
        error=DeviceError,
    )
