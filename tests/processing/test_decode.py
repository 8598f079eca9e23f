"""Decoding captured images, dark frames and HDR merging (processing.decode, processing.hdr)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from core.colour import srgb_to_linear
from core.errors import InputError
from core.image_io import write_exr, write_linear16_tiff, write_srgb8
from processing.decode import DecodedImage, DecodeError, decode_image
from processing.hdr import Exposure, hat, merge_exposures
from sim.sensor import Sensor, bayer_mosaic, expose, linear_from_dn, to_linear16, to_srgb8
from sim.sensor_files import write_dng

SENSOR = Sensor(noise=False, exposure_s=0.01)  # saturation radiance 20000 / 19000 = 1.05


def scene(height: int = 32, width: int = 48) -> NDArray[np.float64]:
    """Flat colour patches (demosaicing is exact inside them) and a saturated corner."""
    rgb = np.empty((height, width, 3))
    rgb[:, : width // 2] = (0.3, 0.5, 0.1)
    rgb[:, width // 2 :] = (0.02, 0.9, 0.6)
    rgb[:8, :8] = 5.0
    return rgb


def expected(rgb: NDArray[np.float64], sensor: Sensor = SENSOR) -> NDArray[np.float32]:
    return np.clip(linear_from_dn(expose(rgb, sensor), sensor), 0.0, 1.0)


def test_linear16_tiff_and_png(tmp_path: Path) -> None:
    rgb = scene()
    pixels = to_linear16(expose(rgb, SENSOR), SENSOR)
    write_linear16_tiff(tmp_path / "a.tif", pixels)
    assert cv2.imwrite(str(tmp_path / "a.png"), pixels[:, :, ::-1])
    for name in ("a.tif", "a.png"):
        image = decode_image(tmp_path / name)
        assert image.encoding == "linear16" and image.linear.dtype == np.float32
        np.testing.assert_allclose(image.linear, expected(rgb), atol=1 / 65535)
        np.testing.assert_array_equal(image.saturated, pixels == 65535)
        assert image.saturated[:8, :8].all() and image.saturated.sum() == 8 * 8 * 3


def test_srgb8_png_and_jpeg(tmp_path: Path) -> None:
    rgb = scene()
    pixels = to_srgb8(expose(rgb, SENSOR), SENSOR)
    write_srgb8(tmp_path / "a.png", pixels)
    image = decode_image(tmp_path / "a.png")
    assert image.encoding == "srgb8"
    np.testing.assert_array_equal(image.linear, srgb_to_linear(pixels / 255.0))
    # 8-bit sRGB steps are at most 1 % of the value above 0.02 of saturation.
    np.testing.assert_allclose(image.linear, expected(rgb), rtol=0.01, atol=2e-4)
    np.testing.assert_array_equal(image.saturated, pixels == 255)
    write_srgb8(tmp_path / "a.jpg", pixels, quality=100)
    jpeg = decode_image(tmp_path / "a.jpg")
    assert np.median(np.abs(jpeg.linear - image.linear)) < 0.01
    # The transfer can be overridden (an 8-bit linear camera).
    np.testing.assert_allclose(
        decode_image(tmp_path / "a.png", transfer="linear").linear, pixels / 255.0, atol=1e-7
    )


def test_dng_through_rawpy(tmp_path: Path) -> None:
    rgb = scene()
    dn = expose(rgb, SENSOR)
    write_dng(tmp_path / "a.dng", bayer_mosaic(dn, SENSOR.pattern), SENSOR)
    image = decode_image(tmp_path / "a.dng")
    assert image.encoding == "raw" and image.shape == (32, 48)
    truth = expected(rgb)
    inner = (slice(10, 30), slice(2, 22)), (slice(10, 30), slice(26, 46))  # away from edges
    for rows, cols in inner:
        np.testing.assert_allclose(image.linear[rows, cols], truth[rows, cols], atol=2e-4)
        assert not image.saturated[rows, cols].any()
    assert image.saturated[:8, :8].all()
    # No rescaling to the data's maximum: an image peaking at 85 % of white stays at 85 %.
    dim = np.full((32, 32, 3), 0.85 * SENSOR.saturation_radiance)
    write_dng(tmp_path / "dim.dng", bayer_mosaic(expose(dim, SENSOR), "RGGB"), SENSOR)
    np.testing.assert_allclose(decode_image(tmp_path / "dim.dng").linear, 0.85, atol=1e-3)


def test_exr_is_read_as_stored(tmp_path: Path) -> None:
    rgb = scene().astype(np.float32)
    write_exr(tmp_path / "a.exr", rgb, np.ones(rgb.shape[:2], np.float32))
    image = decode_image(tmp_path / "a.exr")
    np.testing.assert_array_equal(image.linear, rgb)
    assert image.encoding == "float" and not image.saturated.any()


@pytest.mark.parametrize("name", ["a.tif", "a.png", "a.jpg", "a.dng"])
def test_truncated_files_are_named(tmp_path: Path, name: str) -> None:
    rgb = scene()
    dn = expose(rgb, SENSOR)
    path = tmp_path / name
    if name.endswith(".dng"):
        write_dng(path, bayer_mosaic(dn, "RGGB"), SENSOR)
    elif name.endswith(".tif"):
        write_linear16_tiff(path, to_linear16(dn, SENSOR))
    else:
        write_srgb8(path, to_srgb8(dn, SENSOR))
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(DecodeError, match=rf"{name}: .*(truncated|corrupt)"):
        decode_image(path)


def test_unreadable_missing_unknown_and_wrong_size(tmp_path: Path) -> None:
    (tmp_path / "junk.dng").write_bytes(b"not a raw file at all" * 10)
    with pytest.raises(DecodeError, match=r"junk\.dng: cannot decode as RAW"):
        decode_image(tmp_path / "junk.dng")
    with pytest.raises(DecodeError, match=r"gone\.tif: no such image file"):
        decode_image(tmp_path / "gone.tif")
    (tmp_path / "a.bmp").write_bytes(b"BM")
    with pytest.raises(DecodeError, match=r"a\.bmp: unknown image format"):
        decode_image(tmp_path / "a.bmp")
    write_linear16_tiff(tmp_path / "a.tif", np.zeros((4, 6, 3), np.uint16))
    with pytest.raises(
        DecodeError, match=r"a\.tif: image is 6x4 pixels, the camera model says 8x4"
    ):
        decode_image(tmp_path / "a.tif", expected_shape=(4, 8))


def _decoded(rgb: NDArray[np.float64], sensor: Sensor, seed: int = 0) -> DecodedImage:
    dn = expose(rgb, sensor, seed)
    linear = np.clip(linear_from_dn(dn, sensor), 0.0, 1.0)
    return DecodedImage(Path(f"t{sensor.exposure_s * 1e3:g}ms.tif"), linear, dn >= 16383, "x")


def test_dark_frame_subtraction() -> None:
    # Stray light (or a black-level error) adds the same offset to the image and its dark frame.
    radiance = scene() * 0.1
    offset = np.full(radiance.shape, 0.05)
    sensor = replace(SENSOR, exposure_s=0.004)
    image, dark = _decoded(radiance + offset, sensor), _decoded(offset, sensor)
    merged = merge_exposures([Exposure(image, 4.0, dark)])
    rate = merged.rate * (sensor.full_well / (sensor.sensitivity * 1e-3))  # back to radiance
    np.testing.assert_allclose(rate, radiance, atol=2e-4)
    without = merge_exposures([Exposure(image, 4.0)]).rate
    assert without.mean() > merged.rate.mean()


def _ramp_bracket(noise: bool) -> tuple[NDArray[np.float64], list[Exposure]]:
    # A ramp over 4 decades: 10 ms saturates above 0.105, 0.1 ms sees 0.001 as 0.2 electrons.
    ramp = np.geomspace(1e-3, 10.0, 400)
    radiance = np.repeat(ramp[None, :, None], 3, axis=2).repeat(2, axis=0)
    sensor = replace(SENSOR, noise=noise)
    bracket = [
        Exposure(_decoded(radiance, replace(sensor, exposure_s=t / 1e3), seed=k), t)
        for k, t in enumerate((0.1, 1.0, 10.0))
    ]
    return radiance, bracket


def _relative_error(
    radiance: NDArray[np.float64], exposures: list[Exposure]
) -> NDArray[np.float64]:
    merged = merge_exposures(exposures)
    estimate = merged.rate * (SENSOR.full_well / (SENSOR.sensitivity * 1e-3))  # to radiance
    return np.asarray(np.abs(estimate / radiance - 1.0))


def test_hdr_merge_recovers_radiance_beyond_one_exposure() -> None:
    radiance, bracket = _ramp_bracket(noise=False)
    assert not merge_exposures(bracket).saturated.any()
    error = _relative_error(radiance, bracket)
    ramp = radiance[0, :, 0]
    # Noise-free: only quantisation is left (0.03 % median, 1.1 % at 0.003, 0.3 % above 0.01).
    assert np.median(error) < 5e-4
    assert error[:, ramp > 0.003].max() < 0.015 and error[:, ramp > 0.01].max() < 0.005
    # Any one exposure alone loses an end of the ramp: clipped at the top or noise at the bottom.
    for exposure in bracket:
        assert _relative_error(radiance, [exposure]).max() > 0.3


def test_hdr_merge_beats_every_single_exposure_with_noise() -> None:
    radiance, bracket = _ramp_bracket(noise=True)
    merged = np.median(_relative_error(radiance, bracket))
    singles = [np.median(_relative_error(radiance, [e])) for e in bracket]
    assert merged < 0.5 * min(singles)  # 1.6 % against 4.3 % for the best single exposure


def test_hat_weights() -> None:
    values = np.array([0.0, 0.01, 0.02, 0.5, 0.9, 0.94, 0.98, 1.0])
    np.testing.assert_allclose(hat(values), [0.05, 0.525, 1, 1, 1, 0.5, 0, 0], atol=1e-6)


def test_merge_errors_name_the_files() -> None:
    white = np.full((4, 4, 3), 100.0)
    saturated = _decoded(white, SENSOR)
    with pytest.raises(DecodeError, match=r"every pixel is saturated .* t10ms\.tif"):
        merge_exposures([Exposure(saturated, 10.0), Exposure(saturated, 10.0)])
    small = DecodedImage(
        Path("small.tif"), np.zeros((2, 4, 3), np.float32), np.zeros((2, 4, 3), bool), "x"
    )
    with pytest.raises(DecodeError, match=r"small\.tif: image of shape \(2, 4, 3\) in a bracket"):
        merge_exposures([Exposure(_decoded(white * 0, SENSOR), 10.0, small)])


def test_a_file_of_another_format_than_the_capture_is_named(tmp_path: Path) -> None:
    pixels = to_linear16(expose(scene(), SENSOR), SENSOR)
    assert cv2.imwrite(str(tmp_path / "a.png"), pixels[:, :, ::-1])
    write_srgb8(tmp_path / "b.png", to_srgb8(expose(scene(), SENSOR), SENSOR))
    assert cv2.imwrite(str(tmp_path / "grey.png"), pixels[:, :, 1])
    capture = decode_image(tmp_path / "a.png").format
    assert (capture.encoding, capture.channels) == ("linear16", 3)
    assert decode_image(tmp_path / "a.png", expected=capture).encoding == "linear16"
    with pytest.raises(DecodeError, match=r"b\.png: a 8-bit sRGB colour image among the "
                       r"capture's 16-bit linear colour ones \(such as .*a\.png\)"):  # fmt: skip
        decode_image(tmp_path / "b.png", expected=capture)
    grey = decode_image(tmp_path / "grey.png")
    assert grey.channels == 1 and grey.linear.shape[2] == 3
    with pytest.raises(DecodeError, match=r"grey\.png: a 16-bit linear grey image"):
        decode_image(tmp_path / "grey.png", expected=capture)
    # The demosaic is the capture's option, refused on any file.
    with pytest.raises(InputError, match="unknown demosaic 'bogus'"):
        decode_image(tmp_path / "a.png", demosaic="bogus")


def test_a_dark_frame_brighter_than_its_image_is_refused() -> None:
    sensor = replace(SENSOR, exposure_s=0.004)
    image, lit_dark = _decoded(scene() * 0.02, sensor), _decoded(scene() * 0.3, sensor)
    with pytest.raises(DecodeError, match=r"the dark frame \(mean 0\.\d+ of full scale\) is "
                       r"brighter than the light image"):  # fmt: skip
        merge_exposures([Exposure(image, 4.0, lit_dark)])
    # A light behind the object leaves its image about as dark as the dark frame: kept.
    black = _decoded(np.full(scene().shape, 0.01), sensor)
    merge_exposures([Exposure(black, 4.0, _decoded(np.full(scene().shape, 0.0101), sensor, 1))])
