"""The ``[camera]`` section of the rig config: one table per backend.

``backend`` picks the table's shape: ``opencv`` (a UVC camera through ``cv2.VideoCapture``),
``gphoto2`` (a tethered DSLR saving RAW files), ``simulated`` (the synthetic camera of the
simulated rig, with optional fault injection in ``[camera.faults]``) or ``replay`` (the images
of an existing dataset served by pose). Keys are documented in ``docs/rig-config.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any, Literal

from core.errors import ConfigError
from rig.config_schema import Table

__all__ = [
    "CAMERA_BACKENDS",
    "EXPOSURE_UNITS",
    "CameraConfig",
    "CameraFaultConfig",
    "GPhoto2CameraConfig",
    "OpenCVCameraConfig",
    "ReplayCameraConfig",
    "SimulatedCameraConfig",
    "camera_to_dict",
    "parse_camera",
]

CAMERA_BACKENDS = ("opencv", "gphoto2", "simulated", "replay")
#: How a driver's CAP_PROP_EXPOSURE number relates to time: V4L2's exposure_time_absolute
#: counts 100 microsecond steps; DirectShow and Media Foundation take log2 of seconds.
EXPOSURE_UNITS = ("100us", "log2_s")
OPENCV_APIS = ("any", "v4l2", "dshow", "msmf", "avfoundation", "gstreamer")
SIMULATED_OUTPUTS = ("linear16", "srgb8", "dng")


def _check(ok: bool, key: str, value: object, problem: str) -> None:
    if not ok:
        raise ConfigError(f"camera.{key} = {value!r} {problem}")


@dataclass(frozen=True)
class OpenCVCameraConfig:
    """A UVC camera through OpenCV, with manual exposure."""

    backend: Literal["opencv"] = "opencv"
    device: int | str = 0  # index, or a device path such as /dev/video2
    width: int | None = None
    height: int | None = None
    api: str = "any"  # capture backend: any, v4l2, dshow, msmf, avfoundation, gstreamer
    manual_exposure: bool = True
    auto_exposure_off: float = 1.0  # CAP_PROP_AUTO_EXPOSURE value meaning manual (V4L2: 1)
    exposure_unit: str = "100us"
    flush_frames: int = 4  # frames dropped before each capture (stale after a light change)
    timeout_s: float = 5.0

    def __post_init__(self) -> None:
        if isinstance(self.device, int):
            _check(self.device >= 0, "device", self.device, "must be >= 0")
        else:
            _check(bool(self.device), "device", self.device, "must name a device")
        for key in ("width", "height"):
            value = getattr(self, key)
            _check(value is None or value > 0, key, value, "must be positive")
        _check(self.api in OPENCV_APIS, "api", self.api, f"is not one of {OPENCV_APIS}")
        _check(
            self.exposure_unit in EXPOSURE_UNITS,
            "exposure_unit",
            self.exposure_unit,
            f"is not one of {EXPOSURE_UNITS}",
        )
        _check(self.flush_frames >= 0, "flush_frames", self.flush_frames, "must be >= 0")
        _check(self.timeout_s > 0, "timeout_s", self.timeout_s, "must be positive")


@dataclass(frozen=True)
class GPhoto2CameraConfig:
    """A tethered camera through libgphoto2 (the ``dslr`` extra), saving RAW files."""

    backend: Literal["gphoto2"] = "gphoto2"
    folder: str = "raw"  # where captured files are saved (relative to the config file)
    port: str | None = None  # e.g. "usb:001,005"; the first camera found when absent
    keep_on_camera: bool = False
    timeout_s: float = 30.0

    def __post_init__(self) -> None:
        _check(bool(self.folder), "folder", self.folder, "must name a folder")
        _check(self.timeout_s > 0, "timeout_s", self.timeout_s, "must be positive")


@dataclass(frozen=True)
class CameraFaultConfig:
    """Injected faults of the simulated camera (``[camera.faults]``)."""

    timeout_after: int | None = None  # captures that succeed before every later one times out
    timeout_probability: float = 0.0  # chance that any capture times out (seeded)
    seed: int = 0
    stall_s: float = 0.0  # how long a timed-out capture blocks first (capped at timeout_s)

    def __post_init__(self) -> None:
        _check(
            self.timeout_after is None or self.timeout_after >= 0,
            "faults.timeout_after",
            self.timeout_after,
            "must be >= 0",
        )
        _check(
            0.0 <= self.timeout_probability <= 1.0,
            "faults.timeout_probability",
            self.timeout_probability,
            "must be in [0, 1]",
        )
        _check(self.stall_s >= 0, "faults.stall_s", self.stall_s, "must be >= 0")


@dataclass(frozen=True)
class SimulatedCameraConfig:
    """The synthetic camera of the simulated rig (renders the scene at the current pose)."""

    backend: Literal["simulated"] = "simulated"
    scene: str = "glossy-sphere"
    points: int = 20_000
    distance: float = 4.0
    fov_deg: float = 40.0
    width: int = 256
    height: int = 256
    light_distance: float | None = None  # a point light at this distance; directional if None
    output: str = "linear16"  # linear16 or srgb8 pixels, or dng files in ``folder``
    folder: str = "raw"
    noise: bool = True
    seed: int = 0
    timeout_s: float = 5.0
    faults: CameraFaultConfig = field(default_factory=CameraFaultConfig)

    def __post_init__(self) -> None:
        _check(bool(self.scene), "scene", self.scene, "must name a scene")
        for key in ("points", "width", "height", "distance", "timeout_s"):
            _check(getattr(self, key) > 0, key, getattr(self, key), "must be positive")
        _check(0 < self.fov_deg < 180, "fov_deg", self.fov_deg, "must be in (0, 180)")
        _check(
            self.light_distance is None or self.light_distance > 0,
            "light_distance",
            self.light_distance,
            "must be positive",
        )
        _check(
            self.output in SIMULATED_OUTPUTS,
            "output",
            self.output,
            f"is not one of {SIMULATED_OUTPUTS}",
        )


@dataclass(frozen=True)
class ReplayCameraConfig:
    """The images of an existing dataset, served by the rig's pose."""

    backend: Literal["replay"] = "replay"
    dataset: str = ""  # dataset directory (relative to the config file)
    tolerance_deg: float = 0.5  # largest axis difference between the pose and a stored one

    def __post_init__(self) -> None:
        _check(bool(self.dataset), "dataset", self.dataset, "must name a dataset directory")
        _check(self.tolerance_deg >= 0, "tolerance_deg", self.tolerance_deg, "must be >= 0")


