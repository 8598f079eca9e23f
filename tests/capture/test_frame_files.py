"""capture.frame_files: a frame as the bytes of a lossless file, decoded back to its pixels."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from capture.frame_files import frame_file
from core.image_io import read_pixels
from rig.devices import Frame, frame_metadata


def _frame(pixels: NDArray[Any] | None = None, path: Path | None = None) -> Frame:
    return Frame(pixels=pixels, path=path, metadata=frame_metadata(10.0, "test", "bench"))


def _decode(tmp_path: Path, suffix: str, data: bytes) -> NDArray[Any]:
    file = tmp_path / f"stored{suffix}"
    file.write_bytes(data)
    return read_pixels(file)


def _pixels(dtype: type[np.generic], shape: tuple[int, ...]) -> NDArray[Any]:
    rng = np.random.default_rng(7)
    if np.issubdtype(dtype, np.integer):
        top = int(np.iinfo(np.dtype(dtype)).max)
        return rng.integers(0, top + 1, shape).astype(dtype)
    return (rng.random(shape) * 1e3).astype(dtype)


@pytest.mark.parametrize(
    ("dtype", "shape"),
    [(np.uint16, (12, 17, 3)), (np.uint8, (12, 17, 3)), (np.uint16, (12, 17)), (np.uint8, (9, 5))],
)
def test_integer_frames_are_stored_as_png(
    tmp_path: Path, dtype: type[np.generic], shape: tuple[int, ...]
) -> None:
    pixels = _pixels(dtype, shape)
    suffix, data = frame_file(_frame(pixels))
    assert suffix == ".png" and data.startswith(b"\x89PNG\r\n\x1a\n")
    back = _decode(tmp_path, suffix, data)
    assert back.dtype == dtype and back.shape == shape
    np.testing.assert_array_equal(back, pixels)  # lossless, RGB order kept


def test_float_grey_frames_are_stored_as_float32_tiff(tmp_path: Path) -> None:
    pixels = _pixels(np.float32, (8, 11))
    suffix, data = frame_file(_frame(pixels))
    assert suffix == ".tif"
    back = _decode(tmp_path, suffix, data)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, pixels)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_float_rgb_frames_are_stored_as_float32_tiff(
    tmp_path: Path, dtype: type[np.generic]
) -> None:
    pixels = _pixels(dtype, (8, 11, 3))
    suffix, data = frame_file(_frame(pixels))
    assert suffix == ".tif"
    np.testing.assert_array_equal(_decode(tmp_path, suffix, data), pixels.astype(np.float32))


def test_the_bytes_are_deterministic() -> None:
    pixels = _pixels(np.uint16, (12, 17, 3))
    first = frame_file(_frame(pixels))
    # Another frame of the same pixels, taken later (another timestamp): the same file.
    again = frame_file(_frame(pixels.copy()))
    assert first == again
    other = pixels.copy()
    other[3, 4, 1] ^= 1
    assert frame_file(_frame(other))[1] != first[1]


def test_the_frames_pixels_are_left_untouched() -> None:
    pixels = _pixels(np.uint8, (6, 7, 3))
    frame = _frame(pixels)
    before = np.array(frame.pixels)
    frame_file(frame)
    np.testing.assert_array_equal(frame.pixels, before)


def test_a_frame_written_by_the_camera_is_stored_as_is(tmp_path: Path) -> None:
    raw = tmp_path / "IMG_0001.DNG"
    content = bytes(range(256)) * 8  # not decoded: any bytes the camera wrote
    raw.write_bytes(content)
    assert frame_file(_frame(path=raw)) == (".dng", content)


def test_a_file_wins_over_pixels_when_a_frame_has_both(tmp_path: Path) -> None:
    raw = tmp_path / "frame.nef"
    raw.write_bytes(b"raw sensor data")
    both = _frame(pixels=_pixels(np.uint16, (4, 4, 3)), path=raw)
    assert frame_file(both) == (".nef", b"raw sensor data")


def test_a_camera_file_that_is_gone_is_named(tmp_path: Path) -> None:
    gone = tmp_path / "IMG_0002.CR2"
    frame = _frame(path=gone)
    # (A bare OSError, not a DatasetError: frame_file does not wrap it.)
    with pytest.raises(OSError, match=r"IMG_0002\.CR2"):
        frame_file(frame)
