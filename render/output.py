"""Writing relit images and sequences: linear EXR, tone-mapped PNG, GIF and MP4.

One exposure serves a whole sequence (chosen on its first frame), so frames do not flicker.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import imageio.v2 as imageio
import imageio_ffmpeg  # type: ignore[import-untyped]
import numpy as np
from numpy.typing import NDArray

from core.atomic import atomic_path, write_bytes_atomic
from core.errors import InputError
from core.image_io import write_exr, write_srgb8
from render.tonemap import auto_exposure, tone_mapped_8bit

__all__ = [
    "IMAGE_SUFFIXES",
    "SEQUENCE_SUFFIXES",
    "display_picture",
    "write_image",
    "write_sequence",
]

IMAGE_SUFFIXES = (".exr", ".png")
SEQUENCE_SUFFIXES = (".gif", ".mp4")


def display_picture(
    rgb: NDArray[np.floating], coverage: NDArray[np.bool_], exposure: float | None = None
) -> NDArray[np.uint8]:
    """Tone-mapped 8-bit sRGB picture (H, W, 3) of a linear image; exposure from the object."""
    if exposure is None:
        covered = np.asarray(rgb)[coverage]
        exposure = auto_exposure(covered) if covered.size else 1.0
    return tone_mapped_8bit(rgb, exposure=exposure)


def write_image(
    path: str | os.PathLike[str],
    rgb: NDArray[np.floating],
    coverage: NDArray[np.bool_],
    exposure: float | None = None,
) -> None:
    """Write linear RGB + coverage alpha as OpenEXR, or a tone-mapped PNG, by suffix."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix == ".exr":
        write_exr(target, np.asarray(rgb, np.float32), coverage.astype(np.float32))
    elif suffix == ".png":
        write_srgb8(target, display_picture(rgb, coverage, exposure))
    else:
        raise InputError(f"{target}: write an image as {' or '.join(IMAGE_SUFFIXES)}")


def write_sequence(
    path: str | os.PathLike[str], frames: Sequence[NDArray[np.uint8]], fps: float = 12.0
) -> None:
    """Write 8-bit RGB frames (H, W, 3) as an animated GIF (looping) or an H.264 MP4."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in SEQUENCE_SUFFIXES:
        raise InputError(f"{target}: write a sequence as {' or '.join(SEQUENCE_SUFFIXES)}")
    if not frames:
        raise InputError(f"{target}: a sequence needs at least one frame")
    if suffix == ".gif":
        # Encoded in memory, the file written checked (Pillow's own writing leaves a cut file
        # and a second error when the disk is full).
        encoded = imageio.mimwrite(
            "<bytes>", list[Any](frames), format="GIF", duration=1000.0 / fps, loop=0
        )
        write_bytes_atomic(target, encoded)
        return
    # H.264 wants even sizes; pad by one black row/column where needed.
    height, width = frames[0].shape[:2]
    pad = ((0, height % 2), (0, width % 2), (0, 0))
    padded: list[Any] = [np.pad(frame, pad) for frame in frames]
    with atomic_path(target) as temporary:
        imageio.mimwrite(temporary, padded, fps=fps, macro_block_size=1, format="FFMPEG")
        _check_video(target, temporary, len(padded))


def _check_video(target: Path, written: Path, count: int) -> None:
    """Read the video ``written`` back: ffmpeg's failed writes (a full disk) are not reported.

    imageio ignores ffmpeg's exit status, so a video cut short by the disk looks written; a
    video that does not decode, or holds fewer frames, is an InputError naming ``target``.
    """
    try:
        frames, _ = imageio_ffmpeg.count_frames_and_secs(str(written))
    except (RuntimeError, OSError) as error:
        last = str(error).strip().splitlines()[-1:] or [""]
        raise InputError(
            f"{target}: cannot write: the video written does not decode ({last[0]}); is the "
            "disk full? Nothing was replaced"
        ) from None
    if frames != count:
        raise InputError(
            f"{target}: cannot write: the video written holds {frames} of {count} frames; is the "
            "disk full? Nothing was replaced"
        )
