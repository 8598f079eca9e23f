"""core.image_io: every writer read back, every broken file refused by name."""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest
import tifffile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray
from PIL import Image

from core.colour import linear_to_srgb, srgb_to_linear
from core.errors import InputError, RigError
from core.image_io import (
    OPENCV_SUFFIXES,
    READABLE_SUFFIXES,
    ImageFileError,
    auto_transfer,
    check_tiff_strips,
    encode_lossless,
    linear_from_pixels,
    pixel_depth,
    read_linear,
    read_pixels,
    write_exr,
    write_linear,
    write_linear16_tiff,
    write_srgb8,
)
from tests.full_disk import writes_under_limit

EXR_HEADER = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}


def _rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


def _hdr(height: int = 6, width: int = 10) -> NDArray[np.float32]:
    """Linear radiance over five decades, distinct per channel."""
    return (10.0 ** _rng().uniform(-2.0, 3.0, (height, width, 3))).astype(np.float32)


def _names(path: Path) -> str:
    return re.escape(str(path))


def _only(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# -- OpenEXR ------------------------------------------------------------------------------------


def test_exr_round_trips_float32_exactly(tmp_path: Path) -> None:
    rgb = _hdr()
    write_exr(tmp_path / "a.exr", rgb)
    back = read_pixels(tmp_path / "a.exr")
    assert back.dtype == np.float32 and back.shape == (6, 10, 3)
    np.testing.assert_array_equal(back, rgb)
    with OpenEXR.File(str(tmp_path / "a.exr"), separate_channels=True) as exr:
        assert sorted(exr.channels()) == ["B", "G", "R"]
        assert exr.header()["compression"] == OpenEXR.ZIP_COMPRESSION
    assert _only(tmp_path) == ["a.exr"]
    write_linear(tmp_path / "b.EXR", rgb.astype(np.float64))  # by suffix, in any case
    np.testing.assert_array_equal(read_linear(tmp_path / "b.EXR"), rgb)


def test_exr_with_alpha_stores_it_and_reads_rgb(tmp_path: Path) -> None:
    rgb = _hdr()
    alpha = _rng().random((6, 10)).astype(np.float32)
    write_exr(tmp_path / "a.exr", rgb.astype(np.float64), alpha)  # float64 stored as float32
    with OpenEXR.File(str(tmp_path / "a.exr"), separate_channels=True) as exr:
        channels = exr.channels()
        assert sorted(channels) == ["A", "B", "G", "R"]
        np.testing.assert_array_equal(channels["A"].pixels, alpha)
        assert channels["A"].pixels.dtype == np.float32
    back = read_pixels(tmp_path / "a.exr")
    assert back.shape == (6, 10, 3)  # alpha dropped
    np.testing.assert_array_equal(back, rgb)


def test_exr_alpha_of_another_size_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "a.exr"
    with pytest.raises(ImageFileError, match=_names(target) + r": alpha \(6, 9\)"):
        write_exr(target, _hdr(), np.zeros((6, 9), np.float32))
    assert _only(tmp_path) == []


def test_exr_extra_channels_are_dropped_from_a_read(tmp_path: Path) -> None:
    rgb = np.ones((2, 3, 4), np.float32) * np.array([1, 2, 3, 4], np.float32)
    write_exr(tmp_path / "a.exr", rgb)  # the fourth column is not written
    np.testing.assert_array_equal(read_pixels(tmp_path / "a.exr"), rgb[:, :, :3])


def test_exr_luminance_only_and_layered_channels(tmp_path: Path) -> None:
    y = np.arange(12, dtype=np.float32).reshape(3, 4)
    with OpenEXR.File(EXR_HEADER, {"Y": y}) as exr:
        exr.write(str(tmp_path / "y.exr"))
    grey = read_pixels(tmp_path / "y.exr")
    assert grey.shape == (3, 4, 3)
    for channel in range(3):
        np.testing.assert_array_equal(grey[:, :, channel], y)
    with OpenEXR.File(EXR_HEADER, {"diffuse.R": y, "diffuse.G": 2 * y, "diffuse.B": 3 * y}) as exr:
        exr.write(str(tmp_path / "layer.exr"))
    np.testing.assert_array_equal(read_pixels(tmp_path / "layer.exr")[1, 2], [6.0, 12.0, 18.0])


def test_exr_without_colour_channels_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "depth.exr"
    with OpenEXR.File(EXR_HEADER, {"Z": np.zeros((3, 4), np.float32)}) as exr:
        exr.write(str(target))
    with pytest.raises(ImageFileError, match=_names(target) + r".*found \['Z'\]"):
        read_pixels(target)


def test_exr_keeps_non_finite_values_as_stored(tmp_path: Path) -> None:
    rgb = np.array([[[np.nan, np.inf, -np.inf], [1.0, 2.0, 3.0]]], np.float32)
    write_linear(tmp_path / "a.exr", rgb)
    np.testing.assert_array_equal(read_linear(tmp_path / "a.exr"), rgb)


# -- write_linear: .hdr and .png ----------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".hdr", ".pic"])
def test_radiance_hdr_round_trips_to_rgbe_precision(tmp_path: Path, suffix: str) -> None:
    rgb = _hdr()
    write_linear(tmp_path / f"a{suffix}", rgb)
    back = read_pixels(tmp_path / f"a{suffix}")
    assert back.dtype == np.float32 and back.shape == rgb.shape
    # RGBE: one shared exponent, 8-bit mantissas: errors scale with the pixel's largest channel.
    brightest = rgb.max(axis=2, keepdims=True)
    assert np.all(np.abs(back - rgb) <= brightest / 128.0)
    assert np.all(np.abs(back.max(axis=2) - rgb.max(axis=2)) <= rgb.max(axis=2) / 128.0)
    assert read_linear(tmp_path / f"a{suffix}", transfer="srgb").dtype == np.float32


def test_png8_of_linear_values_is_srgb_encoded_and_clipped(tmp_path: Path) -> None:
    # linear 0.18 -> sRGB 0.4614 -> 117.6; 0.5 -> 0.7354 -> 187.5; above 1 and below 0 clip.
    rgb = np.array([[[0.0, 0.18, 1.0], [2.0, -1.0, 0.5]]], np.float32)
    write_linear(tmp_path / "a.png", rgb)
    back = read_pixels(tmp_path / "a.png")
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, [[[0, 118, 255], [255, 0, 188]]])


