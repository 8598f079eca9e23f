"""A tethered camera (DSLR, mirrorless) through libgphoto2, saving each capture's RAW file.

Needs the optional ``dslr`` extra (``pip install .[dslr]``: python-gphoto2 and libgphoto2);
the module imports it only when a camera is opened, so everything else works without it.

Each capture sets the ``shutterspeed`` config widget to the camera's listed choice nearest to
the asked exposure (refusing one more than a third of a stop away), reads the widget back,
triggers ``Camera.capture(GP_CAPTURE_IMAGE)``, downloads the file (``file_get`` with
``GP_FILE_TYPE_NORMAL``) atomically into ``folder`` and deletes it from the card unless
``keep_on_camera``. libgphoto2 calls block; the capture runs in a worker thread so a hung
camera is a :class:`~rig.devices.CameraTimeoutError` after ``timeout_s`` (the camera must then
be reopened).
"""

from __future__ import annotations

import concurrent.futures
import importlib
import math
import os
from pathlib import Path
from typing import Any

from core.atomic import atomic_path
from core.errors import DeviceError
from rig.devices import CameraTimeoutError, Frame, frame_metadata

__all__ = ["GPhoto2Camera", "import_gphoto2", "shutter_seconds"]

#: A third of a stop: the largest exposure mismatch accepted when picking a shutter speed.
THIRD_STOP = 2.0 ** (1.0 / 3.0)


def import_gphoto2() -> Any:
    """The ``gphoto2`` module, or a DeviceError saying how to install it."""
    try:
        return importlib.import_module("gphoto2")
    except ImportError:
        raise DeviceError(
            "the gphoto2 camera backend needs python-gphoto2 and libgphoto2; install the "
            "optional extra with `pip install .[dslr]`"
        ) from None


def shutter_seconds(choice: str) -> float | None:
    """Seconds of a shutter-speed choice such as ``1/60``, ``0.5``, ``2"`` or ``30s``.

    Returns None for choices that are not times (``Bulb``, ``Time``, ``auto``).
    """
    text = choice.strip().rstrip('s"').strip()
    try:
        if "/" in text:
            numerator, denominator = text.split("/", 1)
            value = float(numerator) / float(denominator)
        else:
            value = float(text)
    except (ValueError, ZeroDivisionError):
        return None
    return value if math.isfinite(value) and value > 0 else None


class GPhoto2Camera:
    """A libgphoto2 camera satisfying :class:`~rig.devices.Camera`; frames carry a RAW path.

    Parameters
    ----------
    folder : path
        Where captured files are written (created if missing).
    port : str, optional
        libgphoto2 port such as ``"usb:001,005"``; the first camera found when None.
    keep_on_camera : bool
        Leave each file on the memory card too.
    timeout_s : float
        Longest wait for one capture and download.
    """

    def __init__(
        self,
        folder: str | os.PathLike[str],
        *,
        port: str | None = None,
        keep_on_camera: bool = False,
        timeout_s: float = 30.0,
    ) -> None:
        self._gp = import_gphoto2()
        self.folder = Path(folder)
        self.port = port
        self.keep_on_camera = keep_on_camera
        self.timeout_s = timeout_s
        self._count = 0
        self._worker: concurrent.futures.ThreadPoolExecutor | None = None
        self._camera: Any = self._gp.Camera()
        try:
            if port is not None:
                ports = self._gp.PortInfoList()
                ports.load()
                self._camera.set_port_info(ports[ports.lookup_path(port)])
            self._camera.init()
        except self._gp.GPhoto2Error as error:
            self._camera = None
            where = f" at {port}" if port else ""
            raise DeviceError(f"gphoto2: no usable camera{where}: {error}") from None
        self._worker = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="gphoto2")

    @property
    def _name(self) -> str:
        return f"gphoto2 camera {self.port or '(auto)'}"

    def __enter__(self) -> GPhoto2Camera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _set_shutter(self, exposure_ms: float) -> tuple[str, float]:
        config = self._camera.get_config()
        widget = config.get_child_by_name("shutterspeed")
        timed = [(c, s) for c in widget.get_choices() if (s := shutter_seconds(c)) is not None]
        if not timed:
            raise DeviceError(f"{self._name} lists no shutter speeds (is it in manual mode?)")
        wanted = exposure_ms / 1000.0
        choice, seconds = min(timed, key=lambda cs: abs(math.log(cs[1] / wanted)))
        if max(seconds / wanted, wanted / seconds) > THIRD_STOP:
            raise DeviceError(
                f"{self._name}: no shutter speed near {exposure_ms:g} ms (nearest {choice!r}); "
                "use exposures the camera offers"
            )
        widget.set_value(choice)
        self._camera.set_config(config)
        got = self._camera.get_config().get_child_by_name("shutterspeed").get_value()
        if got != choice:
            raise DeviceError(f"{self._name} ignored shutterspeed: set {choice!r}, read {got!r}")
        return choice, seconds

    def _capture_file(self) -> tuple[Path, str]:
        gp = self._gp
        where = self._camera.capture(gp.GP_CAPTURE_IMAGE)
        self._count += 1
        target = self.folder / f"{self._count:06d}_{where.name}"
        camera_file = self._camera.file_get(where.folder, where.name, gp.GP_FILE_TYPE_NORMAL)
        with atomic_path(target) as temporary:
            camera_file.save(str(temporary))
        if not self.keep_on_camera:
            self._camera.file_delete(where.folder, where.name)
        return target, f"{where.folder}/{where.name}"

    def capture(self, exposure_ms: float) -> Frame:
        """Set the shutter, capture, download the file; see the module notes."""
        metadata = frame_metadata(exposure_ms, "gphoto2", self.port or "auto")
        if self._camera is None or self._worker is None:
            raise DeviceError(f"{self._name} is closed or was lost after a timeout; reopen it")
        gp = self._gp
        try:
            choice, seconds = self._set_shutter(exposure_ms)
            future = self._worker.submit(self._capture_file)
            path, on_camera = future.result(timeout=self.timeout_s)
        except concurrent.futures.TimeoutError:
            # The worker is still inside libgphoto2: the camera's state is unknown.
            self._worker.shutdown(wait=False, cancel_futures=True)
            self._worker = None
            raise CameraTimeoutError(
                f"{self._name}: no image within {self.timeout_s:g} s; reconnect the camera"
            ) from None
        except gp.GPhoto2Error as error:
            if getattr(error, "code", None) == getattr(gp, "GP_ERROR_TIMEOUT", None):
                raise CameraTimeoutError(f"{self._name}: {error}") from None
            raise DeviceError(f"{self._name}: {error}") from None
        metadata.update(
            shutterspeed=choice, exposure_ms_device=seconds * 1000.0, camera_file=on_camera
        )
        return Frame(path=path, metadata=metadata)

    def close(self) -> None:
        """Stop the capture worker and release the camera; closing twice is harmless."""
        if self._worker is not None:
            self._worker.shutdown(wait=True)
            self._worker = None
        if self._camera is not None:
            try:
                self._camera.exit()
            except self._gp.GPhoto2Error:
                pass  # the camera may already be gone; nothing else to release
            self._camera = None
