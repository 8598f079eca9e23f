from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from core.colour import linear_to_srgb, srgb_to_linear
from core.errors import PanoramaError
from core.image_io import write_linear
from processing.panorama import adjust_panorama, panorama_from_array, read_panorama


def _image(h: int = 16) -> np.ndarray:
    return np.random.default_rng(1).random((h, 2 * h, 3)).astype(np.float32) + 0.01


@pytest.mark.parametrize("name", ["courtyard.exr", "studio.exr"])
def test_reads_dwab_exr(name: str, courtyard_path: Path) -> None:
    p = read_panorama(courtyard_path.parent / name)
    assert p.rgb.shape == (512, 1024, 3) and p.rgb.dtype == np.float32
    assert p.rgb.min() >= 0  # DWAB's tiny negative noise is clamped


def test_exr_and_hdr_round_trip(tmp_path: Path) -> None:
    image = _image() * 40
    write_linear(tmp_path / "a.exr", image)
    np.testing.assert_array_equal(read_panorama(tmp_path / "a.exr").rgb, image)
    write_linear(tmp_path / "a.hdr", image)
    # RGBE shares one exponent per pixel: precision is relative to the largest channel.
    error = np.abs(read_panorama(tmp_path / "a.hdr").rgb - image).max(axis=2)
    assert np.all(error <= 0.01 * image.max(axis=2))


@pytest.mark.parametrize("bits", [8, 16])
def test_png_is_srgb_decoded(tmp_path: Path, bits: int) -> None:
    image = _image() * 0.9
    write_linear(tmp_path / "a.png", image, bits=bits)
    tolerance = 0.01 if bits == 8 else 1e-4
    np.testing.assert_allclose(read_panorama(tmp_path / "a.png").rgb, image, atol=tolerance)


def test_jpeg_is_srgb_decoded(tmp_path: Path) -> None:
    grey = np.full((16, 32, 3), 128, dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "a.jpg"), grey)
    value = read_panorama(tmp_path / "a.jpg").rgb.mean()
    assert value == pytest.approx(srgb_to_linear(np.array(128 / 255)), rel=0.02)


def test_srgb_round_trip() -> None:
    x = np.linspace(0, 1, 101, dtype=np.float32)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-6)


@pytest.mark.parametrize("suffix", [".exr", ".png", ".jpg", ".hdr"])
def test_truncated_files_are_refused(tmp_path: Path, suffix: str) -> None:
    full = tmp_path / f"full{suffix}"
    if suffix == ".jpg":
        cv2.imwrite(str(full), (_image(64) * 255).astype(np.uint8))
    else:
        write_linear(full, _image(64))
    cut = tmp_path / f"cut{suffix}"
    data = full.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(PanoramaError, match=str(cut)):
        read_panorama(cut)


def test_missing_and_unknown_files(tmp_path: Path) -> None:
    with pytest.raises(PanoramaError, match="no such file"):
        read_panorama(tmp_path / "none.exr")
    (tmp_path / "a.gif").write_bytes(b"GIF89a")
    with pytest.raises(PanoramaError, match="unknown"):
        read_panorama(tmp_path / "a.gif")


def test_not_two_to_one_is_refused_unless_resampled(tmp_path: Path) -> None:
    image = np.ones((10, 30, 3), dtype=np.float32)
    write_linear(tmp_path / "a.exr", image)
    with pytest.raises(PanoramaError, match="twice as wide"):
        read_panorama(tmp_path / "a.exr")
    assert read_panorama(tmp_path / "a.exr", resample=True).rgb.shape == (10, 20, 3)


@pytest.mark.parametrize(
    ("value", "message"), [(np.nan, "NaN"), (np.inf, "infinite"), (-5.0, "negative")]
)
def test_bad_values_are_refused(value: float, message: str) -> None:
    image = _image()
    image[3, 4, 1] = value
    with pytest.raises(PanoramaError, match=message):
        panorama_from_array(image, source="x.exr")


def test_all_black_is_refused() -> None:
    with pytest.raises(PanoramaError, match="no light"):
        panorama_from_array(np.zeros((8, 16, 3)), source="black.exr")


def test_adjust_rotates_and_scales() -> None:
    p = panorama_from_array(_image())
    q = adjust_panorama(p, yaw_deg=45.0, exposure=2.0)
    np.testing.assert_allclose(q.rgb.sum(), 2 * p.rgb.sum(), rtol=1e-5)
    with pytest.raises(PanoramaError, match="exposure"):
        adjust_panorama(p, exposure=0.0)


def test_compression_noise_is_clamped_with_a_note(tmp_path: Path) -> None:
    # A dim interior: the old per-pixel rule refused -0.0022 against a mean of 0.05.
    image = _image() * 0.05
    image[[2, 5, 9], [3, 7, 11], 0] = -0.0022
    p = panorama_from_array(image, source="dim.exr")
    assert p.rgb.min() == 0.0 and p.negative_pixels == 3
    assert 0 < p.negative_share < 1e-3
    assert p.note is not None and "3 pixels with small negative values" in p.note
    assert panorama_from_array(_image()).note is None


@pytest.mark.parametrize("compression", ["DWAA_COMPRESSION", "DWAB_COMPRESSION"])
def test_a_dwa_compressed_panorama_is_read(tmp_path: Path, compression: str) -> None:
    import OpenEXR

    rng = np.random.default_rng(0)
    image = np.zeros((64, 128, 3), dtype=np.float32)
    image[:32] = rng.random((32, 128, 3)) * 0.05
    image[10:12, 20:22] = 2000.0  # a sun
    image[40:42, ::3] = 5.0  # sharp edges ring below zero in DWA's DCT
    header = {"compression": getattr(OpenEXR, compression), "type": OpenEXR.scanlineimage}
    path = tmp_path / "dwa.exr"
    with OpenEXR.File(header, {"RGB": image.astype(np.float16)}) as exr:
        exr.write(str(path))
    with OpenEXR.File(str(path)) as exr:
        assert exr.channels()["RGB"].pixels.min() < 0  # the file really holds negatives
    p = read_panorama(path)
    assert p.rgb.min() == 0.0 and p.negative_pixels > 0 and p.note is not None


def test_material_negative_light_is_refused_naming_its_share() -> None:
    image = _image()
    image[:4] = -0.5
    with pytest.raises(PanoramaError, match=r"pixels hold negative radiance .* of the light, "
                       r"more than compression noise \(0\.001\)"):  # fmt: skip
        panorama_from_array(image, source="x.exr")


def test_overflowing_radiance_and_tiny_images_are_refused(tmp_path: Path) -> None:
    image = _image()
    image[0, 0] = 1e30
    with pytest.raises(PanoramaError, match=r"radiance up to 1e\+30 \(dynamic range"):
        panorama_from_array(image, source="x.exr")
    with pytest.raises(PanoramaError, match="exposure 1e\\+20 takes its radiance to"):
        adjust_panorama(panorama_from_array(_image()), exposure=1e20)
    with pytest.raises(PanoramaError, match=r"2x1 pixels is too small .* at least 8x4"):
        panorama_from_array(np.ones((1, 2, 3)), source="x.exr")
    (tmp_path / "folder.exr").mkdir()
    with pytest.raises(PanoramaError, match="is a directory, not an image file"):
        read_panorama(tmp_path / "folder.exr")
