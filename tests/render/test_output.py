"""render.output: relit images as EXR or PNG, sequences as GIF or MP4, read back."""

from __future__ import annotations

import gc
import re
from pathlib import Path
from typing import Any

import imageio.v2 as imageio
import imageio.v3 as iio
import numpy as np
import OpenEXR
import pytest
from numpy.typing import NDArray

from core.errors import InputError
from core.image_io import read_pixels
from render.output import (
    IMAGE_SUFFIXES,
    SEQUENCE_SUFFIXES,
    display_picture,
    write_image,
    write_sequence,
)
from tests.full_disk import writes_under_limit


def _code(linear_display: float) -> int:
    """The 8-bit sRGB code of a display value in [0, 1], written out independently."""
    v = (
        12.92 * linear_display
        if linear_display <= 0.0031308
        else (1.055 * linear_display ** (1 / 2.4) - 0.055)
    )
    return round(v * 255)


def _object_on_background() -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """A 6 x 8 image: a grey object of radiance 0.5 (columns 2-5) on a bright background."""
    rgb = np.full((6, 8, 3), 100.0, np.float32)
    coverage = np.zeros((6, 8), bool)
    coverage[:, 2:6] = True
    rgb[coverage] = 0.5
    return rgb, coverage


def _frames(height: int, width: int, count: int = 4) -> list[NDArray[np.uint8]]:
    frames = []
    for index in range(count):
        frame = np.full((height, width, 3), 60 * index, np.uint8)
        frame[:, : width // 3] = (255, 0, 0)
        frames.append(frame)
    return frames


def _only(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_the_suffixes() -> None:
    assert IMAGE_SUFFIXES == (".exr", ".png")
    assert SEQUENCE_SUFFIXES == (".gif", ".mp4")


# -- display_picture ----------------------------------------------------------------------------


def test_the_exposure_comes_from_the_object_not_the_background() -> None:
    rgb, coverage = _object_on_background()
    picture = display_picture(rgb, coverage)
    assert picture.shape == (6, 8, 3) and picture.dtype == np.uint8
    # The object's log-average 0.5 goes to the key 0.18 (exposure 0.36): 0.18 / 1.18.
    assert np.all(picture[coverage] == _code(0.18 / 1.18))
    # The background, 100 x 0.36 = 36, is compressed to 36 / 37.
    assert np.all(picture[~coverage] == _code(36.0 / 37.0))


def test_an_explicit_exposure_or_no_object() -> None:
    rgb, coverage = _object_on_background()
    assert np.all(display_picture(rgb, coverage, exposure=2.0)[coverage] == _code(0.5))
    # Nothing covered: exposure 1, so 0.5 -> 0.5 / 1.5.
    nothing = np.zeros_like(coverage)
    assert np.all(display_picture(rgb, nothing)[coverage] == _code(0.5 / 1.5))


# -- write_image --------------------------------------------------------------------------------


def test_write_image_exr_stores_linear_rgb_and_coverage_alpha(tmp_path: Path) -> None:
    rgb, coverage = _object_on_background()
    rgb[0, 3] = (0.25, 3.0, 1e4)
    write_image(tmp_path / "relit.exr", rgb.astype(np.float64), coverage)
    np.testing.assert_array_equal(read_pixels(tmp_path / "relit.exr"), rgb)
    with OpenEXR.File(str(tmp_path / "relit.exr"), separate_channels=True) as exr:
        alpha = exr.channels()["A"].pixels
    np.testing.assert_array_equal(alpha, coverage.astype(np.float32))
    assert _only(tmp_path) == ["relit.exr"]


def test_write_image_png_is_the_display_picture(tmp_path: Path) -> None:
    rgb, coverage = _object_on_background()
    write_image(tmp_path / "relit.png", rgb, coverage)
    back = read_pixels(tmp_path / "relit.png")
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, display_picture(rgb, coverage))
    assert np.all(back[coverage] == _code(0.18 / 1.18))
    write_image(tmp_path / "fixed.PNG", rgb, coverage, exposure=2.0)  # the suffix in any case
    assert np.all(read_pixels(tmp_path / "fixed.PNG")[coverage] == _code(0.5))


@pytest.mark.parametrize("name", ["relit.jpg", "relit.hdr", "relit"])
def test_write_image_refuses_other_suffixes(tmp_path: Path, name: str) -> None:
    rgb, coverage = _object_on_background()
    target = tmp_path / name
    with pytest.raises(InputError, match=re.escape(f"{target}: write an image as .exr or .png")):
        write_image(target, rgb, coverage)
    assert _only(tmp_path) == []


# -- write_sequence -----------------------------------------------------------------------------


def test_a_gif_holds_every_frame_and_loops(tmp_path: Path) -> None:
    frames = _frames(15, 21, count=5)
    write_sequence(tmp_path / "turn.gif", frames, fps=10.0)
    back = imageio.mimread(tmp_path / "turn.gif")
    assert len(back) == 5
    for original, read in zip(frames, back, strict=True):
        assert read.shape[:2] == (15, 21)
        np.testing.assert_array_equal(read[:, :, :3], original)  # few colours: exact palette
    meta = iio.immeta(tmp_path / "turn.gif")
    assert meta["loop"] == 0 and meta["duration"] == 100  # ms per frame at 10 fps
    assert _only(tmp_path) == ["turn.gif"]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.filterwarnings("ignore::ResourceWarning")
@pytest.mark.parametrize(("height", "width"), [(15, 21), (16, 22), (15, 22)])
def test_an_mp4_is_padded_to_even_sizes(tmp_path: Path, height: int, width: int) -> None:
    # (imageio's ffmpeg reader leaves its pipes to the garbage collector: the warnings
    # filtered here are the reader's, collected below.)
    frames = _frames(height, width, count=4)
    write_sequence(tmp_path / "turn.mp4", frames, fps=8.0)
    assert _only(tmp_path) == ["turn.mp4"]
    reader: Any
    with imageio.get_reader(tmp_path / "turn.mp4", format="FFMPEG") as reader:
        meta = reader.get_meta_data()
        count = reader.count_frames()
        back = [reader.get_data(i) for i in range(count)]
    gc.collect()
    even = (height + height % 2, width + width % 2)
    assert count == 4 and meta["codec"] == "h264" and meta["fps"] == 8.0
    assert meta["size"] == (even[1], even[0])  # (width, height)
    for original, read in zip(frames, back, strict=True):
        assert read.shape == (*even, 3)
        # Lossy, but the content is where it was: red on the left, the grey level elsewhere.
        error = np.abs(read[:height, :width].astype(int) - original.astype(int))
        assert np.median(error) <= 3
    if height % 2:
        assert back[3][-1, width // 2].max() < 40  # the padding row is black (not grey 180)


@pytest.mark.parametrize("suffix", SEQUENCE_SUFFIXES)
def test_an_empty_sequence_is_refused(tmp_path: Path, suffix: str) -> None:
    target = tmp_path / f"nothing{suffix}"
    with pytest.raises(InputError, match=re.escape(f"{target}: a sequence needs at least one")):
        write_sequence(target, [])
    assert _only(tmp_path) == []


@pytest.mark.parametrize("name", ["turn.avi", "turn.png", "turn"])
def test_a_sequence_of_another_suffix_is_refused(tmp_path: Path, name: str) -> None:
    target = tmp_path / name
    with pytest.raises(InputError, match=re.escape(f"{target}: write a sequence as .gif or .mp4")):
        write_sequence(target, _frames(4, 4))
    assert _only(tmp_path) == []


# -- a full disk, for real: a child process under a file size limit (tests/full_disk.py) --------


def test_every_output_refuses_a_full_disk_and_keeps_the_old_file(tmp_path: Path) -> None:
    # A full disk emptied r.png with exit 0 (OpenCV's imwrite) and cut an MP4 (ffmpeg's exit
    # status is not read by imageio): each is now an error naming the file, the old one kept.
    names = ("r.png", "r.exr", "turn.gif", "turn.mp4")
    for name in names:
        (tmp_path / name).write_bytes(b"the previous output")
    found = writes_under_limit(
        f"""
import numpy as np
from render.output import write_image, write_sequence
folder = {str(tmp_path)!r}
rng = np.random.default_rng(1)
rgb = rng.random((96, 96, 3)).astype(np.float32)
coverage = np.ones((96, 96), bool)
frames = [(rng.random((96, 96, 3)) * 255).astype(np.uint8) for _ in range(6)]
attempt("r.png", lambda: write_image(folder + "/r.png", rgb, coverage))
attempt("r.exr", lambda: write_image(folder + "/r.exr", rgb, coverage))
attempt("turn.gif", lambda: write_sequence(folder + "/turn.gif", frames))
attempt("turn.mp4", lambda: write_sequence(folder + "/turn.mp4", frames))
""",
        limit=2000,
    )
    for name in names:
        assert found[name]["project"], found[name]["traceback"]
        assert found[name]["message"].startswith(f"{tmp_path / name}: cannot write: ")
        assert (tmp_path / name).read_bytes() == b"the previous output"
    assert "nothing was replaced" in found["turn.mp4"]["message"].lower()
    assert _only(tmp_path) == sorted(names)
    assert "Traceback" not in found["stderr"]["text"]