def test_png16_of_linear_values(tmp_path: Path) -> None:
    rgb = np.array([[[0.0, 0.18, 1.0], [2.0, -1.0, 0.5]]], np.float32)
    write_linear(tmp_path / "a.png", rgb, bits=16)
    back = read_pixels(tmp_path / "a.png")
    assert back.dtype == np.uint16
    np.testing.assert_array_equal(back, [[[0, 30235, 65535], [65535, 0, 48192]]])


@settings(max_examples=40, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    rgb=arrays(
        np.float32, (3, 5, 3), elements=st.floats(0.0, 1.0, width=32, allow_subnormal=False)
    ),
    bits=st.sampled_from([8, 16]),
)
def test_png_of_linear_values_reads_back_linear(
    tmp_path: Path, rgb: NDArray[np.float32], bits: int
) -> None:
    target = tmp_path / "round.png"
    write_linear(target, rgb, bits=8 if bits == 8 else 16)
    stored = read_pixels(target)
    scale = 255.0 if bits == 8 else 65535.0
    np.testing.assert_array_equal(stored, np.round(linear_to_srgb(rgb) * scale))
    back = read_linear(target)
    assert back.dtype == np.float32 and back.shape == rgb.shape
    # Half a code value in sRGB, through the curve's steepest slope (2.4 / 1.055 at 1).
    tolerance = 0.5 / scale * 2.4 / 1.055 + 1e-6
    assert np.max(np.abs(back - rgb)) <= tolerance


def test_write_linear_refuses_other_suffixes(tmp_path: Path) -> None:
    target = tmp_path / "a.jpg"
    with pytest.raises(ImageFileError, match=_names(target) + r": cannot write '\.jpg'"):
        write_linear(target, _hdr())
    assert _only(tmp_path) == []


