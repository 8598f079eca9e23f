from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rawpy

from core.errors import DeviceError, InputError
from rig.config import CameraFaultConfig, simulated_config
from rig.config_cameras import SimulatedCameraConfig
from rig.devices import Camera, CameraTimeoutError, LightState
from rig.pose import RigPose
from sim.sensor import Sensor
from sim.simulated_camera import SimulatedCamera, capture_seed

POSE = RigPose(30.0, 60.0, 120.0, 40.0)
ON = LightState(True, 1.0)
OFF = LightState(False, 0.0)
SMALL: dict[str, Any] = {"points": 4000, "width": 48, "height": 48}


class Rig:
    """A stand-in for the emulators' state: the pose and light the camera will see."""

    def __init__(self, pose: RigPose = POSE, light: LightState = ON) -> None:
        self.pose, self.light = pose, light

    def __call__(self) -> tuple[RigPose, LightState]:
        return self.pose, self.light


def _pixels(camera: SimulatedCamera, exposure_ms: float = 16.0) -> np.ndarray:
    frame = camera.capture(exposure_ms)
    assert frame.pixels is not None
    return np.asarray(frame.pixels)


def test_the_same_pose_gives_identical_bytes() -> None:
    first = SimulatedCamera(Rig(), **SMALL)
    second = SimulatedCamera(Rig(), **SMALL)  # another process of the same plan
    assert isinstance(first, Camera)
    a, b = _pixels(first), _pixels(second)
    assert a.dtype == np.uint16 and a.shape == (48, 48, 3)
    assert a.tobytes() == b.tobytes()
    assert _pixels(first).tobytes() == a.tobytes()  # and again on the same camera


def test_noise_is_present_and_depends_on_the_pose() -> None:
    rig = Rig()
    camera = SimulatedCamera(rig, **SMALL)
    noisy = _pixels(camera)
    clean = _pixels(SimulatedCamera(rig, sensor=Sensor(noise=False), **SMALL))
    assert not np.array_equal(noisy, clean)
    seeds = {
        capture_seed(0, POSE, ON, 16.0),
        capture_seed(0, RigPose(30.0, 60.0, 121.0, 40.0), ON, 16.0),
        capture_seed(1, POSE, ON, 16.0),
        capture_seed(0, POSE, ON, 17.0),
    }
    assert len(seeds) == 4


def test_a_different_light_pose_gives_a_different_image() -> None:
    rig = Rig()
    camera = SimulatedCamera(rig, sensor=Sensor(noise=False), **SMALL)
    before = _pixels(camera).astype(float)
    rig.pose = RigPose(30.0, 60.0, 300.0, 40.0)  # light moved to the far side
    after = _pixels(camera).astype(float)
    assert np.abs(before - after).mean() > 0.05 * before.mean()


def test_light_off_gives_a_dark_frame() -> None:
    rig = Rig()
    camera = SimulatedCamera(rig, **SMALL)
    lit = _pixels(camera)
    rig.light = OFF
    dark = _pixels(camera)
    assert dark.mean() < 0.01 * lit.mean()
    raw = SimulatedCamera(rig, output="srgb8", **SMALL)
    assert _pixels(raw).max() < 40  # read noise only, after black subtraction


def test_the_intensity_scales_the_radiance() -> None:
    rig = Rig()
    camera = SimulatedCamera(rig, **SMALL)
    full = camera.render(POSE, ON)
    half = camera.render(POSE, LightState(True, 0.5))
    np.testing.assert_allclose(half, 0.5 * full, rtol=1e-5, atol=1e-7)


def test_a_turntable_turn_equals_turning_camera_and_light_back() -> None:
    camera = SimulatedCamera(Rig(), **SMALL)
    turned = camera.render(RigPose(30.0, 60.0, 120.0, 40.0, turntable_deg=25.0), ON)
    same = camera.render(RigPose(5.0, 60.0, 95.0, 40.0), ON)
    np.testing.assert_allclose(turned, same, atol=1e-6)