CameraConfig = OpenCVCameraConfig | GPhoto2CameraConfig | SimulatedCameraConfig | ReplayCameraConfig


def _optional_int(table: Table, name: str) -> int | None:
    value: int | None = table.integer(name, None)
    return value


def _parse_opencv(t: Table) -> OpenCVCameraConfig:
    device: int | str = 0
    if t.has("device"):
        # An index or a device path: read with the checker that matches what was written.
        device = t.integer("device") if isinstance(t.peek("device"), int) else t.string("device")
    return OpenCVCameraConfig(
        device=device,
        width=_optional_int(t, "width"),
        height=_optional_int(t, "height"),
        api=t.string("api", "any", choices=OPENCV_APIS),
        manual_exposure=t.boolean("manual_exposure", True),
        auto_exposure_off=t.number("auto_exposure_off", 1.0),
        exposure_unit=t.string("exposure_unit", "100us", choices=EXPOSURE_UNITS),
        flush_frames=t.integer("flush_frames", 4),
        timeout_s=t.number("timeout_s", 5.0),
    )


def _parse_gphoto2(t: Table) -> GPhoto2CameraConfig:
    return GPhoto2CameraConfig(
        folder=t.string("folder", "raw"),
        port=t.string("port", None),
        keep_on_camera=t.boolean("keep_on_camera", False),
        timeout_s=t.number("timeout_s", 30.0),
    )


def _parse_faults(t: Table | None) -> CameraFaultConfig:
    if t is None:
        return CameraFaultConfig()
    faults = CameraFaultConfig(
        timeout_after=_optional_int(t, "timeout_after"),
        timeout_probability=t.number("timeout_probability", 0.0),
        seed=t.integer("seed", 0),
        stall_s=t.number("stall_s", 0.0),
    )
    t.finish()
    return faults


def _parse_simulated(t: Table) -> SimulatedCameraConfig:
    return SimulatedCameraConfig(
        scene=t.string("scene", "glossy-sphere"),
        points=t.integer("points", 20_000),
        distance=t.number("distance", 4.0),
        fov_deg=t.number("fov_deg", 40.0),
        width=t.integer("width", 256),
        height=t.integer("height", 256),
        light_distance=t.number("light_distance", None),
        output=t.string("output", "linear16", choices=SIMULATED_OUTPUTS),
        folder=t.string("folder", "raw"),
        noise=t.boolean("noise", True),
        seed=t.integer("seed", 0),
        timeout_s=t.number("timeout_s", 5.0),
        faults=_parse_faults(t.table("faults", required=False)),
    )


def _parse_replay(t: Table) -> ReplayCameraConfig:
    return ReplayCameraConfig(
        dataset=t.string("dataset"), tolerance_deg=t.number("tolerance_deg", 0.5)
    )


_PARSERS: dict[str, Callable[[Table], CameraConfig]] = {
    "opencv": _parse_opencv,
    "gphoto2": _parse_gphoto2,
    "simulated": _parse_simulated,
    "replay": _parse_replay,
}


def parse_camera(table: Table) -> CameraConfig:
    """Read the ``[camera]`` table (its keys depend on ``backend``)."""
    backend = table.string("backend", choices=CAMERA_BACKENDS)
    camera: CameraConfig = _PARSERS[backend](table)
    table.finish(allowed_note=f"not a key of the {backend} backend")
    return camera


def camera_to_dict(camera: CameraConfig) -> dict[str, Any]:
    """The ``[camera]`` table of a config (None values left out, faults as a sub-table)."""
    document: dict[str, Any] = {}
    for f in fields(camera):
        value = getattr(camera, f.name)
        if isinstance(value, CameraFaultConfig):
            faults = {g.name: getattr(value, g.name) for g in fields(value)}
            value = {k: v for k, v in faults.items() if v is not None}  # TOML has no null
        if value is not None:
            document[f.name] = value
    return document
