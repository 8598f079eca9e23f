"""Reflectance Transformation Imaging (RTI) data: ``.lp`` files and single-view fields.

An RTI capture is one fixed camera and T photographs, each lit from one direction, listed in an
``.lp`` file::

    240
    jpg/Loewenkopf_klein_0001.jpg -0.0019356994 -0.14720464 0.98910415
    ...

The first line is the image count N, then N lines ``filename x y z`` (whitespace-separated; the
filename is relative to the ``.lp`` file's folder and may name a subfolder). The directions point
from the object toward the light in the CAMERA frame: x to the image's right, y to the image's
top, z toward the camera. Files in the wild carry Windows or old-Mac line endings, tabs, blank
lines and float32-rounded vectors; all are accepted (every direction is normalised). A count that
disagrees with the entries, a missing or non-numeric value, a zero or non-finite vector is refused
with the file and line number.

This project also reads (and :func:`write_lp` writes) a fifth column, ``filename x y z
intensity``: the light's relative intensity (positive, finite), by which the import divides the
image. Every line has four columns or every line has five. A line is read as five columns when
it has five or more fields and the fourth from the end is a number, so an image name whose last
space-separated part is a number (``scan 2``) cannot be used: :func:`write_lp` refuses it, and
:func:`read_lp` reads its line as five columns and refuses the mix with the others.

Beside the ``.lp`` file (:func:`import_rti` looks for them; the first name found is used):

- a mask, ``<lp stem>.mask.png`` or else ``mask.png``: non-zero pixels are the object, the
  others are not samples (an explicit ``mask`` argument wins over both);
- light intensities, ``<lp stem>.intensities`` or else ``intensities.txt``: UTF-8 text, one line
  ``filename intensity`` per image, names as in the ``.lp`` file, every image exactly once in
  any order; blank lines and lines starting with ``#`` are skipped (see
  :func:`read_intensity_sidecar`). A fifth column and a sidecar together are refused.

Imported, an RTI capture becomes a field of pixels (``core.field_store``, samples of kind
``"pixels"``) with one camera straight above the object (azimuth 0, inclination 0): the object
plane is the rig's xy-plane and a light's camera z is its rig z (the cosine of its inclination).
That camera's image right is rig ``+y`` and its image up is rig ``-x`` (the limit of
:meth:`core.camera_model.PinholeCamera.axes` approached from azimuth 0). An RTI file does not
record the camera's distance or field of view; nominal values are stored and marked as such.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from core.atomic import atomic_path
from core.camera_model import PinholeCamera, camera_to_rig, rig_to_camera
from core.errors import DatasetError, InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.image_io import (
    ImageFileError,
    PixelDepth,
    Transfer,
    TransferChoice,
    auto_transfer,
    linear_from_pixels,
    pixel_depth,
    read_pixels,
    write_linear16_tiff,
    write_srgb8,
)

__all__ = [
    "INTENSITY_SIDECARS",
    "MASK_SIDECARS",
    "NOMINAL_DISTANCE",
    "NOMINAL_FOV_DEG",
    "LightPositions",
    "export_lp",
    "import_rti",
    "open_field_or_rti",
    "read_intensity_sidecar",
    "read_lp",
    "rti_camera",
    "write_lp",
    "write_rti_capture",
]

#: Nominal camera distance (scene units) of an imported RTI view: the data do not record it.
NOMINAL_DISTANCE = 10.0
#: Nominal horizontal field of view (degrees) of an imported RTI view: the data do not record it.
NOMINAL_FOV_DEG = 10.0

#: Vectors shorter than this are "zero": they have no direction to normalise to.
_ZERO_LENGTH = 1e-9

#: Mask sidecars beside an ``.lp`` file, in the order looked for (``{stem}``: the file's stem).
MASK_SIDECARS = ("{stem}.mask.png", "mask.png")
#: Intensity sidecars beside an ``.lp`` file, in the order looked for.
INTENSITY_SIDECARS = ("{stem}.intensities", "intensities.txt")

#: What ``transfer="auto"`` assumes, as the import reports it.
_AUTO_RULE = "auto: 8-bit is sRGB, 16-bit and float are linear"


@dataclass(frozen=True, eq=False)
class LightPositions:
    """The contents of an ``.lp`` file.

    Attributes
    ----------
    files : list of str, length N
        Image file names as written, relative to the ``.lp`` file's folder.
    directions : ndarray, shape (N, 3), float64
        Unit vectors toward each light in the camera frame (x right, y up, z toward the camera).
    lines : tuple of int, length N or empty
        1-based line of each entry in the file it was read from (empty if not read from a file).
    source : Path or None
        The file it was read from.
    intensities : ndarray, shape (N,), float64, or None
        Each light's relative intensity (the fifth column; positive, finite), None when the
        file has four columns.
    """

    files: list[str]
    directions: NDArray[np.float64]
    lines: tuple[int, ...] = ()
    source: Path | None = None
    intensities: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        count = len(self.files)
        if np.shape(self.directions) != (count, 3):
            raise InputError(
                f"light directions must have shape ({count}, 3) for {count} files, "
                f"got {np.shape(self.directions)}"
            )
        if self.lines and len(self.lines) != count:
            raise InputError(f"{len(self.lines)} line numbers for {count} files")
        if self.intensities is not None:
            if np.shape(self.intensities) != (count,):
                raise InputError(
                    f"light intensities must have shape ({count},) for {count} files, "
                    f"got {np.shape(self.intensities)}"
                )
            bad = np.flatnonzero(~(np.isfinite(self.intensities) & (self.intensities > 0)))
            if bad.size:
                raise InputError(
                    f"light {bad[0]} ({self.files[bad[0]]!r}): intensity "
                    f"{self.intensities[bad[0]]} is not a positive finite number"
                )

    def __len__(self) -> int:
        return len(self.files)

    def line(self, index: int) -> int:
        """1-based line of entry ``index`` (where :func:`write_lp` would put it, if unknown)."""
        return self.lines[index] if self.lines else index + 2


def _parse_direction(values: Sequence[str], where: str) -> NDArray[np.float64]:
    numbers = []
    for value in values:
        try:
            numbers.append(float(value))
        except ValueError:
            raise DatasetError(f"{where}: {value!r} is not a number") from None
    vector = np.array(numbers, dtype=np.float64)
    if not np.all(np.isfinite(vector)):
        raise DatasetError(f"{where}: the direction {values} is not finite")
    length = float(np.linalg.norm(vector))
    if length < _ZERO_LENGTH:
        raise DatasetError(f"{where}: the direction {values} has zero length")
    return vector / length


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _numeric_tail(name: str) -> bool:
    """Whether a name's last whitespace-separated part is a number (``scan 2``)."""
    parts = name.split()
    return len(parts) > 1 and _is_number(parts[-1])


