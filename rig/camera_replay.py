"""A camera that serves the images of an existing capture by the rig's pose.

The dataset format belongs to the capture issue, so this camera takes the mapping from poses to
image files directly: either

- ``images``: a mapping ``RigPose -> path`` (lit images; the pose holds both camera and light
  angles) with an optional ``dark``: ``RigPose -> path`` of light-off frames, matched on the
  camera axes and turntable only; a stored pose matches when no axis differs by more than
  ``tolerance_deg`` (the nearest such pose wins); or
- ``lookup``: a callable ``(pose, light, exposure_ms) -> path or None`` for anything else
  (exposure brackets, a dataset reader).

Before each capture it asks ``state`` (see :data:`~rig.devices.RigStateSource`) for the rig's
pose and light. 8/16-bit PNG/TIFF/JPEG files are decoded to RGB pixels; other files (RAW) are
returned as a path.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path

from core.errors import DeviceError, InputError
from core.image_io import ImageFileError, read_pixels
from rig.devices import Frame, LightState, RigStateSource, frame_metadata
from rig.pose import RigPose

__all__ = ["DECODED_SUFFIXES", "ReplayCamera", "ReplayLookup"]

DECODED_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
ReplayLookup = Callable[[RigPose, LightState, float], "str | os.PathLike[str] | None"]
_CAMERA_AXES = ("camera_azimuth_deg", "camera_inclination_deg", "turntable_deg")


def _distance(a: RigPose, b: RigPose, axes: tuple[str, ...]) -> float:
    return max(abs(getattr(a, axis) - getattr(b, axis)) for axis in axes)


def _nearest(
    table: Mapping[RigPose, str | os.PathLike[str]],
    pose: RigPose,
    axes: tuple[str, ...],
    tolerance_deg: float,
) -> str | os.PathLike[str] | None:
    best = min(table, key=lambda stored: _distance(stored, pose, axes), default=None)
    if best is None or _distance(best, pose, axes) > tolerance_deg:
        return None
    return table[best]


class ReplayCamera:
    """Serves stored images by pose; satisfies :class:`~rig.devices.Camera`.

    Parameters
    ----------
    state : callable
        Returns the rig's current ``(RigPose, LightState)``.
    images : mapping RigPose -> path, optional
    dark : mapping RigPose -> path, optional
    lookup : callable, optional
        Used instead of ``images`` / ``dark`` when given.
    tolerance_deg : float
    root : path, optional
        Folder that relative paths are relative to.
    """

    def __init__(
        self,
        state: RigStateSource,
        *,
        images: Mapping[RigPose, str | os.PathLike[str]] | None = None,
        dark: Mapping[RigPose, str | os.PathLike[str]] | None = None,
        lookup: ReplayLookup | None = None,
        tolerance_deg: float = 0.5,
        root: str | os.PathLike[str] | None = None,
    ) -> None:
        if (lookup is None) == (images is None):
            raise InputError("give a replay camera either images (and dark) or lookup")
        if not tolerance_deg >= 0:
            raise InputError(f"tolerance_deg must be >= 0, got {tolerance_deg}")
        self._state = state
        self._images = dict(images or {})
        self._dark = dict(dark or {})
        self._lookup = lookup
        self.tolerance_deg = tolerance_deg
        self.root = Path(root) if root is not None else None
        self._closed = False

    def _find(self, pose: RigPose, light: LightState, exposure_ms: float) -> Path:
        found: str | os.PathLike[str] | None
        if self._lookup is not None:
            found = self._lookup(pose, light, exposure_ms)
        elif light.on:
            found = _nearest(
                self._images, pose, tuple(f"{r}_deg" for r, _ in pose.items()), self.tolerance_deg
            )
        else:
            found = _nearest(self._dark, pose, _CAMERA_AXES, self.tolerance_deg)
        if found is None:
            kind = "image" if light.on else "dark frame"
            raise DeviceError(
                f"replay camera: no stored {kind} within {self.tolerance_deg:g} deg of "
                f"{pose.to_dict()}"
            )
        path = Path(found)
        return path if path.is_absolute() or self.root is None else self.root / path

    def capture(self, exposure_ms: float) -> Frame:
        """The stored image of the rig's current pose and light."""
        metadata = frame_metadata(exposure_ms, "replay", str(self.root or "memory"))
        if self._closed:
            raise DeviceError("replay camera is closed")
        pose, light = self._state()
        path = self._find(pose, light, exposure_ms)
        metadata.update(pose=pose.to_dict(), light_on=light.on, source=str(path))
        if path.suffix.lower() not in DECODED_SUFFIXES:
            if not path.is_file():
                raise DeviceError(f"replay camera: {path} is missing")
            return Frame(path=path, metadata=metadata)
        try:
            image = read_pixels(path)
        except ImageFileError as error:
            raise DeviceError(f"replay camera: cannot read {path}: {error}") from error
        return Frame(pixels=image, path=path, metadata=metadata)

    def close(self) -> None:
        """Refuse further captures (a DeviceError); closing twice is harmless."""
        self._closed = True
