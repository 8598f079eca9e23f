"""The small typed interfaces the capture executor uses; real and simulated devices satisfy them.

- :class:`Camera`: ``capture(exposure_ms) -> Frame`` and ``close()``.
- :class:`LightSource`: ``light_on(intensity)`` and ``light_off()``.
- :class:`PoseAxes`: a group of axes driven by one device (the servo chain, the gantry), moved
  together in rig degrees by role name.

The executor never knows whether it holds a real driver or a simulated one. Servo ticks, G-code
and driver property numbers never cross these interfaces.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from core.errors import DeviceError, InputError, RigError
from rig.pose import RigPose

__all__ = [
    "Camera",
    "CameraTimeoutError",
    "Frame",
    "LightSource",
    "LightState",
    "PoseAxes",
    "RigStateSource",
    "close_after",
    "frame_metadata",
]


class CameraTimeoutError(DeviceError):
    """A camera delivered no frame within its timeout (the capture may be retried)."""


@dataclass(frozen=True, eq=False)
class Frame:
    """One captured image: pixels in memory, or a file the camera wrote (RAW), or both.

    Attributes
    ----------
    pixels : ndarray or None
        ``(H, W, 3)`` RGB (uint8 sRGB, uint16 linear) or ``(H, W)``; never BGR.
    path : Path or None
        A file written by the camera (a DSLR's RAW file, a simulated DNG).
    metadata : mapping, read-only
        At least ``exposure_ms`` (as requested), ``timestamp`` (seconds since the epoch),
        ``backend`` and ``device``; backends add what they know (the exposure read back, the
        pose of a simulated or replayed frame, the source file).
    """

    pixels: NDArray[Any] | None = None
    path: Path | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.pixels is None and self.path is None:
            raise InputError("a frame needs pixels or a file path")
        if self.pixels is not None and self.pixels.ndim not in (2, 3):
            raise InputError(f"frame pixels must be (H, W) or (H, W, C), got {self.pixels.shape}")
        missing = [
            k for k in ("exposure_ms", "timestamp", "backend", "device") if k not in self.metadata
        ]
        if missing:
            raise InputError(f"frame metadata lacks {', '.join(missing)}")
        # Frozen means frozen: a frame handed to the dataset writer cannot change under it.
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))
        if self.pixels is not None:
            # A read-only view, not a copy: a full-size RAW frame is large.
            pixels = np.asarray(self.pixels).view()
            pixels.flags.writeable = False
            object.__setattr__(self, "pixels", pixels)

    @property
    def exposure_ms(self) -> float:
        """The exposure requested, milliseconds (``metadata["exposure_ms"]``)."""
        return float(self.metadata["exposure_ms"])


def frame_metadata(exposure_ms: float, backend: str, device: str, **extra: Any) -> dict[str, Any]:
    """The common metadata of a frame taken now, plus backend extras."""
    if not (math.isfinite(exposure_ms) and exposure_ms > 0):
        raise InputError(f"exposure_ms must be a positive number, got {exposure_ms}")
    return {
        "exposure_ms": float(exposure_ms),
        "timestamp": time.time(),
        "backend": backend,
        "device": device,
        **extra,
    }


@runtime_checkable
class Camera(Protocol):
    """Anything that takes a picture at a given exposure."""

    def capture(self, exposure_ms: float) -> Frame:
        """Take one frame exposed for ``exposure_ms`` milliseconds.

        Frames buffered before the call (before the last move or light change) are never
        returned. Raises :class:`CameraTimeoutError` when no frame arrives in time and
        :class:`~core.errors.DeviceError` for other faults.
        """
        ...

    def close(self) -> None:
        """Release the device; closing twice is harmless."""
        ...


@dataclass(frozen=True)
class LightState:
    """Whether the light is on, and at what intensity in [0, 1]."""

    on: bool = False
    intensity: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.intensity) and 0.0 <= self.intensity <= 1.0):
            raise InputError(f"light intensity must be in [0, 1], got {self.intensity}")

    @property
    def level(self) -> float:
        """The effective intensity: 0 when off."""
        return self.intensity if self.on else 0.0


#: What a pose-aware camera (simulated, replay) asks for before each capture: the rig's current
#: pose and light. The simulated rig reads it from its emulators; tests pass a plain function.
RigStateSource = Callable[[], tuple[RigPose, LightState]]


@runtime_checkable
class LightSource(Protocol):
    """The rig's light."""

    def light_on(self, intensity: float = 1.0) -> None:
        """Switch the light on at ``intensity`` in (0, 1] (on/off lights ignore the level)."""
        ...

    def light_off(self) -> None:
        """Switch the light off; safe to call at any time, also after an error."""
        ...


@runtime_checkable
class PoseAxes(Protocol):
    """Axes driven by one device, addressed by role (``camera_azimuth``...) in rig degrees."""

    @property
    def roles(self) -> tuple[str, ...]:
        """The roles this device drives."""
        ...

    def move_to_deg(self, targets: Mapping[str, float]) -> None:
        """Start a synchronised move of some of its axes to ``{role: degrees}``.

        Limits and forbidden zones are checked by the caller (:mod:`rig.safety`) and again by
        the driver before anything is sent.
        """
        ...

    def wait_until_arrived(self, timeout_s: float) -> None:
        """Block until every axis is at its target; DeviceError on timeout or fault."""
        ...

    def position_deg(self) -> dict[str, float]:
        """The measured position of every axis, ``{role: degrees}``."""
        ...

    def stop(self) -> None:
        """Stop motion now (safe to call at any time)."""
        ...

    def close(self) -> None:
        """Leave the device safe (torque off, motion stopped) and release the port."""
        ...


def close_after(close: Callable[[], None], error: BaseException | None) -> None:
    """Close a device on leaving a ``with`` block, keeping the error that ended the block.

    Leaving on ``error``, a failure to close becomes a note on that error instead of replacing
    it (the cause matters more).
    """
    if error is None:
        close()
        return
    try:
        close()
    except RigError as failure:
        error.add_note(str(failure))
