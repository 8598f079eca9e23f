from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import rawpy
import tifffile

from app.cli import main
from core.errors import InputError
from core.image_io import write_linear16_tiff, write_srgb8
from sim.sensor import (
    Sensor,
    auto_exposure_time,
    bayer_mosaic,
    expose,
    radiance_from_dn,
    to_linear16,
    to_srgb8,
)
from sim.sensor_files import write_dng


def _ramp(height: int = 32, width: int = 48) -> np.ndarray:
    rng = np.random.default_rng(5)
    return rng.uniform(0.0, 0.5, size=(height, width, 3))


def test_noiseless_exposure_inverts_to_the_radiance() -> None:
    sensor = Sensor(noise=False)
    radiance = _ramp()
    decoded = radiance_from_dn(expose(radiance, sensor), sensor)
    # One digital number is the quantisation step.
    step = sensor.saturation_radiance / (sensor.white_level - sensor.black_level)
    np.testing.assert_allclose(decoded, radiance, atol=0.51 * step)


def test_saturation_reads_the_white_level_and_darkness_the_black_level() -> None:
    sensor = Sensor()
    radiance = np.zeros((4, 4, 3))
    radiance[:2] = 10 * sensor.saturation_radiance
    dn = expose(radiance, sensor, seed=1)
    assert (dn[:2] == sensor.white_level).all()
    assert abs(float(dn[2:].mean()) - sensor.black_level) < 1.0


def test_noise_has_the_shot_and_read_variance() -> None:
    sensor = Sensor(read_noise=8.0)
    electrons = 4000.0
    radiance = np.full((200, 200, 3), electrons / (sensor.sensitivity * sensor.exposure_s))
    dn = expose(radiance, sensor, seed=2).astype(np.float64)
    measured = (dn - sensor.black_level) / sensor.gain
    assert abs(measured.mean() - electrons) < 1.0
    expected_std = np.sqrt(electrons + sensor.read_noise**2)
    assert abs(measured.std() / expected_std - 1) < 0.02


def test_the_same_seed_gives_the_same_image() -> None:
    sensor = Sensor()
    radiance = _ramp()
    np.testing.assert_array_equal(expose(radiance, sensor, 3), expose(radiance, sensor, 3))
    assert (expose(radiance, sensor, 3) != expose(radiance, sensor, 4)).any()


def test_outputs_span_black_to_saturation() -> None:
    sensor = Sensor(noise=False)
    radiance = np.zeros((2, 2, 3))
    radiance[0, 0] = sensor.saturation_radiance
    radiance[0, 1] = 0.5 * sensor.saturation_radiance
    dn = expose(radiance, sensor)
    linear, srgb = to_linear16(dn, sensor), to_srgb8(dn, sensor)
    assert linear[0, 0, 0] == 65535 and linear[1, 1, 0] == 0
    assert abs(int(linear[0, 1, 0]) - 32768) <= 3
    assert srgb[0, 0, 0] == 255 and srgb[1, 1, 0] == 0
    assert srgb[0, 1, 0] == 188  # sRGB encoding of 0.5


def test_bayer_mosaic_keeps_one_channel_per_site() -> None:
    dn = np.zeros((4, 6, 3), dtype=np.uint16)
    dn[..., 0], dn[..., 1], dn[..., 2] = 100, 200, 300
    rggb = bayer_mosaic(dn, "RGGB")
    np.testing.assert_array_equal(rggb[:2, :2], [[100, 200], [200, 300]])
    np.testing.assert_array_equal(bayer_mosaic(dn, "GBRG")[:2, :2], [[200, 300], [100, 200]])


def test_dng_is_decoded_by_rawpy_to_the_linear_image(tmp_path: Path) -> None:
    sensor = Sensor(noise=False, pattern="GRBG")
    radiance = np.empty((40, 60, 3))
    radiance[:] = np.array([0.1, 0.2, 0.3]) * sensor.saturation_radiance
    dn = expose(radiance, sensor)
    mosaic = bayer_mosaic(dn, sensor.pattern)
    write_dng(tmp_path / "frame.dng", mosaic, sensor)
    with rawpy.imread(str(tmp_path / "frame.dng")) as raw:
        np.testing.assert_array_equal(raw.raw_image_visible, mosaic)
        assert raw.white_level == sensor.white_level
        assert list(raw.black_level_per_channel) == [sensor.black_level] * 4
        assert raw.color_desc == b"RGBG"
        # GRBG: green at (0, 0), red at (0, 1), blue at (1, 0).
        colors = raw.raw_colors_visible[:2, :2]
        assert colors[0, 1] == 0 and colors[1, 0] == 2 and colors[0, 0] in (1, 3)
        rgb = raw.postprocess(
            gamma=(1, 1),
            no_auto_bright=True,
            output_bps=16,
            use_camera_wb=False,
            user_wb=[1.0, 1.0, 1.0, 1.0],
            output_color=rawpy.ColorSpace.raw,
            user_flip=0,
        )
    centre = rgb[10:30, 10:50].reshape(-1, 3).mean(axis=0) / 65535.0
    np.testing.assert_allclose(centre, [0.1, 0.2, 0.3], atol=2e-4)