def _parse_intensity(value: str, where: str) -> float:
    """A light intensity: a positive finite number (a zero would divide the image by zero)."""
    try:
        number = float(value)
    except ValueError:
        raise DatasetError(f"{where}: intensity {value!r} is not a number") from None
    if not (math.isfinite(number) and number > 0):
        raise DatasetError(
            f"{where}: intensity {value!r} must be a positive finite number (the light's "
            "relative intensity; the image is divided by it)"
        )
    return number


def read_lp(path: str | os.PathLike[str]) -> LightPositions:
    """Read an RTI ``.lp`` file.

    Parameters
    ----------
    path : path to the ``.lp`` file (UTF-8, with or without a byte-order mark; any line endings)

    Returns
    -------
    LightPositions
        N file names as written and N unit directions (N, 3) in the camera frame; every vector
        is normalised, whatever its length. ``intensities`` (N,) when the lines have a fifth
        column, else None.

    Raises
    ------
    DatasetError
        Missing or unreadable file, empty file, a first line that is not a positive count, more
        or fewer entries than the count, a line that is not ``filename x y z`` (or ``filename x
        y z intensity``), four- and five-column lines mixed, a non-numeric, non-finite or
        zero-length direction, an intensity that is not a positive finite number. The message
        names the file and the line.
    """
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DatasetError(f"{file}: no such .lp file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(f"{file}: cannot read as a text .lp file: {error}") from error
    # Line numbers as an editor shows them, for \n, \r\n and \r endings alike.
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    entries = [(number, line.strip()) for number, line in enumerate(lines, 1) if line.strip()]
    if not entries:
        raise DatasetError(f"{file}, line 1: empty file; an .lp file starts with the image count")
    header_line, header = entries[0]
    try:
        count = int(header)
    except ValueError:
        count = 0
    if count < 1:
        raise DatasetError(
            f"{file}, line {header_line}: expected the image count (a positive integer), "
            f"got {header!r}"
        )
    rows = entries[1:]
    if len(rows) > count:
        raise DatasetError(
            f"{file}, line {rows[count][0]}: more entries than the {count} announced on line "
            f"{header_line}"
        )
    if len(rows) < count:
        last = rows[-1][0] if rows else header_line
        raise DatasetError(
            f"{file}, line {header_line}: announces {count} images but only {len(rows)} entries "
            f"follow (the file ends after line {last})"
        )
    files: list[str] = []
    directions = np.empty((count, 3), dtype=np.float64)
    intensities = np.empty(count, dtype=np.float64)
    columns = 0  # the first entry's, which every other must have
    for index, (number, line) in enumerate(rows):
        where = f"{file}, line {number}"
        tokens = line.split()
        found = 5 if len(tokens) >= 5 and _is_number(tokens[-4]) else 4
        if len(tokens) < 4:
            raise DatasetError(
                f"{where}: expected 'filename x y z' (or 'filename x y z intensity'), got {line!r}"
            )
        if not columns:
            columns = found
        elif found != columns:
            first = rows[0][0]
            raise DatasetError(
                f"{where}: {found} columns, but line {first} has {columns}; give every line an "
                "intensity ('filename x y z intensity') or none ('filename x y z'); an image "
                "name ending in a separate number reads as a fifth column: rename it"
            )
        fields = line.rsplit(None, columns - 1)  # the filename keeps any inner spaces
        files.append(fields[0])
        directions[index] = _parse_direction(fields[1:4], where)
        if columns == 5:
            intensities[index] = _parse_intensity(fields[4], where)
    return LightPositions(
        files=files,
        directions=directions,
        lines=tuple(number for number, _ in rows),
        source=file,
        intensities=intensities if columns == 5 else None,
    )


def read_intensity_sidecar(
    path: str | os.PathLike[str], lights: LightPositions
) -> NDArray[np.float64]:
    """Read a light-intensity sidecar: one ``filename intensity`` line per image of ``lights``.

    Parameters
    ----------
    path : the sidecar (UTF-8 text; any line endings; blank lines and ``#`` comments skipped)
    lights : the ``.lp`` file's contents; every one of its file names, as written there, must
        appear exactly once (in any order; a name may hold inner spaces)

    Returns
    -------
    ndarray, shape (N,), float64
        The intensity of each light in the ``.lp`` file's order (relative units, positive).

    Raises
    ------
    DatasetError
        Unreadable file, a line that is not ``filename intensity``, an intensity that is not a
        positive finite number, a name the ``.lp`` file does not list or listed twice (both
        lines named), an image of the ``.lp`` file without an intensity (the count and the
        first such name given).
    """
    file = Path(path)
    lp_name = lights.source.name if lights.source is not None else "the .lp file"
    try:
        text = file.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DatasetError(f"{file}: no such intensity file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(f"{file}: cannot read as a text intensity file: {error}") from error
    index_of = {name: index for index, name in enumerate(lights.files)}
    values = np.full(len(lights), np.nan)
    seen: dict[str, int] = {}
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    for number, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{file}, line {number}"
        fields = line.rsplit(None, 1)
        if len(fields) != 2:
            raise DatasetError(f"{where}: expected 'filename intensity', got {line!r}")
        name, value = fields
        if name not in index_of:
            raise DatasetError(
                f"{where}: {name!r} is not an image of {lp_name}; name each image as the .lp "
                "file does"
            )
        if name in seen:
            raise DatasetError(f"{where}: {name!r} already has an intensity on line {seen[name]}")
        seen[name] = number
        values[index_of[name]] = _parse_intensity(value, where)
    missing = np.flatnonzero(np.isnan(values))
    if missing.size:
        first = int(missing[0])
        raise DatasetError(
            f"{file}: lists {len(seen)} intensities for the {len(lights)} images of {lp_name}; "
            f"{lights.files[first]!r} ({lp_name} line {lights.line(first)}) has none"
            + (f", nor {missing.size - 1} more" if missing.size > 1 else "")
        )
    return values


def write_lp(
    path: str | os.PathLike[str],
    files: Sequence[str],
    directions: ArrayLike,
    intensities: ArrayLike | None = None,
) -> LightPositions:
    r"""Write an RTI ``.lp`` file atomically.

    Parameters
    ----------
    path : path of the ``.lp`` file to write (its folder is created if needed)
    files : sequence of str, length N >= 1
        Image names relative to the ``.lp`` file's folder; non-empty, no line breaks, no leading
        or trailing whitespace (inner spaces survive :func:`read_lp`, but other RTI tools split
        on them).
    directions : array_like, shape (N, 3)
        Directions toward the lights in the camera frame (x right, y up, z toward the camera);
        normalised before writing.
    intensities : array_like, shape (N,), or None
        Each light's relative intensity (positive, finite), written as a fifth column; None
        writes the usual four.

    Returns
    -------
    LightPositions
        What was written (unit directions, the intensities), with the line numbers of the file.

    Notes
    -----
    Format: ``N\n`` then ``name x y z\n`` (or ``name x y z intensity\n``) per image; the
    numbers are written with the shortest representation that reads back to the same float64
    (``repr``). RTI tools that know four columns only will not read a five-column file.

    Raises
    ------
    InputError
        No files, a count or shape mismatch, a bad name, a zero-length or non-finite direction,
        an intensity that is not a positive finite number; the message names the file and the
        line the entry would occupy.
    """
    file = Path(path)
    names = list(files)
    vectors = np.asarray(directions, dtype=np.float64)
    if not names:
        raise InputError(f"{file}: an .lp file needs at least one image")
    if vectors.shape != (len(names), 3):
        raise InputError(
            f"{file}: {len(names)} file names need directions of shape ({len(names)}, 3), "
            f"got {vectors.shape}"
        )
    scales = None if intensities is None else np.asarray(intensities, dtype=np.float64)
    if scales is not None and scales.shape != (len(names),):
        raise InputError(
            f"{file}: {len(names)} file names need intensities of shape ({len(names)},), "
            f"got {scales.shape}"
        )
    unit = np.empty_like(vectors)
    for index, (name, vector) in enumerate(zip(names, vectors, strict=True)):
        where = f"{file}, line {index + 2}"
        if not isinstance(name, str) or not name or name != name.strip():
            raise InputError(f"{where}: image name {name!r} is empty or has edge whitespace")
        if "\n" in name or "\r" in name:
            raise InputError(f"{where}: image name {name!r} contains a line break")
        length = float(np.linalg.norm(vector))
        if not (np.all(np.isfinite(vector)) and length >= _ZERO_LENGTH):
            raise InputError(f"{where}: direction {vector.tolist()} is zero or not finite")
        if scales is not None and not (np.isfinite(scales[index]) and scales[index] > 0):
            raise InputError(
                f"{where}: intensity {float(scales[index])} is not a positive finite number"
            )
        if _numeric_tail(name):
            # read_lp would take the name's last part for x and the line for five columns.
            raise InputError(
                f"{where}: image name {name!r} ends in a separate number, which an .lp file "
                "cannot hold (it would read as a column); rename the image"
            )
        unit[index] = vector / length
    rows = [
        f"{name} {float(x)!r} {float(y)!r} {float(z)!r}"
        for name, (x, y, z) in zip(names, unit, strict=True)
    ]
    if scales is not None:
        rows = [f"{row} {float(scale)!r}" for row, scale in zip(rows, scales, strict=True)]
    body = "".join(f"{row}\n" for row in rows)
    with atomic_path(file) as temporary:
        temporary.write_text(f"{len(names)}\n{body}", encoding="utf-8")
    return LightPositions(
        files=names,
        directions=unit,
        lines=tuple(range(2, len(names) + 2)),
        source=file,
        intensities=None if scales is None else scales.copy(),
    )


def rti_camera(width: int, height: int) -> PinholeCamera:
    """The camera of an imported RTI view: straight above the object, nominal intrinsics.

    Parameters
    ----------
    width, height : int, image size in pixels

    Returns
    -------
    PinholeCamera
        Azimuth 0, inclination 0, distance :data:`NOMINAL_DISTANCE`, horizontal field of view
        :data:`NOMINAL_FOV_DEG` (placeholders: RTI data record neither).
    """
    return PinholeCamera(
        azimuth_deg=0.0,
        inclination_deg=0.0,
        distance=NOMINAL_DISTANCE,
        fov_deg=NOMINAL_FOV_DEG,
        width=width,
        height=height,
    )


def _image_path(folder: Path, name: str) -> Path:
    """The image ``name`` of an ``.lp`` file in ``folder``; Windows separators are accepted."""
    path = folder / name
    if not path.exists() and "\\" in name:
        path = folder / name.replace("\\", "/")
    return path


def _read_rti_pixels(path: Path, where: str) -> NDArray[Any]:
    """The stored values (H, W, 3) of one RTI photograph; grey is repeated, alpha dropped."""
    try:
        pixels = read_pixels(path)
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[2] not in (1, 3, 4):
        raise DatasetError(f"{where}: {path}: expected a grey or RGB image, got {pixels.shape}")
    if pixels.shape[2] == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    return pixels[:, :, :3]


def _linear_rti_image(
    pixels: NDArray[Any], transfer: Transfer, path: Path, where: str
) -> NDArray[np.float32]:
    """Linear float32 (H, W, 3) of one photograph's stored values; non-finite values refused."""
    try:
        image = linear_from_pixels(pixels, transfer=transfer, where=str(path))
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error
    if not np.all(np.isfinite(image)):
        raise DatasetError(f"{where}: {path}: NaN or infinite pixel values")
    return np.ascontiguousarray(image, dtype=np.float32)


def _sidecar(folder: Path, stem: str, patterns: Sequence[str]) -> Path | None:
    """The first of ``patterns`` (``{stem}`` filled in) that is a file in ``folder``."""
    for pattern in patterns:
        candidate = folder / pattern.format(stem=stem)
        if candidate.is_file():
            return candidate
    return None


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _read_mask(path: Path, how: str, height: int, width: int) -> NDArray[np.bool_]:
    """Which of the H W pixels (row-major, (P,) bool) a mask image marks: its non-zero ones.

    ``how`` says where the mask came from (``"mask argument"``, ``"mask sidecar"``), for the
    messages.
    """
    try:
        pixels = read_pixels(path)
    except ImageFileError as error:
        raise DatasetError(f"{how}: {error}") from error
    if pixels.ndim not in (2, 3):
        raise DatasetError(f"{how} {path}: expected a grey or RGB image, got {pixels.shape}")
    if pixels.shape[:2] != (height, width):
        raise DatasetError(
            f"{how} {path}: {pixels.shape[1]}x{pixels.shape[0]} pixels, the images are "
            f"{width}x{height} (width x height); give a mask of the images' size"
        )
    if pixels.dtype.kind == "f" and not np.all(np.isfinite(pixels)):
        raise DatasetError(f"{how} {path}: NaN or infinite values; a mask is 0 or non-zero")
    selected = pixels != 0 if pixels.ndim == 2 else np.any(pixels != 0, axis=2)
    if not selected.any():
        raise DatasetError(
            f"{how} {path}: every pixel is zero, so no pixel would count; non-zero pixels mark "
            "the object"
        )
    return np.ascontiguousarray(selected.reshape(-1))


def _transfer_record(
    requested: TransferChoice, first: NDArray[Any], depth: PixelDepth, first_name: str
) -> tuple[Transfer, dict[str, Any], str]:
    """The curve applied to every image, its provenance record and its words for the report."""
    applied: Transfer = auto_transfer(first) if requested == "auto" else requested
    if depth == "float":
        applied = "linear"  # floats are linear as stored, whatever was asked
        said = "taken as stored (float: linear"
        said += "; transfer 'srgb' does not apply to floats)" if requested == "srgb" else ")"
    else:
        curve = "sRGB" if applied == "srgb" else "linear"
        said = f"decoded as {curve} (" + (
            f"{_AUTO_RULE}; transfer 'srgb' or 'linear' overrides)"
            if requested == "auto"
            else f"transfer {requested!r} as asked)"
        )
    record = {
        "requested": requested,
        "applied": applied,
        "bit_depth": depth,
        "first_image": first_name,
        "rule": _AUTO_RULE,
    }
    return applied, record, said


def import_rti(
    lp_path: str | os.PathLike[str],
    output_store: str | os.PathLike[str],
    *,
    dtype: str = "float32",
    progress: bool = True,
    overwrite: bool = True,
    transfer: TransferChoice = "auto",
    mask: str | os.PathLike[str] | None = None,
) -> ReflectanceField:
    """Import an RTI capture (an ``.lp`` file and its images) as a single-view pixel field.

    Parameters
    ----------
    lp_path : path to the ``.lp`` file; image names are relative to its folder
    output_store : path of the field store to create
    overwrite : bool, replace an existing field store there (and the fit saved beside it)
    dtype : {"float32", "float16"}, storage dtype of the radiance
    progress : bool
        Show a progress bar (one step per image) and print what the import assumed (the
        ``assumed`` line below) to stderr first.
    transfer : {"auto", "srgb", "linear"}
        How the images' integer values encode light. ``"auto"``: 8-bit images (JPEG, PNG, TGA,
        BMP...) are sRGB, 16-bit (PNG, TIFF) linear; float images (EXR, HDR, PFM, float TIFF)
        are linear whatever is asked.
    mask : path of a mask image, or None
        Non-zero pixels are the object: the others are not samples (visibility False). None
        looks for a sidecar beside the ``.lp`` file (:data:`MASK_SIDECARS`: ``<stem>.mask.png``,
        then ``mask.png``); without one, every pixel counts.

    Returns
    -------
    ReflectanceField
        The new store, opened: S = 1 camera (:func:`rti_camera` with the images' size), T = N
        lights (unit directions in the rig frame, (T, 3)), P = H W pixels in row-major order;
        radiance (1, T, P, 3) is each image, linear (grey repeated to RGB), divided by its
        light's intensity when the ``.lp`` file's fifth column or a sidecar
        (:data:`INTENSITY_SIDECARS`) gives intensities, in the images' relative units (RTI
        intensities are not calibrated); visibility (1, P) is the mask (all True without one).
        Its ``provenance`` records every assumption: ``transfer`` (requested, applied, the bit
        depth seen), ``mask`` (file, SHA-256, where it was found, pixels selected; None),
        ``intensities`` (source, SHA-256 of a sidecar, the values; None) and ``assumed``, one
        line saying all of it.

    Raises
    ------
    DatasetError
        A bad ``.lp`` file (see :func:`read_lp`) or intensity sidecar (see
        :func:`read_intensity_sidecar`), intensities in both; a missing, unreadable or
        non-finite image, images of different sizes or bit depths (the first that differs
        named with its ``.lp`` line); a mask that cannot be read, is not the images' size or
        selects no pixel.
    InputError
        A bad ``dtype`` or ``transfer``, or an output path that exists and is not a field store
        (or is one, without ``overwrite``).

    Notes
    -----
    The store is written beside ``output_store`` under a temporary name and renamed into place
    once complete: a failed or interrupted import leaves no half-filled store behind.
    """
    lp_file = Path(lp_path)
    target = Path(output_store)
    if dtype not in ("float16", "float32"):
        raise InputError(f"field dtype must be float16 or float32, got {dtype!r}")
    if transfer not in ("auto", "srgb", "linear"):
        raise InputError(f"transfer must be 'auto', 'srgb' or 'linear', got {transfer!r}")
    lights = read_lp(lp_file)
    folder = lp_file.parent
    paths = [_image_path(folder, name) for name in lights.files]
    for index, path in enumerate(paths):
        if not path.is_file():
            raise DatasetError(
                f"{lp_file}, line {lights.line(index)}: image {lights.files[index]!r} not found "
                f"({path})"
            )
    intensities, intensity_record = _intensities(lp_file, lights)
    first_where = f"{lp_file}, line {lights.line(0)}"
    first = _read_rti_pixels(paths[0], first_where)
    depth = _depth(first, paths[0], first_where)
    applied, transfer_record, transfer_said = _transfer_record(
        transfer, first, depth, lights.files[0]
    )
    height, width = first.shape[:2]
    visible, mask_record = _mask(lp_file, mask, height, width)
    assumed = "; ".join(
        [
            f"rti {lp_file.name}: {len(lights)} {depth} images {transfer_said}",
            "mask: none, every pixel counts"
            if mask_record is None
            else f"mask: {mask_record['file']} ({mask_record['found']}), "
            f"{mask_record['pixels']} of {height * width} pixels count",
            "intensities: none, the lights are taken as equal"
            if intensity_record is None
            else f"intensities: {intensity_record['source']} "
            f"({min(intensity_record['values']):g} to {max(intensity_record['values']):g}), "
            "each image divided by its own",
        ]
    )
    if progress:
        print(assumed, file=sys.stderr)
    camera = rti_camera(width, height)
    writer = FieldStoreWriter(
        target,
        overwrite=overwrite,
        points=None,
        normals=None,
        light_directions=camera_to_rig(lights.directions, camera),
        cameras=[camera],
        image_shape=(height, width),
        dtype=dtype,
        light_model={
            "type": "directional",
            "irradiance": 1.0,
            "note": "RTI: intensities not calibrated"
            if intensities is None
            else "RTI: each image divided by its light's relative intensity (not calibrated)",
        },
        provenance={
            "source": "rti",
            "tool": "processing.rti.import_rti",
            "lp": str(lp_file.resolve()),
            "images": len(lights),
            "first_image": lights.files[0],
            "transfer": transfer_record,
            "mask": mask_record,
            "intensities": intensity_record,
            "assumed": assumed,
            "light_frame": (
                "the .lp directions (camera frame: x right, y up, z toward the camera) are "
                "stored in the rig frame of a camera straight above the object"
            ),
            "camera_intrinsics": {
                "distance": NOMINAL_DISTANCE,
                "fov_deg": NOMINAL_FOV_DEG,
                "nominal": True,
                "note": "RTI data record neither the camera distance nor its field of view",
            },
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
        },
    )
    try:
        steps = tqdm(paths, desc="rti", unit="image", disable=not progress)
        for index, path in enumerate(steps):
            where = f"{lp_file}, line {lights.line(index)}"
            pixels = first if index == 0 else _read_rti_pixels(path, where)
            name = lights.files[index]
            if pixels.shape[:2] != (height, width):
                raise DatasetError(
                    f"{where}: image {name!r} is {pixels.shape[1]}x{pixels.shape[0]} pixels, "
                    f"the first ({lights.files[0]!r}) is {width}x{height}"
                )
            seen = _depth(pixels, path, where)
            if seen != depth:
                raise DatasetError(
                    f"{where}: image {name!r} is {seen}, the first ({lights.files[0]!r}) is "
                    f"{depth}; a capture's images share one bit depth (one transfer curve "
                    "decodes them all): convert them alike"
                )
            image = _linear_rti_image(pixels, applied, path, where)
            if intensities is not None:
                # Radiance per unit irradiance: the lights' differences leave the data.
                image = image / np.float32(intensities[index])
            writer.write_slab(0, index, image.reshape(-1, 3))
        steps.close()
        writer.write_visibility(0, visible)
    except BaseException:
        writer.abort()
        raise
    writer.finish()
    return ReflectanceField.open(target)


def _depth(pixels: NDArray[Any], path: Path, where: str) -> PixelDepth:
    try:
        return pixel_depth(pixels, where=str(path))
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error


def _mask(
    lp_file: Path, mask: str | os.PathLike[str] | None, height: int, width: int
) -> tuple[NDArray[np.bool_], dict[str, Any] | None]:
    """The visibility (H W,) of the import and its provenance record (None: no mask)."""
    if mask is not None:
        path, found = Path(mask), "mask argument"
    else:
        sidecar = _sidecar(lp_file.parent, lp_file.stem, MASK_SIDECARS)
        if sidecar is None:
            return np.ones(height * width, dtype=bool), None
        path, found = sidecar, "mask sidecar"
    visible = _read_mask(path, found, height, width)
    record = {
        "file": str(path.resolve()),
        "sha256": _sha256(path),
        "found": found,
        "pixels": int(visible.sum()),
        "rule": "non-zero pixels count; the others are not samples (visibility False)",
    }
    return visible, record


def _intensities(
    lp_file: Path, lights: LightPositions
) -> tuple[NDArray[np.float64] | None, dict[str, Any] | None]:
    """The lights' intensities (fifth column or sidecar) and their provenance record."""
    sidecar = _sidecar(lp_file.parent, lp_file.stem, INTENSITY_SIDECARS)
    if lights.intensities is not None:
        if sidecar is not None:
            raise DatasetError(
                f"{lp_file}: gives intensities in a fifth column and {sidecar} gives them too; "
                "keep one of the two"
            )
        values = lights.intensities
        record: dict[str, Any] = {"source": f"{lp_file.name} fifth column"}
    elif sidecar is not None:
        values = read_intensity_sidecar(sidecar, lights)
        record = {"source": str(sidecar.resolve()), "sha256": _sha256(sidecar)}
    else:
        return None, None
    record["values"] = [float(value) for value in values]
    record["rule"] = "each image divided by its light's intensity"
    return values, record


def write_rti_capture(
    folder: str | os.PathLike[str],
    name: str,
    images: NDArray[np.floating],
    directions: ArrayLike,
    *,
    scale: float,
    mask: NDArray[np.bool_] | None = None,
) -> Path:
    """Write an RTI capture as a dome would leave it: images, ``NAME.lp`` and ``NAME.mask.png``.

    Parameters
    ----------
    folder : the capture's folder (created)
    name : the ``.lp`` file's stem; images are ``images/NAME_NNN.tif``
    images : ndarray, shape (T, H, W, 3), linear radiance
    directions : array_like, shape (T, 3), toward each light in the camera frame
    scale : float > 0, the radiance written as 16-bit white (values above are clipped)
    mask : ndarray (H, W) of bool, or None: the object's pixels (the sidecar the import reads)

    Returns
    -------
    Path of the ``.lp`` file. Images are linear 16-bit TIFF (:func:`import_rti` reads 16-bit
    as linear by default).
    """
    root = Path(folder)
    pictures = np.asarray(images, dtype=np.float64)
    if pictures.ndim != 4 or pictures.shape[3] != 3 or not scale > 0:
        raise InputError(f"images must be (T, H, W, 3) and scale positive, got {pictures.shape}")
    files = [f"images/{name}_{t:03d}.tif" for t in range(len(pictures))]
    for file, image in zip(files, pictures, strict=True):
        levels = np.round(np.clip(image * scale, 0.0, 1.0) * 65535.0).astype(np.uint16)
        write_linear16_tiff(root / file, levels)
    lp = root / f"{name}.lp"
    write_lp(lp, files, directions)
    if mask is not None:
        picture = np.where(np.asarray(mask, dtype=bool), 255, 0).astype(np.uint8)
        write_srgb8(root / f"{name}.mask.png", np.repeat(picture[:, :, None], 3, axis=2))
    return lp


def export_lp(
    field: ReflectanceField | str | os.PathLike[str],
    camera_index: int,
    lp_path: str | os.PathLike[str],
    image_names: Sequence[str],
) -> LightPositions:
    """Write the ``.lp`` file of one camera pose of a field (the images are not written).

    Parameters
    ----------
    field : ReflectanceField or path of its store
    camera_index : int, the camera s in 0..S-1 whose frame the directions are given in
    lp_path : path of the ``.lp`` file to write
    image_names : sequence of str, length T
        The name of light t's image relative to the ``.lp`` file's folder (the caller writes
        the images).

    Returns
    -------
    LightPositions
        What was written: the field's light directions in camera s's frame (x right, y up, z
        toward the camera). Lights behind the object plane seen from that camera have z <= 0
        and are written as they are.

    Raises
    ------
    InputError
        A camera index out of range, or a number of names other than T.
    """
    opened = field if isinstance(field, ReflectanceField) else ReflectanceField.open(field)
    cameras, lights, _ = opened.shape
    if not 0 <= camera_index < cameras:
        raise InputError(
            f"{lp_path}: camera index {camera_index} outside 0..{cameras - 1} of {opened.path}"
        )
    if len(image_names) != lights:
        raise InputError(
            f"{lp_path}: {len(image_names)} image names for the {lights} lights of {opened.path}"
        )
    directions = rig_to_camera(opened.light_directions, opened.cameras[camera_index])
    return write_lp(lp_path, image_names, directions)


@contextlib.contextmanager
def open_field_or_rti(
    path: str | os.PathLike[str],
    *,
    progress: bool = False,
    transfer: TransferChoice = "auto",
    mask: str | os.PathLike[str] | None = None,
) -> Iterator[ReflectanceField]:
    """Open a field store, or an RTI capture imported into a temporary store for the ``with``.

    Parameters
    ----------
    path : a field store directory, an ``.lp`` file, or a folder holding exactly one ``.lp``
    progress : bool, a progress bar while importing (and the import's ``assumed`` line)
    transfer, mask : passed to :func:`import_rti` (a store is opened as it is: giving either
        for one is refused)

    Raises
    ------
    DatasetError
        A folder that is neither a store nor holds one ``.lp`` file; what
        :meth:`ReflectanceField.open` and :func:`import_rti` refuse.
    InputError
        ``transfer`` other than ``"auto"``, or a ``mask``, given for a field store.
    """
    where = Path(path)
    lp = where
    if where.is_dir() and not (where / "zarr.json").exists():
        found = sorted(where.glob("*.lp"))
        if len(found) != 1:
            raise DatasetError(f"{where}: neither a field store nor a folder with one .lp file")
        lp = found[0]
    if lp.suffix.lower() != ".lp":
        if transfer != "auto" or mask is not None:
            raise InputError(
                f"{where}: a transfer or a mask applies to an RTI capture (.lp) as it is "
                "imported; a field store keeps the ones it was made with"
            )
        yield ReflectanceField.open(where)
        return
    with tempfile.TemporaryDirectory(prefix="rig-rti-") as scratch:
        yield import_rti(
            lp, Path(scratch) / "field.zarr", progress=progress, transfer=transfer, mask=mask
        )