def test_png_of_nan_is_refused_by_name(tmp_path: Path) -> None:
    target = tmp_path / "nan.png"
    rgb = np.full((2, 3, 3), 0.5, np.float32)
    rgb[1, 1, 0] = np.nan
    with pytest.raises(RigError, match=_names(target)):
        write_linear(target, rgb)
    assert _only(tmp_path) == []


# -- write_srgb8 and write_linear16_tiff ---------------------------------------------------------


def _gradient() -> NDArray[np.uint8]:
    g = np.tile(np.linspace(0.0, 255.0, 64), (48, 1))  # red rises to the right, green falls
    return np.dstack([g, g[:, ::-1], np.full_like(g, 90.0)]).astype(np.uint8)


def test_srgb8_png_round_trips_exactly(tmp_path: Path) -> None:
    picture = _rng().integers(0, 256, (7, 9, 3), dtype=np.uint8)
    write_srgb8(tmp_path / "a.png", picture)
    back = read_pixels(tmp_path / "a.png")
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, picture)  # RGB order, not OpenCV's BGR
    np.testing.assert_array_equal(
        read_linear(tmp_path / "a.png"), srgb_to_linear(picture.astype(np.float32) / 255.0)
    )


@pytest.mark.parametrize("suffix", [".jpg", ".jpeg", ".JPG"])
def test_srgb8_jpeg_is_close_and_quality_sets_the_size(tmp_path: Path, suffix: str) -> None:
    picture = _gradient()
    write_srgb8(tmp_path / f"q95{suffix}", picture)
    back = read_pixels(tmp_path / f"q95{suffix}")
    assert back.dtype == np.uint8 and back.shape == picture.shape
    error = np.abs(back.astype(int) - picture.astype(int))
    assert error.mean() < 1.5 and error.max() <= 10
    # The red channel rises to the right: channel order survives.
    assert back[:, -1, 0].mean() > back[:, 0, 0].mean() + 200
    assert back[:, 0, 1].mean() > back[:, -1, 1].mean() + 200
    write_srgb8(tmp_path / f"q10{suffix}", picture, quality=10)
    assert (tmp_path / f"q10{suffix}").stat().st_size < (tmp_path / f"q95{suffix}").stat().st_size


def test_srgb8_refuses_other_pictures_and_suffixes(tmp_path: Path) -> None:
    with pytest.raises(ImageFileError, match=r"a\.png: expected an \(H, W, 3\) uint8"):
        write_srgb8(tmp_path / "a.png", np.zeros((2, 2, 3), np.uint16))
    with pytest.raises(ImageFileError, match=r"a\.png: expected .* got \(2, 2\)"):
        write_srgb8(tmp_path / "a.png", np.zeros((2, 2), np.uint8))
    target = tmp_path / "a.tif"
    with pytest.raises(ImageFileError, match=_names(target) + ".*not '.tif'"):
        write_srgb8(target, np.zeros((2, 2, 3), np.uint8))
    assert _only(tmp_path) == []


def test_linear16_tiff_round_trips_exactly(tmp_path: Path) -> None:
    picture = _rng().integers(0, 65536, (5, 8, 3), dtype=np.uint16)
    write_linear16_tiff(tmp_path / "a.tiff", picture)
    back = read_pixels(tmp_path / "a.tiff")
    assert back.dtype == np.uint16
    np.testing.assert_array_equal(back, picture)
    np.testing.assert_array_equal(
        read_linear(tmp_path / "a.tiff", transfer="linear"),
        picture.astype(np.float32) / np.float32(65535.0),
    )
    with tifffile.TiffFile(tmp_path / "a.tiff") as tiff:
        assert tiff.pages[0].compression == 1  # uncompressed  # type: ignore[union-attr]
    with pytest.raises(ImageFileError, match=r"b\.tif: expected an \(H, W, 3\) uint16"):
        write_linear16_tiff(tmp_path / "b.tif", picture.astype(np.uint8))


# -- encode_lossless ----------------------------------------------------------------------------


def _decode(tmp_path: Path, suffix: str, data: bytes) -> NDArray[np.generic]:
    path = tmp_path / f"decoded{suffix}"
    path.write_bytes(data)
    return read_pixels(path)


