"""The RTI ``.lp`` light-position format: reading, writing, the intensity and mask sidecars.

The one home of the format: :mod:`capture.lp_export` writes a dataset's light poses with
:func:`write_lp`, :mod:`processing.rti` imports captures with :func:`read_lp` (and writes a
field's lights back); both sit above ``core``.

An RTI capture is one fixed camera and T photographs, each lit from one direction, listed in an
``.lp`` file::

    240
    jpg/Loewenkopf_klein_0001.jpg -0.0019356994 -0.14720464 0.98910415
    ...

The first line is the image count N, then N lines ``filename x y z`` (whitespace-separated; the
filename is relative to the ``.lp`` file's folder and may name a subfolder). The directions point
from the object toward the light in the CAMERA frame: x to the image's right, y to the image's
top, z toward the camera (:func:`core.camera_model.rig_to_camera` turns rig-frame directions
into it, :func:`core.camera_model.camera_to_rig` back). Files in the wild carry Windows or
old-Mac line endings, tabs, blank lines and float32-rounded vectors; all are accepted (every
direction is normalised). A count that disagrees with the entries, a missing or non-numeric
value, a zero or non-finite vector is refused with the file and line number.

This project also reads (and :func:`write_lp` writes) a fifth column, ``filename x y z
intensity``: the light's relative intensity (positive, finite), by which the import divides the
image. Every line has four columns or every line has five. A line is read as five columns when
it has five or more fields and the fourth from the end is a number, so an image name whose last
space-separated part is a number (``scan 2``) cannot be used: :func:`write_lp` refuses it, and
:func:`read_lp` reads its line as five columns and refuses the mix with the others.

Light intensities may instead come from a sidecar beside the ``.lp`` file,
``<lp stem>.intensities`` or else ``intensities.txt`` (:data:`INTENSITY_SIDECARS`): UTF-8
text, one line ``filename intensity`` per image, names as in the ``.lp`` file, every image
exactly once in any order; blank lines and lines starting with ``#`` are skipped
(:func:`read_intensity_sidecar`).

A mask may sit beside the ``.lp`` file too, ``<lp stem>.mask.png`` or else ``mask.png``
(:data:`MASK_SIDECARS`): non-zero pixels are the object (:func:`processing.rti.import_rti` reads
it, :func:`sim.rti_capture.write_rti_capture` writes it).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.atomic import atomic_path
from core.errors import DatasetError, InputError

__all__ = [
    "INTENSITY_SIDECARS",
    "MASK_SIDECARS",
    "LightPositions",
    "read_intensity_sidecar",
    "read_lp",
    "write_lp",
]

#: Vectors shorter than this are "zero": they have no direction to normalise to.
_ZERO_LENGTH = 1e-9

#: Intensity sidecars beside an ``.lp`` file, in the order looked for.
INTENSITY_SIDECARS = ("{stem}.intensities", "intensities.txt")

#: Mask sidecars beside an ``.lp`` file, in the order looked for (``{stem}``: the file's stem).
MASK_SIDECARS = ("{stem}.mask.png", "mask.png")


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


def _numbered_lines(file: Path, what: str) -> list[tuple[int, str]]:
    """Each non-blank line of a text file, stripped, with its number as an editor shows it.

    LF, CRLF and CR endings alike; a UTF-8 byte-order mark is dropped.

    Raises
    ------
    DatasetError
        A missing or unreadable file, named as ``what`` (".lp", "intensity").
    """
    try:
        text = file.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DatasetError(f"{file}: no such {what} file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(f"{file}: cannot read as a text {what} file: {error}") from error
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    return [(number, line.strip()) for number, line in enumerate(lines, 1) if line.strip()]


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
    entries = _numbered_lines(file, ".lp")
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
    lines = _numbered_lines(file, "intensity")
    index_of = {name: index for index, name in enumerate(lights.files)}
    values = np.full(len(lights), np.nan)
    seen: dict[str, int] = {}
    for number, line in lines:
        if line.startswith("#"):
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
