"""A UVC camera through OpenCV's ``VideoCapture``, with manual exposure checked by read-back.

OpenCV's camera properties are backend specific and a driver may accept, refuse or silently
ignore a ``set``: every set here is checked by reading the property back, and a refused or
ignored one is a :class:`~core.errors.DeviceError` naming the property, the value and the
backend. Manual exposure is ``CAP_PROP_AUTO_EXPOSURE = auto_exposure_off`` (V4L2: 1, the
``V4L2_EXPOSURE_MANUAL`` menu entry; DirectShow: 0.25) followed by ``CAP_PROP_EXPOSURE`` in the
driver's unit (V4L2 ``exposure_time_absolute``: 100 microsecond steps; DirectShow and Media
Foundation: log2 of seconds).

A UVC camera streams continuously and the driver queues a few frames (V4L2 in OpenCV: 4
buffers), so a frame read right after a move or a light change was exposed before it. Each
capture therefore grabs and drops ``flush_frames`` frames first, then returns the next one.
No frame within ``timeout_s`` is a :class:`~rig.devices.CameraTimeoutError`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from core.errors import DeviceError, InputError
from rig.devices import CameraTimeoutError, Frame, frame_metadata

__all__ = [
    "OPENCV_APIS",
    "OpenCVCamera",
    "VideoCaptureLike",
    "exposure_from_property",
    "exposure_to_property",
]

OPENCV_APIS = {
    "any": cv2.CAP_ANY,
    "v4l2": cv2.CAP_V4L2,
    "dshow": cv2.CAP_DSHOW,
    "msmf": cv2.CAP_MSMF,
    "avfoundation": cv2.CAP_AVFOUNDATION,
    "gstreamer": cv2.CAP_GSTREAMER,
}
_POLL_S = 0.005


class VideoCaptureLike(Protocol):
    """The part of ``cv2.VideoCapture`` the camera uses (tests substitute fakes)."""

    def isOpened(self) -> bool:
        """Whether the device is open."""
        ...

    def set(self, propId: int, value: float) -> bool:
        """Set the property ``propId`` to ``value``; whether the driver accepted it."""
        ...

    def get(self, propId: int) -> float:
        """The value of the property ``propId``."""
        ...

    def grab(self) -> bool:
        """Grab the next frame from the device; whether one came."""
        ...

    def retrieve(self) -> tuple[bool, Any]:
        """Decode the grabbed frame: ``(ok, image)``, the image in BGR (or BGRA, or grey)."""
        ...

    def release(self) -> None:
        """Close the device."""
        ...


def exposure_to_property(exposure_ms: float, unit: str) -> float:
    """The ``CAP_PROP_EXPOSURE`` value for ``exposure_ms`` in the driver's ``unit``."""
    if unit == "100us":
        return exposure_ms * 10.0
    if unit == "log2_s":
        return math.log2(exposure_ms / 1000.0)
    raise InputError(f"unknown exposure unit {unit!r}; use '100us' or 'log2_s'")


def exposure_from_property(value: float, unit: str) -> float:
    """Milliseconds of a ``CAP_PROP_EXPOSURE`` value in the driver's ``unit``."""
    if unit == "100us":
        return value / 10.0
    if unit == "log2_s":
        return 1000.0 * 2.0**value
    raise InputError(f"unknown exposure unit {unit!r}; use '100us' or 'log2_s'")


def _open_capture(device: int | str, api: int) -> VideoCaptureLike:
    # Two calls because VideoCapture's index and filename constructors are separate overloads.
    if isinstance(device, int):
        return cv2.VideoCapture(device, api)
    return cv2.VideoCapture(device, api)