def test_an_arm_past_the_zenith_sees_the_other_side() -> None:
    camera = SimulatedCamera(Rig(), **SMALL)
    over = camera.render(RigPose(0.0, -30.0, 120.0, 40.0), ON)
    other = camera.render(RigPose(180.0, 30.0, 120.0, 40.0), ON)
    np.testing.assert_allclose(over, other, atol=1e-6)


def test_a_point_light_delivers_the_intensity_at_the_centre() -> None:
    directional = SimulatedCamera(Rig(), **SMALL).render(POSE, ON)
    point = SimulatedCamera(Rig(), light_distance=40.0, **SMALL).render(POSE, ON)
    assert point.mean() == pytest.approx(directional.mean(), rel=0.1)
    with pytest.raises(InputError, match="inside the object"):
        SimulatedCamera(Rig(), light_distance=0.5, **SMALL)


def test_dng_output_writes_a_raw_file(tmp_path: Path) -> None:
    camera = SimulatedCamera(Rig(), output="dng", folder=tmp_path, **SMALL)
    frame = camera.capture(16.0)
    assert frame.pixels is None and frame.path == tmp_path / "000001.dng"
    with rawpy.imread(str(frame.path)) as raw:
        assert raw.raw_image.shape == (48, 48)
    with pytest.raises(InputError, match="needs a folder"):
        SimulatedCamera(Rig(), output="dng", **SMALL)


def test_timeout_after_n_captures() -> None:
    faults = CameraFaultConfig(timeout_after=2)
    camera = SimulatedCamera(Rig(), faults=faults, timeout_s=0.5, **SMALL)
    camera.capture(16.0)
    camera.capture(16.0)
    with pytest.raises(CameraTimeoutError, match=r"no frame within 0\.5 s .*after 2 captures"):
        camera.capture(16.0)


def test_random_timeouts_are_seeded() -> None:
    def pattern(seed: int) -> list[bool]:
        faults = CameraFaultConfig(timeout_probability=0.5, seed=seed)
        camera = SimulatedCamera(Rig(), faults=faults, **SMALL)
        failed = []
        for _ in range(12):
            try:
                camera.capture(16.0)
                failed.append(False)
            except CameraTimeoutError:
                failed.append(True)
        return failed

    first = pattern(3)
    assert first == pattern(3)
    assert any(first) and not all(first)
    assert first != pattern(4)


def test_timeouts_on_demand_stall_at_most_the_timeout() -> None:
    faults = CameraFaultConfig(stall_s=10.0)
    camera = SimulatedCamera(Rig(), faults=faults, timeout_s=0.1, **SMALL)
    camera.fail_next()
    started = time.monotonic()
    with pytest.raises(CameraTimeoutError, match="on demand"):
        camera.capture(16.0)
    assert 0.1 <= time.monotonic() - started < 1.0
    camera.capture(16.0)  # the next one works again
    camera.close()
    with pytest.raises(DeviceError, match="closed"):
        camera.capture(16.0)


def test_built_from_a_rig_config(tmp_path: Path) -> None:
    config = simulated_config("a", "b")
    assert isinstance(config.camera, SimulatedCameraConfig)
    camera = SimulatedCamera.from_config(config.camera, Rig(), root=tmp_path)
    assert camera.scene == "glossy-sphere" and camera.width == 256
    small = SimulatedCameraConfig(scene="diffuse-sphere", output="srgb8", **SMALL)
    frame = SimulatedCamera.from_config(small, Rig()).capture(16.0)
    assert frame.pixels is not None and frame.pixels.dtype == np.uint8
    assert frame.metadata["pose"] == POSE.to_dict()
    assert frame.metadata["scene"] == "diffuse-sphere"
    with pytest.raises(InputError, match="unknown scene 'teapot'"):
        SimulatedCamera(Rig(), scene="teapot", **SMALL)
