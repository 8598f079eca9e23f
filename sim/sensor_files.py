"""Files a simulated camera writes: 8-bit sRGB photos, 16-bit linear TIFFs and Bayer DNGs.

The DNG is a single-IFD, uncompressed CFA image (DNG 1.4, PhotometricInterpretation 32803)
with the tags a RAW decoder needs: CFA pattern, black and white level, a colour matrix and
the as-shot neutral. The sensor's channels are linear Rec. 709 primaries, so ColorMatrix1 is
the XYZ to linear-sRGB matrix under D65 and the as-shot neutral is (1, 1, 1): decoding with
rawpy in the camera's own colour space returns the rendered linear RGB. tifffile writes the
TIFF structure (a well-kept library; writing IFDs by hand would repeat it).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import tifffile
from numpy.typing import NDArray

from core.atomic import atomic_path
from core.errors import InputError
from core.image_io import write_linear16_tiff, write_srgb8
from sim.sensor import BAYER_PATTERNS, Sensor, bayer_mosaic, expose, to_linear16, to_srgb8

__all__ = [
    "PHOTO_SUFFIXES",
    "write_dng",
    "write_photo",
]

#: What each file suffix records: an ordinary photo, a linear TIFF, or the raw mosaic.
PHOTO_SUFFIXES = {
    ".png": "8-bit sRGB",
    ".jpg": "8-bit sRGB",
    ".jpeg": "8-bit sRGB",
    ".tif": "16-bit linear RGB",
    ".tiff": "16-bit linear RGB",
    ".dng": "Bayer raw",
}

#: XYZ -> linear sRGB (IEC 61966-2-1), D65 white; the DNG ColorMatrix1 of a Rec. 709 sensor.
XYZ_TO_LINEAR_SRGB = (
    (3.2404542, -1.5371385, -0.4985314),
    (-0.9692660, 1.8760108, 0.0415560),
    (0.0556434, -0.2040259, 1.0572252),
)
#: EXIF LightSource code of D65, used as the DNG calibration illuminant.
ILLUMINANT_D65 = 21
RATIONAL_DENOMINATOR = 1_000_000


def _srational(values: tuple[float, ...]) -> tuple[int, ...]:
    pairs: list[int] = []
    for value in values:
        pairs += [round(value * RATIONAL_DENOMINATOR), RATIONAL_DENOMINATOR]
    return tuple(pairs)


def write_dng(
    path: str | os.PathLike[str],
    mosaic: NDArray[np.uint16],
    sensor: Sensor,
    camera_name: str = "Reflectance rig simulator",
) -> None:
    """Write a Bayer mosaic as a DNG file, atomically.

    Parameters
    ----------
    path : path of the .dng file
    mosaic : ndarray, shape (H, W), uint16 digital numbers in ``sensor.pattern`` order
    sensor : Sensor
        Black and white level, pattern and exposure time recorded in the file.
    camera_name : str
        Make/model/UniqueCameraModel strings.
    """
    target = Path(path)
    if mosaic.ndim != 2 or mosaic.dtype != np.uint16:
        raise InputError(
            f"{target}: expected an (H, W) uint16 mosaic, got {mosaic.shape} {mosaic.dtype}"
        )
    matrix = tuple(value for row in XYZ_TO_LINEAR_SRGB for value in row)
    exposure = (round(sensor.exposure_s * RATIONAL_DENOMINATOR), RATIONAL_DENOMINATOR)
    tags = [
        (271, "s", 0, camera_name, True),  # Make
        (272, "s", 0, camera_name, True),  # Model
        (274, "H", 1, 1, True),  # Orientation: top-left
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, BAYER_PATTERNS[sensor.pattern], True),  # CFAPattern
        (33434, "2I", 1, exposure, True),  # ExposureTime, seconds
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, camera_name, True),  # UniqueCameraModel
        (50713, "H", 2, (1, 1), True),  # BlackLevelRepeatDim
        (50714, "I", 1, sensor.black_level, True),  # BlackLevel
        (50717, "I", 1, sensor.white_level, True),  # WhiteLevel
        (50721, "2i", 9, _srational(matrix), True),  # ColorMatrix1
        (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True),  # AsShotNeutral
        (50778, "H", 1, ILLUMINANT_D65, True),  # CalibrationIlluminant1
    ]
    with atomic_path(target) as temporary:
        tifffile.imwrite(
            temporary,
            np.ascontiguousarray(mosaic),
            photometric=32803,  # CFA
            compression=None,
            metadata=None,
            software="reflectance-rig",
            extratags=tags,
        )


def write_photo(
    path: str | os.PathLike[str],
    rgb: NDArray[np.floating],
    sensor: Sensor,
    seed: int | np.random.Generator = 0,
) -> None:
    """Expose linear radiance on ``sensor`` and write it in the format the suffix names.

    Parameters
    ----------
    path : .png/.jpg (8-bit sRGB), .tif/.tiff (16-bit linear) or .dng (Bayer raw)
    rgb : ndarray, shape (H, W, 3), linear radiance
    sensor : Sensor
    seed : noise seed (see :func:`sim.sensor.expose`)
    """
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in PHOTO_SUFFIXES:
        raise InputError(
            f"{target}: unknown photo format {suffix!r}; use one of {', '.join(PHOTO_SUFFIXES)}"
        )
    dn = expose(rgb, sensor, seed)
    if suffix == ".dng":
        write_dng(target, bayer_mosaic(dn, sensor.pattern), sensor)
    elif PHOTO_SUFFIXES[suffix] == "16-bit linear RGB":
        write_linear16_tiff(target, to_linear16(dn, sensor))
    else:
        write_srgb8(target, to_srgb8(dn, sensor))