@pytest.mark.parametrize(
    ("dtype", "shape"),
    [(np.uint8, (5, 7, 3)), (np.uint16, (5, 7, 3)), (np.uint8, (5, 7)), (np.uint16, (5, 7))],
)
def test_integer_pixels_encode_as_png(
    tmp_path: Path, dtype: type[np.unsignedinteger], shape: tuple[int, ...]
) -> None:
    pixels = _rng().integers(0, np.iinfo(dtype).max + 1, shape, dtype=dtype)
    suffix, data = encode_lossless(pixels)
    assert suffix == ".png" and data.startswith(b"\x89PNG\r\n\x1a\n")
    back = _decode(tmp_path, suffix, data)
    assert back.dtype == dtype
    np.testing.assert_array_equal(back, pixels)
    assert encode_lossless(pixels.copy()) == (suffix, data)  # deterministic bytes


def test_float_grey_pixels_encode_as_float32_tiff(tmp_path: Path) -> None:
    pixels = _hdr()[:, :, 0].astype(np.float64)
    suffix, data = encode_lossless(pixels)
    assert suffix == ".tif" and data[:4] in (b"II*\x00", b"MM\x00*")
    back = _decode(tmp_path, suffix, data)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, pixels.astype(np.float32))
    assert encode_lossless(pixels) == (suffix, data)


def test_float_rgb_pixels_encode_as_float32_tiff(tmp_path: Path) -> None:
    pixels = _hdr()
    suffix, data = encode_lossless(pixels)
    assert suffix == ".tif"
    np.testing.assert_array_equal(_decode(tmp_path, suffix, data), pixels)


def test_other_pixel_types_cannot_be_encoded() -> None:
    with pytest.raises(ImageFileError, match="dtype int32 cannot be stored"):
        encode_lossless(np.zeros((2, 2, 3), np.int32))


# -- read_pixels and read_linear ----------------------------------------------------------------


def test_grey_png_reads_as_two_dimensional(tmp_path: Path) -> None:
    grey = _rng().integers(0, 256, (4, 6), dtype=np.uint8)
    assert cv2.imwrite(str(tmp_path / "g.png"), grey)
    back = read_pixels(tmp_path / "g.png")
    assert back.shape == (4, 6) and back.dtype == np.uint8
    np.testing.assert_array_equal(back, grey)
    assert read_linear(tmp_path / "g.png").shape == (4, 6)


def test_alpha_is_dropped_and_channels_come_in_rgb_order(tmp_path: Path) -> None:
    bgra = np.zeros((2, 3, 4), np.uint8)
    bgra[...] = (10, 20, 30, 40)  # OpenCV's order: blue, green, red, alpha
    assert cv2.imwrite(str(tmp_path / "rgba.png"), bgra)
    back = read_pixels(tmp_path / "rgba.png")
    assert back.shape == (2, 3, 3)
    np.testing.assert_array_equal(back[0, 0], [30, 20, 10])
    rgba = _rng().integers(0, 256, (3, 4, 4), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "rgba.tif", rgba, photometric="rgb")
    np.testing.assert_array_equal(read_pixels(tmp_path / "rgba.tif"), rgba[:, :, :3])


def test_transfer_srgb_decodes_and_linear_scales(tmp_path: Path) -> None:
    picture = np.array([[[0, 128, 255]]], np.uint8)
    write_srgb8(tmp_path / "a.png", picture)
    srgb = read_linear(tmp_path / "a.png")  # the default is sRGB
    linear = read_linear(tmp_path / "a.png", transfer="linear")
    assert srgb.dtype == linear.dtype == np.float32
    # 128/255 = 0.50196 encoded -> ((0.50196 + 0.055) / 1.055) ** 2.4 = 0.21586 linear.
    np.testing.assert_allclose(srgb[0, 0], [0.0, 0.2158605, 1.0], rtol=1e-6, atol=0)
    np.testing.assert_allclose(linear[0, 0], [0.0, 128 / 255, 1.0], rtol=1e-7, atol=0)
    write_exr(tmp_path / "a.exr", np.full((1, 1, 3), 0.5, np.float32))  # floats are linear
    np.testing.assert_array_equal(read_linear(tmp_path / "a.exr", transfer="srgb"), 0.5)


