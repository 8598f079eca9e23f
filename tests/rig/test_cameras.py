from __future__ import annotations

import dataclasses
import sys
import threading
import time
import types
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from core.errors import ConfigError, DeviceError, InputError
from rig.camera_gphoto2 import GPhoto2Camera, shutter_seconds
from rig.camera_opencv import OpenCVCamera, exposure_from_property, exposure_to_property
from rig.camera_replay import ReplayCamera
from rig.cameras import open_camera
from rig.config import (
    GPhoto2CameraConfig,
    OpenCVCameraConfig,
    ReplayCameraConfig,
    simulated_config,
)
from rig.devices import Camera, CameraTimeoutError, Frame, LightState
from rig.pose import RigPose

FRAMES = 8


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short MJPEG video: frame i is uniform with RGB (0, 20 i, 200) (BGR on disk)."""
    path = tmp_path_factory.mktemp("video") / "frames.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (64, 48))
    assert writer.isOpened()
    for i in range(FRAMES):
        bgr = np.zeros((48, 64, 3), np.uint8)
        bgr[:, :, 0], bgr[:, :, 1] = 200, 20 * i
        writer.write(bgr)
    writer.release()
    return path


def _frame_index(frame: Frame) -> int:
    assert frame.pixels is not None
    red, green, blue = (float(frame.pixels[:, :, c].mean()) for c in range(3))
    assert red < 10 and blue > 180  # RGB order, not BGR
    return round(green / 20)


# --- OpenCV: a real VideoCapture on a video file -------------------------------------------


def test_a_refused_exposure_mode_is_a_device_error_naming_the_property(video: Path) -> None:
    with pytest.raises(DeviceError, match=r"refused CAP_PROP_AUTO_EXPOSURE = 1 \(set returned"):
        OpenCVCamera(str(video))


def test_a_refused_frame_size_is_a_device_error(video: Path) -> None:
    with pytest.raises(DeviceError, match=r"refused CAP_PROP_FRAME_WIDTH = 640"):
        OpenCVCamera(str(video), width=640, manual_exposure=False)


def test_stale_frames_are_dropped_before_each_capture(video: Path) -> None:
    with OpenCVCamera(str(video), manual_exposure=False, flush_frames=2) as camera:
        assert isinstance(camera, Camera)
        first = camera.capture(10.0)
        assert _frame_index(first) == 2  # frames 0 and 1 were dropped
        assert _frame_index(camera.capture(10.0)) == 5
        assert first.metadata["frames_dropped"] == 2
        assert first.metadata["exposure_controlled"] is False
        assert first.metadata["backend"] == "opencv" and first.exposure_ms == 10.0


def test_no_frame_within_the_timeout(video: Path) -> None:
    camera = OpenCVCamera(str(video), manual_exposure=False, flush_frames=0, timeout_s=0.2)
    for _ in range(FRAMES):
        camera.capture(5.0)
    started = time.monotonic()
    with pytest.raises(CameraTimeoutError, match=r"no frame within 0\.2 s"):
        camera.capture(5.0)  # the file has ended: nothing more arrives
    assert 0.2 <= time.monotonic() - started < 2.0
    camera.close()
    camera.close()
    with pytest.raises(DeviceError, match="is closed"):
        camera.capture(5.0)


def test_a_missing_device_is_a_device_error(tmp_path: Path) -> None:
    with pytest.raises(DeviceError, match="could not be opened"):
        OpenCVCamera(str(tmp_path / "no-such-video.avi"), manual_exposure=False)


def test_exposure_units() -> None:
    assert exposure_to_property(12.5, "100us") == pytest.approx(125.0)
    assert exposure_to_property(125.0, "log2_s") == pytest.approx(-3.0)
    for unit in ("100us", "log2_s"):
        assert exposure_from_property(exposure_to_property(7.0, unit), unit) == pytest.approx(7.0)
    with pytest.raises(InputError, match="unknown exposure unit"):
        exposure_to_property(1.0, "ms")


class FakeCapture:
    """A driver that rounds exposure to its steps, or ignores it, or never delivers."""

    def __init__(self, *, ignore_exposure: bool = False, frames: bool = True) -> None:
        self.props: dict[int, float] = {cv2.CAP_PROP_AUTO_EXPOSURE: 3.0}
        self.ignore_exposure = ignore_exposure
        self.frames = frames
        self.grabs = 0

    def isOpened(self) -> bool:
        return True

    def set(self, prop: int, value: float) -> bool:
        if prop == cv2.CAP_PROP_EXPOSURE and self.ignore_exposure:
            return True  # says yes, does nothing: the case a read-back catches
        self.props[prop] = float(round(value)) if prop == cv2.CAP_PROP_EXPOSURE else value
        return True

    def get(self, prop: int) -> float:
        return self.props.get(prop, 0.0)

    def grab(self) -> bool:
        self.grabs += self.frames
        return self.frames

    def retrieve(self) -> tuple[bool, Any]:
        return True, np.full((4, 6, 3), self.grabs, np.uint8)

    def release(self) -> None:
        pass


def _fake_camera(capture: FakeCapture, **kwargs: Any) -> OpenCVCamera:
    return OpenCVCamera(0, capture_factory=lambda device, api: capture, **kwargs)


def test_manual_exposure_is_set_and_read_back() -> None:
    capture = FakeCapture()
    camera = _fake_camera(capture, flush_frames=3)
    assert capture.props[cv2.CAP_PROP_AUTO_EXPOSURE] == 1.0
    frame = camera.capture(12.5)
    assert capture.props[cv2.CAP_PROP_EXPOSURE] == 125.0
    assert frame.metadata["exposure_ms_device"] == pytest.approx(12.5)
    assert capture.grabs == 4 and frame.pixels is not None and frame.pixels[0, 0, 0] == 4


def test_an_ignored_exposure_is_a_device_error() -> None:
    camera = _fake_camera(FakeCapture(ignore_exposure=True))
    with pytest.raises(DeviceError, match=r"ignored CAP_PROP_EXPOSURE: set 100, read back 0"):
        camera.capture(10.0)


def test_an_exposure_the_driver_cannot_make_is_refused() -> None:
    # log2 seconds in whole steps: 10 ms becomes 2^-7 s = 7.8 ms, 22 % short.
    camera = _fake_camera(FakeCapture(), exposure_unit="log2_s")
    with pytest.raises(
        DeviceError, match=r"ignored CAP_PROP_EXPOSURE: set -6\.64386, read back -7"
    ):
        camera.capture(10.0)
    assert camera.capture(1000.0 / 128).metadata["exposure_ms_device"] == pytest.approx(7.8125)


def test_a_camera_that_never_delivers_times_out() -> None:
    camera = _fake_camera(FakeCapture(frames=False), timeout_s=0.1)
    with pytest.raises(CameraTimeoutError, match=r"camera 0 \(OpenCV api any\): no frame"):
        camera.capture(10.0)


def test_bad_exposures_are_refused_before_the_device() -> None:
    capture = FakeCapture()
    camera = _fake_camera(capture)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="exposure_ms must be a positive number"):
            camera.capture(bad)
    assert capture.grabs == 0


# --- gphoto2 -------------------------------------------------------------------------------


def test_gphoto2_missing_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "gphoto2", None)  # import gphoto2 raises ImportError
    with pytest.raises(DeviceError, match=r"pip install \.\[dslr\]"):
        GPhoto2Camera("raw")


def test_shutter_speed_choices() -> None:
    assert shutter_seconds("1/60") == pytest.approx(1 / 60)
    assert shutter_seconds("0.3") == pytest.approx(0.3)
    assert shutter_seconds('2"') == pytest.approx(2.0)
    assert shutter_seconds("30s") == pytest.approx(30.0)
    assert shutter_seconds("Bulb") is None
    assert shutter_seconds("1/0") is None


class FakeGPhoto2Error(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(f"[{code}] fake error")
        self.code = code


def _fake_gphoto2(hang: threading.Event | None = None, fail_code: int | None = None) -> Any:
    """Enough of python-gphoto2's object API for the driver (names as in its documentation)."""
    module = types.SimpleNamespace(
        GPhoto2Error=FakeGPhoto2Error,
        GP_CAPTURE_IMAGE=0,
        GP_FILE_TYPE_NORMAL=1,
        GP_ERROR_TIMEOUT=-10,
        cards={"/store_00010001/DCIM/100CANON": {}},
    )

    class Widget:
        def __init__(self, value: str) -> None:
            self.value = value

        def get_choices(self) -> list[str]:
            return ["Bulb", "1/4000", "1/125", "1/60", "1/30", "0.5", "1", "2"]

        def set_value(self, value: str) -> None:
            self.value = value

        def get_value(self) -> str:
            return self.value

    class Config:
        def __init__(self, shutter: str) -> None:
            self.shutter = Widget(shutter)

        def get_child_by_name(self, name: str) -> Widget:
            assert name == "shutterspeed"
            return self.shutter

    class CameraFile:
        def __init__(self, data: bytes) -> None:
            self.data = data

        def save(self, path: str) -> None:
            Path(path).write_bytes(self.data)

    class Camera:
        def __init__(self) -> None:
            self.shutter = "1/125"
            self.count = 0
            self.exited = False

        def init(self) -> None:
            pass

        def get_config(self) -> Config:
            return Config(self.shutter)

        def set_config(self, config: Config) -> None:
            self.shutter = config.shutter.value

        def capture(self, kind: int) -> Any:
            if hang is not None:
                hang.wait(5.0)
            if fail_code is not None:
                raise FakeGPhoto2Error(fail_code)
            self.count += 1
            name = f"IMG_{self.count:04d}.CR2"
            folder = "/store_00010001/DCIM/100CANON"
            module.cards[folder][name] = f"raw {self.count} at {self.shutter}".encode()
            return types.SimpleNamespace(folder=folder, name=name)

        def file_get(self, folder: str, name: str, kind: int) -> CameraFile:
            return CameraFile(module.cards[folder][name])

        def file_delete(self, folder: str, name: str) -> None:
            del module.cards[folder][name]

        def exit(self) -> None:
            self.exited = True

    module.Camera = Camera
    return module