class OpenCVCamera:
    """A UVC (or any OpenCV-readable) camera satisfying :class:`~rig.devices.Camera`.

    Parameters
    ----------
    device : int or str
        Camera index, or a device path / URL / video file.
    width, height : int, optional
        Frame size to request (checked).
    api : str
        One of :data:`OPENCV_APIS` (``"v4l2"`` on Linux makes the property semantics definite).
    manual_exposure : bool
        Switch auto exposure off at open and set the exposure of every capture. False leaves
        the camera's exposure alone (``exposure_ms`` is then only recorded).
    auto_exposure_off : float
        The ``CAP_PROP_AUTO_EXPOSURE`` value that means manual on this backend.
    exposure_unit : {"100us", "log2_s"}
    flush_frames : int
        Frames dropped before each capture.
    timeout_s : float
        Longest wait for the frames of one capture.
    exposure_tolerance : float
        Largest relative difference between the exposure asked and the one read back.
    capture_factory : callable, optional
        ``(device, api) -> VideoCaptureLike``; default ``cv2.VideoCapture``.
    """

    def __init__(
        self,
        device: int | str = 0,
        *,
        width: int | None = None,
        height: int | None = None,
        api: str = "any",
        manual_exposure: bool = True,
        auto_exposure_off: float = 1.0,
        exposure_unit: str = "100us",
        flush_frames: int = 4,
        timeout_s: float = 5.0,
        exposure_tolerance: float = 0.05,
        capture_factory: Callable[[int | str, int], VideoCaptureLike] | None = None,
    ) -> None:
        if api not in OPENCV_APIS:
            raise InputError(f"unknown OpenCV api {api!r}; use one of {', '.join(OPENCV_APIS)}")
        exposure_to_property(1.0, exposure_unit)  # validates the unit
        if flush_frames < 0 or not timeout_s > 0:
            raise InputError(
                f"need flush_frames >= 0 and timeout_s > 0, got {flush_frames}, {timeout_s}"
            )
        self.device = device
        self.api = api
        self.manual_exposure = manual_exposure
        self.auto_exposure_off = auto_exposure_off
        self.exposure_unit = exposure_unit
        self.flush_frames = flush_frames
        self.timeout_s = timeout_s
        self.exposure_tolerance = exposure_tolerance
        self._exposure_ms: float | None = None
        self._device_exposure_ms: float | None = None
        factory = capture_factory or _open_capture
        self._capture: VideoCaptureLike | None = factory(device, OPENCV_APIS[api])
        if not self._capture.isOpened():
            self._capture = None
            raise DeviceError(
                f"camera {device!r} (OpenCV api {api}) could not be opened: check the index or "
                "path, the permissions, and that no other program holds it"
            )
        try:
            if width is not None:
                self._set_checked("CAP_PROP_FRAME_WIDTH", float(width))
            if height is not None:
                self._set_checked("CAP_PROP_FRAME_HEIGHT", float(height))
            if manual_exposure:
                self._set_checked("CAP_PROP_AUTO_EXPOSURE", auto_exposure_off)
        except DeviceError:
            self.close()
            raise

    def __enter__(self) -> OpenCVCamera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def _name(self) -> str:
        return f"camera {self.device!r} (OpenCV api {self.api})"

    def _open(self) -> VideoCaptureLike:
        if self._capture is None:
            raise DeviceError(f"{self._name} is closed")
        return self._capture

    def _set_checked(self, name: str, value: float, tolerance: float = 1e-6) -> float:
        """Set a property and read it back; returns the value read."""
        capture = self._open()
        prop = getattr(cv2, name)
        if not capture.set(prop, value):
            raise DeviceError(
                f"{self._name}: the driver refused {name} = {value:g} (set returned False); "
                "this camera or backend does not support it"
            )
        got = capture.get(prop)
        if not abs(got - value) <= tolerance:
            raise DeviceError(
                f"{self._name}: the driver ignored {name}: set {value:g}, read back {got:g}"
            )
        return got

    def _set_exposure(self, exposure_ms: float) -> None:
        if exposure_ms == self._exposure_ms:
            return
        wanted = exposure_to_property(exposure_ms, self.exposure_unit)
        # The driver rounds to its own steps: compare in milliseconds, relative to the request.
        tolerance = abs(
            wanted
            - exposure_to_property(exposure_ms * (1 + self.exposure_tolerance), self.exposure_unit)
        )
        got = self._set_checked("CAP_PROP_EXPOSURE", wanted, tolerance)
        self._exposure_ms = exposure_ms
        self._device_exposure_ms = exposure_from_property(got, self.exposure_unit)

    def _grab(self, deadline: float) -> bool:
        if time.monotonic() > deadline:
            raise CameraTimeoutError(f"{self._name}: no frame within {self.timeout_s:g} s")
        if self._open().grab():
            return True
        time.sleep(_POLL_S)
        return False

    def capture(self, exposure_ms: float) -> Frame:
        """Drop stale frames, then return the next one as RGB (see the module notes)."""
        metadata = frame_metadata(exposure_ms, "opencv", str(self.device))
        if self.manual_exposure:
            self._set_exposure(exposure_ms)
        deadline = time.monotonic() + self.timeout_s
        dropped = 0
        while dropped < self.flush_frames:
            dropped += self._grab(deadline)
        image: NDArray[Any] | None = None
        while image is None:
            if self._grab(deadline):
                ok, retrieved = self._open().retrieve()
                image = np.asarray(retrieved) if ok and retrieved is not None else None
        metadata["timestamp"] = time.time()
        metadata["exposure_controlled"] = self.manual_exposure
        if self.manual_exposure:
            metadata["exposure_ms_device"] = self._device_exposure_ms
        metadata["frames_dropped"] = dropped
        return Frame(pixels=_to_rgb(image), metadata=metadata)

    def close(self) -> None:
        """Release the device; closing twice is harmless."""
        if self._capture is not None:
            self._capture.release()
            self._capture = None


def _to_rgb(image: NDArray[Any]) -> NDArray[Any]:
    """OpenCV's BGR (or BGRA) to RGB; grey frames stay (H, W)."""
    if image.ndim == 3 and image.shape[2] == 3:
        return np.ascontiguousarray(image[:, :, ::-1])
    if image.ndim == 3 and image.shape[2] == 4:
        return np.ascontiguousarray(image[:, :, 2::-1])
    return image