def test_linear_from_pixels_scales_each_integer_type() -> None:
    np.testing.assert_array_equal(
        linear_from_pixels(np.array([0, 65535], np.uint16), transfer="linear"), [0.0, 1.0]
    )
    # sRGB 0.04045 (the curve's knee) and below are divided by 12.92.
    np.testing.assert_allclose(
        linear_from_pixels(np.array([10], np.uint8)), [10 / 255 / 12.92], rtol=1e-6
    )
    floats = np.array([[-1.0, 2.5]], np.float64)
    out = linear_from_pixels(floats, transfer="srgb")  # floats pass as stored
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, floats)
    with pytest.raises(ImageFileError, match=r"frame\.png: unsupported pixel type int8"):
        linear_from_pixels(np.array([1], np.int8), where="frame.png")


# -- broken files -------------------------------------------------------------------------------


def _truncated(tmp_path: Path, name: str, write: Callable[[Path], None]) -> Path:
    """A file written by ``write``, cut to its first half."""
    whole = tmp_path / f"whole-{name}"
    write(whole)
    data = whole.read_bytes()
    target = tmp_path / name
    target.write_bytes(data[: len(data) // 2])
    return target


def test_a_truncated_jpeg_is_refused(tmp_path: Path) -> None:
    target = _truncated(tmp_path, "t.jpg", lambda p: write_srgb8(p, _gradient()))
    with pytest.raises(ImageFileError, match=_names(target) + ": JPEG has no end-of-image"):
        read_pixels(target)


def test_a_zero_byte_jpeg_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "empty.jpg"
    target.write_bytes(b"")
    with pytest.raises(ImageFileError, match=_names(target)):
        read_pixels(target)


def test_a_truncated_png_is_refused(tmp_path: Path) -> None:
    target = _truncated(tmp_path, "t.png", lambda p: write_srgb8(p, _gradient()))
    with pytest.raises(ImageFileError, match=_names(target) + ": cannot decode as PNG"):
        read_pixels(target)


@pytest.mark.parametrize("suffix", [".png", ".hdr"])
def test_a_zero_byte_png_is_refused(tmp_path: Path, suffix: str) -> None:
    target = tmp_path / f"empty{suffix}"
    target.write_bytes(b"")
    with pytest.raises(ImageFileError, match=_names(target)):
        read_pixels(target)


def test_a_truncated_tiff_is_refused(tmp_path: Path) -> None:
    picture = _rng().integers(0, 65536, (20, 30, 3), dtype=np.uint16)
    target = _truncated(tmp_path, "t.tif", lambda p: write_linear16_tiff(p, picture))
    size = target.stat().st_size
    pattern = _names(target) + rf": truncated: image data ends at byte {2 * size}, the file has"
    with pytest.raises(ImageFileError, match=pattern):
        read_pixels(target)
    with pytest.raises(ImageFileError, match=_names(target)):
        check_tiff_strips(target)


def test_a_tiff_cut_inside_its_header_is_refused(tmp_path: Path) -> None:
    whole = tmp_path / "whole.tif"
    write_linear16_tiff(whole, np.zeros((4, 4, 3), np.uint16))
    for length in (0, 4, 10):
        target = tmp_path / f"cut{length}.tif"
        target.write_bytes(whole.read_bytes()[:length])
        with pytest.raises(ImageFileError, match=_names(target)):
            read_pixels(target)


def test_a_tiff_with_a_broken_first_page_offset_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "broken.tif"
    target.write_bytes(b"II*\x00hello world")
    with pytest.raises(ImageFileError, match=_names(target)):
        read_pixels(target)


def test_non_tiff_files_pass_the_strip_check(tmp_path: Path) -> None:
    write_srgb8(tmp_path / "a.png", _gradient())
    check_tiff_strips(tmp_path / "a.png")  # not TIFF-structured: nothing to check


def test_a_truncated_exr_is_refused(tmp_path: Path) -> None:
    target = _truncated(tmp_path, "t.exr", lambda p: write_exr(p, _hdr(40, 60)))
    with pytest.raises(ImageFileError, match=_names(target) + ": cannot read as OpenEXR"):
        read_pixels(target)


@pytest.mark.parametrize("suffix", sorted(READABLE_SUFFIXES))
def test_garbage_is_refused_by_name(tmp_path: Path, suffix: str) -> None:
    target = tmp_path / f"garbage{suffix}"
    target.write_bytes(b"this is not an image\n" * 10 + b"\xff\xd9")
    with pytest.raises(ImageFileError, match=_names(target)):
        read_pixels(target)


def test_a_missing_file_is_refused_by_name(tmp_path: Path) -> None:
    target = tmp_path / "nowhere.png"
    with pytest.raises(ImageFileError, match=_names(target) + ": no such file"):
        read_pixels(target)
    (tmp_path / "folder.exr").mkdir()
    with pytest.raises(ImageFileError, match=r"folder\.exr: is a directory, not an image file"):
        read_linear(tmp_path / "folder.exr")


def test_an_unknown_suffix_is_refused_by_name(tmp_path: Path) -> None:
    target = tmp_path / "photo.gif"  # OpenCV may read GIF; it is not offered (animated, palette)
    target.write_bytes(b"GIF89a" + bytes(32))
    with pytest.raises(ImageFileError, match=_names(target) + r": unknown image format '\.gif'"):
        read_pixels(target)
    assert issubclass(ImageFileError, InputError)


# -- transfer "auto" ----------------------------------------------------------------------------


def test_auto_transfer_is_srgb_for_8_bit_and_linear_for_16_bit_and_float() -> None:
    assert auto_transfer(np.zeros(2, np.uint8)) == "srgb"
    assert auto_transfer(np.zeros(2, np.uint16)) == "linear"
    assert auto_transfer(np.zeros(2, np.float16)) == "linear"
    assert [pixel_depth(np.zeros(1, t)) for t in (np.uint8, np.uint16, np.float32)] == [
        "8-bit",
        "16-bit",
        "float",
    ]
    with pytest.raises(ImageFileError, match=r"a\.png: unsupported pixel type int32"):
        pixel_depth(np.zeros(1, np.int32), where="a.png")
    np.testing.assert_allclose(
        linear_from_pixels(np.array([13107], np.uint16), transfer="auto"), [0.2], rtol=1e-7
    )
    np.testing.assert_allclose(
        linear_from_pixels(np.array([10], np.uint8), transfer="auto"), [10 / 255 / 12.92]
    )
    with pytest.raises(InputError, match=r"f\.png: transfer must be 'auto', 'srgb' or 'linear'"):
        linear_from_pixels(np.zeros(1, np.uint8), transfer="gamma", where="f.png")  # type: ignore[arg-type]


def test_a_16_bit_png_reads_linear_with_auto_and_srgb_by_default(tmp_path: Path) -> None:
    # 13107 / 65535 = 0.2 exactly: a 16-bit linear 0.2 stays 0.2; decoded as sRGB it is 0.0331.
    assert cv2.imwrite(str(tmp_path / "a.png"), np.full((2, 3, 3), 13107, np.uint16))
    auto = read_linear(tmp_path / "a.png", transfer="auto")
    np.testing.assert_allclose(auto, 0.2, rtol=0, atol=1 / 65535)
    np.testing.assert_allclose(read_linear(tmp_path / "a.png"), 0.0331048, rtol=1e-5)
    assert cv2.imwrite(str(tmp_path / "b.png"), np.full((2, 3, 3), 128, np.uint8))
    np.testing.assert_allclose(
        read_linear(tmp_path / "b.png", transfer="auto"), 0.2158605, rtol=1e-6
    )


# -- TGA ----------------------------------------------------------------------------------------


def _tga(pixels: NDArray[np.uint8], *, top_down: bool = False, rle: bool = False) -> bytes:
    """A TGA file written by hand from the specification (no footer).

    ``pixels``: (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA. RLE files mix run packets (for
    repeated pixels) and one-pixel raw packets, none across rows.
    """
    height, width = pixels.shape[:2]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    kind = (3 if channels == 1 else 2) + (8 if rle else 0)
    descriptor = (0x20 if top_down else 0) | (8 if channels == 4 else 0)
    header = struct.pack(
        "<BBBHHBHHHHBB", 0, 0, kind, 0, 0, 0, 0, 0, width, height, 8 * channels, descriptor
    )
    rows = pixels if top_down else pixels[::-1]
    flat = rows.reshape(height * width, channels)
    if channels >= 3:
        flat = flat[:, [2, 1, 0, 3][:channels]]  # stored B, G, R(, A)
    if not rle:
        return header + flat.tobytes()
    body = bytearray()
    for row in flat.reshape(height, width, channels):  # TGA 2.0: no packet spans two rows
        index = 0
        while index < width:
            run = 1
            while index + run < width and run < 128 and (row[index + run] == row[index]).all():
                run += 1
            body += bytes([0x80 | (run - 1) if run > 1 else 0]) + row[index].tobytes()
            index += run
    return header + bytes(body)


def _blocks(channels: int) -> NDArray[np.uint8]:
    """A 6 x 9 picture of flat blocks (runs for RLE) and some noise (raw packets)."""
    shape = (6, 9) if channels == 1 else (6, 9, channels)
    picture = np.zeros(shape, np.uint8)
    picture[:3] = 200
    picture[3:, :4] = 17
    picture[3:, 4:] = _rng().integers(0, 256, picture[3:, 4:].shape, dtype=np.uint8)
    return picture


@pytest.mark.parametrize("rle", [False, True])
@pytest.mark.parametrize("top_down", [False, True])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_tga_reads_every_layout(tmp_path: Path, rle: bool, top_down: bool, channels: int) -> None:
    picture = _blocks(channels)
    target = tmp_path / "a.TGA"
    target.write_bytes(_tga(picture, top_down=top_down, rle=rle))
    back = read_pixels(target)
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, picture if channels != 4 else picture[:, :, :3])
    assert read_linear(target, transfer="auto").dtype == np.float32


def test_tga_written_by_pillow_reads_back(tmp_path: Path) -> None:
    picture = _blocks(3)
    Image.fromarray(picture).save(tmp_path / "rle.tga", compression="tga_rle")
    np.testing.assert_array_equal(read_pixels(tmp_path / "rle.tga"), picture)
    mapped = Image.fromarray(picture).quantize(16)  # a colour-mapped TGA
    mapped.save(tmp_path / "mapped.tga")
    np.testing.assert_array_equal(
        read_pixels(tmp_path / "mapped.tga"), np.asarray(mapped.convert("RGB"))
    )


def test_broken_tga_files_are_refused_by_name(tmp_path: Path) -> None:
    empty = tmp_path / "empty.tga"
    empty.write_bytes(b"")
    with pytest.raises(ImageFileError, match=_names(empty) + r": the file is empty"):
        read_pixels(empty)
    for rle in (False, True):
        whole = _tga(_blocks(3), rle=rle)
        cut = tmp_path / f"cut{rle}.tga"
        cut.write_bytes(whole[: len(whole) - 20])
        with pytest.raises(ImageFileError, match=_names(cut) + r": cannot decode as TGA .*trunc"):
            read_pixels(cut)
    across = tmp_path / "across.tga"  # one RLE packet over every row (TGA 1.0 allowed it)
    across.write_bytes(_tga(np.zeros((6, 9, 3), np.uint8), rle=True)[:18] + b"\xb5\x01\x02\x03")
    with pytest.raises(ImageFileError, match=_names(across) + ": .*runs across rows"):
        read_pixels(across)
    header_only = tmp_path / "header.tga"
    header_only.write_bytes(_tga(_blocks(3))[:10])
    with pytest.raises(ImageFileError, match=_names(header_only) + ": cannot decode as TGA"):
        read_pixels(header_only)
    renamed = tmp_path / "renamed.tga"
    write_srgb8(tmp_path / "a.png", _gradient())
    renamed.write_bytes((tmp_path / "a.png").read_bytes())
    with pytest.raises(ImageFileError, match=_names(renamed) + ": cannot decode as TGA"):
        read_pixels(renamed)
    (tmp_path / "folder.tga").mkdir()
    with pytest.raises(ImageFileError, match=r"folder\.tga: is a directory"):
        read_pixels(tmp_path / "folder.tga")


# -- BMP and the other OpenCV formats -------------------------------------------------------------


def test_bmp_reads_colour_and_grey(tmp_path: Path) -> None:
    assert {".tga", ".bmp"} <= READABLE_SUFFIXES and ".bmp" in OPENCV_SUFFIXES
    colour = _blocks(3)
    assert cv2.imwrite(str(tmp_path / "c.bmp"), colour[:, :, ::-1])  # OpenCV writes BGR
    np.testing.assert_array_equal(read_pixels(tmp_path / "c.bmp"), colour)
    grey = _blocks(1)
    assert cv2.imwrite(str(tmp_path / "g.BMP"), grey)
    back = read_pixels(tmp_path / "g.BMP")
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back if back.ndim == 2 else back[:, :, 0], grey)
    np.testing.assert_allclose(
        read_linear(tmp_path / "c.bmp", transfer="auto"),
        srgb_to_linear(colour.astype(np.float32) / 255.0),
    )


