"""Decoding one captured image file to linear float32 RGB, with its saturated pixels.

Every reader returns a :class:`DecodedImage`: linear values scaled so that the format's (or the
sensor's) saturation level is 1.0, and a mask of the pixels that reached it. Exposure, dark
frames and bracket merging come after (:mod:`processing.hdr`); this module only undoes the
file's encoding.

========================== ==========================================================
format                     decoding
========================== ==========================================================
RAW (.dng .cr2 .nef ...)   rawpy (LibRaw): black level subtracted, scaled so the white
                           level is 1, demosaiced (bilinear by default), camera colour
                           space (``ColorSpace.raw``), fixed unit white balance, linear
                           (gamma (1, 1)), no auto-brightening, no maximum adjustment;
                           saturated = any raw site of the demosaic footprint (3 x 3)
                           at or above the white level
16-bit PNG / TIFF          linear: value / 65535; saturated = 65535
8-bit PNG / JPEG / TIFF    sRGB: the IEC 61966-2-1 curve decoded; saturated = 255
float TIFF, OpenEXR        linear as stored; nothing is marked saturated
========================== ==========================================================

Why the camera's own colour space for RAW: it keeps each channel proportional to the photo-
electrons its sites collected (no 3 x 3 matrix mixing channels, no clipping of out-of-gamut
negatives, no dependence on the file's colour-matrix tags), so one radiometric scale per camera
holds for every pixel and every channel, and a colour calibration (a white reference) can be
applied later as one matrix. The fixed white balance (1, 1, 1, 1) keeps the raw ratio between
channels; ``use_camera_wb`` would change it from file to file with the as-shot neutral. For the
simulated rig's DNGs (Rec. 709 channels, as-shot neutral 1) this returns the rendered linear
RGB exactly (see ``docs/processing.md``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import rawpy
from numpy.typing import NDArray

from core.errors import DatasetError, InputError
from core.image_io import (
    EXR_SUFFIXES,
    TIFF_SUFFIXES,
    ImageFileError,
    Transfer,
    check_tiff_strips,
    linear_from_pixels,
    read_pixels,
)

__all__ = [
    "DEMOSAIC_ALGORITHMS",
    "RAW_SUFFIXES",
    "DecodeError",
    "DecodedImage",
    "ImageFormat",
    "decode_image",
]

#: Suffixes decoded through rawpy (LibRaw), compared case-insensitively.
RAW_SUFFIXES = frozenset(
    {".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".raf", ".orf", ".rw2", ".pef"}
    | {".srw", ".3fr", ".iiq", ".erf", ".kdc", ".mos", ".mrw", ".x3f", ".raw"}
)
#: Read through OpenCV (:mod:`core.image_io`); Radiance HDR is a panorama format, not a capture's.
OPENCV_SUFFIXES = frozenset({".png", ".jpg", ".jpeg"})
#: Demosaicing algorithms offered for RAW files (LibRaw's names, lower case).
DEMOSAIC_ALGORITHMS = ("linear", "vng", "ppg", "ahd", "dcb", "dht", "aahd")
#: White balance multipliers (R, G, B, G2) applied to every RAW file: none.
RAW_WHITE_BALANCE = (1.0, 1.0, 1.0, 1.0)


class DecodeError(DatasetError):
    """An image file of a capture cannot be decoded (unreadable, truncated, wrong size...)."""


@dataclass(frozen=True)
class ImageFormat:
    """What one image file of a capture holds: its encoding and its stored channels.

    A capture is one format throughout: an 8-bit sRGB file among 16-bit linear ones, or a grey
    file among colour ones, is a file from elsewhere (:func:`decode_image`'s ``expected``).

    Attributes
    ----------
    encoding : "raw", "linear16", "srgb8" or "float"
    channels : 1 (grey) or 3 (colour; an alpha channel is dropped)
    example : str, a file of this format, for messages
    """

    encoding: str
    channels: int
    example: str = ""

    def describe(self) -> str:
        """In words: "16-bit linear colour"."""
        words = {"raw": "RAW", "linear16": "16-bit linear", "srgb8": "8-bit sRGB",
                 "float": "floating-point"}  # fmt: skip
        colour = "grey" if self.channels == 1 else "colour"
        return f"{words.get(self.encoding, self.encoding)} {colour}"


@dataclass(frozen=True)
class DecodedImage:
    """One image file, decoded.

    Attributes
    ----------
    path : Path, the file
    linear : ndarray, shape (H, W, 3), float32
        Linear values; 1.0 is the saturation level for integer formats (RAW white level, 65535,
        255). Float formats (EXR, float TIFF) are as stored.
    saturated : ndarray, shape (H, W, 3), bool
        Values that reached saturation and so only bound the true value from below.
    encoding : str
        What the file held: "raw", "linear16", "srgb8" or "float".
    channels : int, 1 for a grey file (its value repeated in ``linear``), else 3
    """

    path: Path
    linear: NDArray[np.float32]
    saturated: NDArray[np.bool_]
    encoding: str
    channels: int = 3

    @property
    def format(self) -> ImageFormat:
        """The file's :class:`ImageFormat`."""
        return ImageFormat(self.encoding, self.channels, str(self.path))

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in pixels."""
        return int(self.linear.shape[0]), int(self.linear.shape[1])


def decode_image(
    path: str | os.PathLike[str],
    *,
    expected_shape: tuple[int, int] | None = None,
    transfer: Transfer | None = None,
    demosaic: str = "linear",
    expected: ImageFormat | None = None,
) -> DecodedImage:
    """Decode one image file to linear float32 RGB and its saturation mask.

    Parameters
    ----------
    path : the file; the suffix picks the reader (see the module docstring)
    expected_shape : (height, width), optional
        Refuse an image of another size (a capture from another camera mode, a cropped file).
    transfer : {"srgb", "linear"}, optional
        Override the transfer curve of 8/16-bit PNG, JPEG and TIFF files (default: 8-bit is sRGB,
        16-bit is linear).
    demosaic : str, one of :data:`DEMOSAIC_ALGORITHMS`
        RAW demosaicing; ``linear`` (bilinear) is exactly linear in the raw data (checked
        whatever the file's format: a capture's option, not one file's).
    expected : ImageFormat, optional
        Refuse a file of another encoding or other channels (the capture's other files').

    Returns
    -------
    DecodedImage

    Raises
    ------
    DecodeError
        The file is missing, of an unknown format, unreadable, truncated, corrupt, not RGB or
        grey, not ``expected_shape`` or not of the ``expected`` format; the message names
        the file.
    """
    file = Path(path)
    suffix = file.suffix.lower()
    if not file.is_file():
        raise DecodeError(f"{file}: no such image file")
    if transfer not in (None, "srgb", "linear"):
        raise InputError(f"transfer must be 'srgb' or 'linear', got {transfer!r}")
    if demosaic not in DEMOSAIC_ALGORITHMS:
        raise InputError(f"unknown demosaic {demosaic!r}; use one of {DEMOSAIC_ALGORITHMS}")
    if suffix in RAW_SUFFIXES:
        image = _decode_raw(file, demosaic)
    elif suffix in TIFF_SUFFIXES or suffix in OPENCV_SUFFIXES:
        image = _from_pixels(file, _pixels(file), transfer)
    elif suffix in EXR_SUFFIXES:
        image = _decode_exr(file)
    else:
        known = sorted(RAW_SUFFIXES | TIFF_SUFFIXES | OPENCV_SUFFIXES | EXR_SUFFIXES)
        raise DecodeError(f"{file}: unknown image format {suffix!r}; use one of {known}")
    if not np.isfinite(image.linear).all():
        raise DecodeError(f"{file}: the image holds NaN or infinite values")
    if expected_shape is not None and image.shape != tuple(expected_shape):
        (h, w), (eh, ew) = image.shape, expected_shape
        raise DecodeError(f"{file}: image is {w}x{h} pixels, the camera model says {ew}x{eh}")
    if expected is not None and (image.encoding, image.channels) != (
        expected.encoding,
        expected.channels,
    ):
        raise DecodeError(
            f"{file}: a {image.format.describe()} image among the capture's "
            f"{expected.describe()} ones (such as {expected.example}): one bit depth and one "
            "set of channels per capture; replace the file with one of the capture's format"
        )
    return image


def _decode_raw(file: Path, demosaic: str) -> DecodedImage:
    try:
        check_tiff_strips(file)
    except ImageFileError as error:
        raise DecodeError(str(error)) from error
    algorithm = getattr(rawpy.DemosaicAlgorithm, demosaic.upper())
    try:
        with rawpy.imread(str(file)) as raw:
            # Copied first: postprocessing rescales LibRaw's buffer in place.
            sites = np.array(raw.raw_image_visible, copy=True)
            white = int(raw.white_level)
            rgb = raw.postprocess(
                demosaic_algorithm=algorithm,
                gamma=(1.0, 1.0),
                no_auto_bright=True,
                output_bps=16,
                use_camera_wb=False,
                use_auto_wb=False,
                user_wb=list(RAW_WHITE_BALANCE),
                output_color=rawpy.ColorSpace.raw,
                adjust_maximum_thr=0.0,  # scale by the file's white level, never the data's
                user_flip=0,  # pixels as the sensor read them: the rig's camera model frame
            )
    except (rawpy.LibRawError, rawpy.NotSupportedError, OSError, ValueError) as error:
        raise DecodeError(
            f"{file}: cannot decode as RAW (truncated, corrupt or unsupported?): "
            f"{type(error).__name__}: {error}"
        ) from error
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[:2] != sites.shape:
        raise DecodeError(
            f"{file}: RAW decoded to {rgb.shape}, the sensor area is {sites.shape}; only "
            f"uncropped 3-colour Bayer files are supported"
        )
    linear = rgb.astype(np.float32) / np.float32(65535.0)
    # A saturated site spoils every pixel whose interpolation reads it (3 x 3 for bilinear
    # demosaicing; wider algorithms are covered by the value test below only approximately).
    clipped = cv2.dilate((sites >= white).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    saturated = clipped[:, :, None] | (linear >= 1.0)
    return DecodedImage(file, linear, np.ascontiguousarray(saturated), "raw")


def _rgb(file: Path, pixels: NDArray[Any]) -> NDArray[Any]:
    """(H, W) grey or (H, W, 3/4) colour pixels as (H, W, 3) (see :func:`_channels`)."""
    if pixels.ndim == 2:
        return np.repeat(pixels[:, :, None], 3, axis=2)
    if pixels.ndim == 3 and pixels.shape[2] in (3, 4):
        return pixels[:, :, :3]
    raise DecodeError(f"{file}: expected a grey or RGB image, got pixels of shape {pixels.shape}")


def _channels(pixels: NDArray[Any]) -> int:
    """1 for grey pixels (H, W), else 3."""
    return 1 if pixels.ndim == 2 else 3


#: What 8- and 16-bit files hold: (encoding name, default transfer curve).
_INTEGER_ENCODINGS: dict[Any, tuple[str, Transfer]] = {
    np.dtype(np.uint8): ("srgb8", "srgb"),
    np.dtype(np.uint16): ("linear16", "linear"),
}


def _from_pixels(file: Path, pixels: NDArray[Any], transfer: Transfer | None) -> DecodedImage:
    rgb = _rgb(file, pixels)
    if rgb.dtype in (np.float16, np.float32, np.float64):
        values = np.ascontiguousarray(rgb, dtype=np.float32)
        saturated = np.zeros(values.shape, dtype=bool)
        return DecodedImage(file, values, saturated, "float", _channels(pixels))
    if rgb.dtype not in _INTEGER_ENCODINGS:
        raise DecodeError(f"{file}: unsupported pixel type {rgb.dtype}")
    encoding, default = _INTEGER_ENCODINGS[rgb.dtype]
    saturated = np.ascontiguousarray(rgb >= np.iinfo(rgb.dtype).max)
    values = linear_from_pixels(rgb, transfer=transfer or default)
    return DecodedImage(file, np.ascontiguousarray(values), saturated, encoding, _channels(pixels))


def _decode_exr(file: Path) -> DecodedImage:
    pixels = _pixels(file)
    rgb = np.ascontiguousarray(_rgb(file, pixels), dtype=np.float32)
    return DecodedImage(file, rgb, np.zeros(rgb.shape, dtype=bool), "float", _channels(pixels))


def _pixels(file: Path) -> NDArray[Any]:
    try:
        return read_pixels(file)
    except ImageFileError as error:
        raise DecodeError(str(error)) from error