def test_photo_files_round_trip(tmp_path: Path) -> None:
    sensor = Sensor()
    dn = expose(_ramp(), sensor, seed=6)
    write_linear16_tiff(tmp_path / "frame.tif", to_linear16(dn, sensor))
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "frame.tif"), to_linear16(dn, sensor))
    write_srgb8(tmp_path / "frame.png", to_srgb8(dn, sensor))
    back = cv2.imread(str(tmp_path / "frame.png"), cv2.IMREAD_COLOR)[:, :, ::-1]
    np.testing.assert_array_equal(back, to_srgb8(dn, sensor))
    assert not list(tmp_path.glob(".*partial*"))


def test_auto_exposure_puts_the_highlights_at_the_target() -> None:
    sensor = Sensor()
    radiance = _ramp()
    seconds = auto_exposure_time(radiance, sensor, percentile=100.0, target=0.5)
    exposed = Sensor(exposure_s=seconds, noise=False)
    peak = radiance_from_dn(expose(radiance, exposed), exposed).max() / exposed.saturation_radiance
    assert abs(peak - 0.5) < 1e-3


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Sensor(exposure_s=0.0), "exposure_s"),
        (lambda: Sensor(black_level=20_000), "black < white"),
        (lambda: Sensor(pattern="RGBW"), "Bayer pattern"),
        (lambda: expose(-np.ones((2, 2, 3)), Sensor()), "non-negative"),
        (lambda: bayer_mosaic(np.zeros((3, 4, 3), np.uint16)), "even image size"),
        (lambda: auto_exposure_time(np.zeros((2, 2, 3)), Sensor()), "no light"),
        (lambda: write_srgb8("photo.bmp", np.zeros((2, 2, 3), np.uint8)), "photo.bmp"),
    ],
)
def test_bad_arguments_are_refused(make, message: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=message):
        make()


@pytest.mark.parametrize("suffix", [".exr", ".png", ".tif", ".dng"])
def test_cli_photo_writes_each_format(tmp_path: Path, suffix: str) -> None:
    out = tmp_path / f"photo{suffix}"
    args = ["sim", "photo", "--scene", "glossy-sphere", "--view", "0,45", "--light", "30,60",
            "--size", "64x48", "--points", "8000", "-o", str(out)]  # fmt: skip
    assert main(args) == 0 and out.exists()
    if suffix == ".dng":
        with rawpy.imread(str(out)) as raw:
            assert raw.raw_image_visible.shape == (48, 64)
            # Auto exposure: the highlight is bright but the object is not all clipped.
            sensor, values = Sensor(), raw.raw_image_visible.astype(np.float64)
            assert values.max() > sensor.black_level + 0.6 * (
                sensor.white_level - sensor.black_level
            )
            assert (values == sensor.white_level).mean() < 0.05


def test_cli_photo_is_deterministic_per_seed(tmp_path: Path) -> None:
    def shoot(name: str, seed: str) -> bytes:
        args = ["sim", "photo", "--scene", "diffuse-sphere", "--view", "0,45", "--light",
                "0,90", "--size", "32x32", "--points", "4000", "--light-distance", "3",
                "--seed", seed, "-o", str(tmp_path / name)]  # fmt: skip
        assert main(args) == 0
        return (tmp_path / name).read_bytes()

    assert shoot("a.png", "1") == shoot("b.png", "1") != shoot("c.png", "2")


def test_cli_photo_refuses_an_unknown_format(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["sim", "photo", "--scene", "diffuse-sphere", "--view", "0,45", "--light", "0,90",
            "-o", str(tmp_path / "photo.bmp")]  # fmt: skip
    assert main(args) == 2
    assert "photo.bmp" in capsys.readouterr().err