def test_broken_bmp_files_are_refused_in_one_line(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    assert cv2.imwrite(str(tmp_path / "whole.bmp"), _blocks(3))
    data = (tmp_path / "whole.bmp").read_bytes()
    capfd.readouterr()
    for length in (0, 30, len(data) // 2):
        cut = tmp_path / f"cut{length}.bmp"
        cut.write_bytes(data[:length])
        with pytest.raises(ImageFileError, match=_names(cut)):
            read_pixels(cut)
    # OpenCV logs its own "[ERROR:0@...]" lines; they go into the message, not before it.
    said = capfd.readouterr()
    assert said.err == "" and said.out == ""
    (tmp_path / "folder.bmp").mkdir()
    with pytest.raises(ImageFileError, match=r"folder\.bmp: is a directory"):
        read_pixels(tmp_path / "folder.bmp")


# --- a full disk, for real: a child process under a file size limit (tests/full_disk.py) -----

#: Each writer, called in the child on a 64 x 64 picture of noise (far past the limit).
_WRITERS = {
    "exr": "write_exr(target, linear)",
    "hdr": "write_linear(target, linear)",
    "png": "write_linear(target, linear, bits=16)",
    "jpg": "write_srgb8(target, picture)",
    "tif": "write_linear16_tiff(target, picture.astype(np.uint16) * 257)",
    "png8": "write_uint8(target, picture)",
    "png16": "write_png16(target, picture.astype(np.uint16) * 257)",
}


def test_every_writer_refuses_a_full_disk_and_keeps_the_old_file(tmp_path: Path) -> None:
    # OpenCV's imwrite reported success on a full disk and left an empty or cut file in place.
    targets = {kind: tmp_path / f"old-{kind}.{kind.rstrip('0123456789')}" for kind in _WRITERS}
    for target in targets.values():
        target.write_bytes(b"the previous image")
    calls = "\n".join(
        f"target = {str(targets[kind])!r}\nattempt({kind!r}, lambda target=target: {call})"
        for kind, call in _WRITERS.items()
    )
    # Where OpenCV would put its Radiance file, and the temporary folder: both stay empty.
    opencv_temp, scratch = tmp_path / "opencv", tmp_path / "scratch"
    opencv_temp.mkdir()
    scratch.mkdir()
    found = writes_under_limit(
        "import os, tempfile\n"
        f"os.environ['OPENCV_TEMP_PATH'] = {str(opencv_temp)!r}\n"
        f"tempfile.tempdir = {str(scratch)!r}\n"
        "import numpy as np\n"
        "from core.image_io import (write_exr, write_linear, write_linear16_tiff, write_png16,\n"
        "    write_srgb8, write_uint8)\n"
        "linear = np.random.default_rng(0).random((64, 64, 3)).astype(np.float32)\n"
        "picture = (linear * 255).astype(np.uint8)\n" + calls,
        limit=1000,
    )
    for kind, target in targets.items():
        assert found[kind]["project"], found[kind]["traceback"]
        # Radiance files are encoded through a temporary file of OpenCV's: that write fails.
        said = "OpenCV could not encode" if kind == "hdr" else "the file is larger"
        assert found[kind]["message"].startswith(f"{target}: cannot write: {said}")
        assert target.read_bytes() == b"the previous image"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [*(t.name for t in targets.values()), "opencv", "scratch"]
    )
    assert not any(opencv_temp.iterdir()) and not any(scratch.iterdir())
    assert found["stderr"]["text"] == ""  # no library's own complaint besides the error
