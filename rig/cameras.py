"""Camera backends, and opening the one a rig config names.

The backends live in their own modules: :mod:`rig.camera_opencv` (UVC through OpenCV),
:mod:`rig.camera_gphoto2` (tethered DSLR, optional ``dslr`` extra), :mod:`rig.camera_replay`
(stored images served by pose); the synthetic camera of the simulated rig is
:class:`sim.simulated_camera.SimulatedCamera` (``rig/`` may not import ``sim/``).
"""

from __future__ import annotations

from core.errors import ConfigError
from rig.camera_gphoto2 import GPhoto2Camera
from rig.camera_opencv import OpenCVCamera
from rig.camera_replay import ReplayCamera, ReplayLookup
from rig.config import (
    GPhoto2CameraConfig,
    OpenCVCameraConfig,
    ReplayCameraConfig,
    RigConfig,
    SimulatedCameraConfig,
)
from rig.devices import Camera, CameraTimeoutError, Frame, RigStateSource

__all__ = [
    "Camera",
    "CameraTimeoutError",
    "Frame",
    "GPhoto2Camera",
    "OpenCVCamera",
    "ReplayCamera",
    "open_camera",
]


def open_camera(
    config: RigConfig,
    *,
    state: RigStateSource | None = None,
    replay_lookup: ReplayLookup | None = None,
) -> Camera:
    """Open the camera of ``config`` (opencv, gphoto2, or replay).

    Parameters
    ----------
    config : RigConfig
    state : callable, optional
        The rig's ``(pose, light)``; needed by the replay camera.
    replay_lookup : callable, optional
        ``(pose, light, exposure_ms) -> path``; the replay camera's source of images until the
        dataset reader exists (the capture issue).

    Raises
    ------
    ConfigError
        For a simulated camera (built by the simulated rig) or a replay camera without
        ``state`` and ``replay_lookup``.
    DeviceError
        When the device cannot be opened or configured.
    """
    camera = config.camera
    if isinstance(camera, OpenCVCameraConfig):
        return OpenCVCamera(
            camera.device,
            width=camera.width,
            height=camera.height,
            api=camera.api,
            manual_exposure=camera.manual_exposure,
            auto_exposure_off=camera.auto_exposure_off,
            exposure_unit=camera.exposure_unit,
            flush_frames=camera.flush_frames,
            timeout_s=camera.timeout_s,
        )
    if isinstance(camera, GPhoto2CameraConfig):
        return GPhoto2Camera(
            config.resolve(camera.folder),
            port=camera.port,
            keep_on_camera=camera.keep_on_camera,
            timeout_s=camera.timeout_s,
        )
    if isinstance(camera, ReplayCameraConfig):
        if state is None or replay_lookup is None:
            raise ConfigError(
                f"{config.source or 'rig config'}: a replay camera needs the rig's state and a "
                "lookup of the dataset's images"
            )
        return ReplayCamera(
            state,
            lookup=replay_lookup,
            tolerance_deg=camera.tolerance_deg,
            root=config.resolve(camera.dataset),
        )
    assert isinstance(camera, SimulatedCameraConfig)
    raise ConfigError(
        f"{config.source or 'rig config'}: the simulated camera is made by the simulated rig "
        "(sim.simulated_camera.SimulatedCamera.from_config)"
    )