def test_gphoto2_capture_saves_the_raw_file(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    fake = _fake_gphoto2()
    monkeypatch.setitem(sys.modules, "gphoto2", fake)
    with GPhoto2Camera(tmp_path / "raw") as camera:
        frame = camera.capture(16.0)
        assert frame.path == tmp_path / "raw" / "000001_IMG_0001.CR2"
        assert frame.path.read_bytes() == b"raw 1 at 1/60"
        assert frame.pixels is None
        assert frame.metadata["shutterspeed"] == "1/60"
        assert frame.metadata["exposure_ms_device"] == pytest.approx(1000 / 60)
        assert fake.cards["/store_00010001/DCIM/100CANON"] == {}  # deleted from the card
        with pytest.raises(DeviceError, match=r"no shutter speed near 200 ms \(nearest '0\.5'\)"):
            camera.capture(200.0)


def test_gphoto2_timeouts(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "gphoto2", _fake_gphoto2(fail_code=-10))
    with pytest.raises(CameraTimeoutError, match=r"fake error"):
        GPhoto2Camera(tmp_path).capture(16.0)
    monkeypatch.setitem(sys.modules, "gphoto2", _fake_gphoto2(fail_code=-7))
    with pytest.raises(DeviceError, match=r"\[-7\] fake error"):
        GPhoto2Camera(tmp_path).capture(16.0)
    hang = threading.Event()
    monkeypatch.setitem(sys.modules, "gphoto2", _fake_gphoto2(hang=hang))
    camera = GPhoto2Camera(tmp_path, timeout_s=0.1)
    try:
        with pytest.raises(CameraTimeoutError, match=r"no image within 0\.1 s"):
            camera.capture(16.0)
        with pytest.raises(DeviceError, match="lost after a timeout; reopen it"):
            camera.capture(16.0)
    finally:
        hang.set()
        camera.close()


# --- replay --------------------------------------------------------------------------------


def _write(path: Path, value: int) -> Path:
    cv2.imwrite(str(path), np.full((4, 4, 3), (10, 20, value), np.uint8))  # BGR
    return path


def test_replay_serves_the_image_of_the_nearest_pose(tmp_path: Path) -> None:
    lit = {
        RigPose(0.0, 45.0, 90.0, 30.0): _write(tmp_path / "a.png", 100),
        RigPose(0.0, 45.0, 120.0, 30.0): _write(tmp_path / "b.png", 200),
    }
    dark = {RigPose(0.0, 45.0, 0.0, 0.0): "dark.png"}
    _write(tmp_path / "dark.png", 1)
    pose, light = RigPose(0.2, 45.0, 119.7, 30.0), LightState(True, 1.0)

    def state() -> tuple[RigPose, LightState]:
        return pose, light

    camera = ReplayCamera(state, images=lit, dark=dark, tolerance_deg=0.5, root=tmp_path)
    frame = camera.capture(20.0)
    assert frame.pixels is not None and tuple(frame.pixels[0, 0]) == (200, 20, 10)  # RGB
    assert frame.metadata["source"] == str(tmp_path / "b.png")
    light = LightState(False, 0.0)
    assert camera.capture(20.0).pixels[0, 0, 0] == 1  # type: ignore[index]
    pose, light = RigPose(3.0, 45.0, 120.0, 30.0), LightState(True, 1.0)
    with pytest.raises(DeviceError, match=r"no stored image within 0\.5 deg"):
        camera.capture(20.0)


def test_replay_with_a_lookup_and_raw_files(tmp_path: Path) -> None:
    raw = tmp_path / "0001.dng"
    raw.write_bytes(b"raw")
    seen: list[float] = []

    def lookup(pose: RigPose, light: LightState, exposure_ms: float) -> Path:
        seen.append(exposure_ms)
        return raw

    camera = ReplayCamera(lambda: (RigPose(0, 0, 0, 0), LightState(True, 1.0)), lookup=lookup)
    frame = camera.capture(8.0)
    assert frame.path == raw and frame.pixels is None and seen == [8.0]
    with pytest.raises(InputError, match="either images"):
        ReplayCamera(lambda: (RigPose(0, 0, 0, 0), LightState()), images={}, lookup=lookup)


# --- the factory and the frame -------------------------------------------------------------


def test_open_camera_from_a_config(video: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    base = simulated_config("a", "b")
    opencv = OpenCVCameraConfig(device=str(video), manual_exposure=False, flush_frames=0)
    camera = open_camera(dataclasses.replace(base, camera=opencv))
    assert isinstance(camera, OpenCVCamera)
    assert _frame_index(camera.capture(1.0)) == 0
    camera.close()
    with pytest.raises(ConfigError, match="made by the simulated rig"):
        open_camera(base)
    with pytest.raises(ConfigError, match="replay camera needs"):
        open_camera(dataclasses.replace(base, camera=ReplayCameraConfig(dataset="d")))
    monkeypatch.setitem(sys.modules, "gphoto2", None)
    with pytest.raises(DeviceError, match="dslr"):
        open_camera(dataclasses.replace(base, camera=GPhoto2CameraConfig()))


def test_frames_are_read_only_and_complete() -> None:
    metadata = {"exposure_ms": 1.0, "timestamp": 0.0, "backend": "x", "device": "y"}
    pixels = np.zeros((2, 2, 3), np.uint8)
    frame = Frame(pixels=pixels, metadata=metadata)
    with pytest.raises(ValueError, match="read-only"):
        frame.pixels[0, 0, 0] = 1  # type: ignore[index]
    with pytest.raises(TypeError):
        frame.metadata["exposure_ms"] = 2.0  # type: ignore[index]
    with pytest.raises(InputError, match="pixels or a file path"):
        Frame(metadata=metadata)
    with pytest.raises(InputError, match="lacks timestamp, backend, device"):
        Frame(pixels=pixels, metadata={"exposure_ms": 1.0})
