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

Imported, an RTI capture becomes a field of pixels (``core.field_store``, samples of kind
``"pixels"``) with one camera straight above the object (azimuth 0, inclination 0): the object
plane is the rig's xy-plane and a light's camera z is its rig z (the cosine of its inclination).
That camera's image right is rig ``+y`` and its image up is rig ``-x`` (the limit of
:meth:`core.camera_model.PinholeCamera.axes` approached from azimuth 0). An RTI file does not
record the camera's distance or field of view; nominal values are stored and marked as such.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from core.atomic import atomic_path
from core.camera_model import PinholeCamera, camera_to_rig, rig_to_camera
from core.errors import DatasetError, InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.image_io import ImageFileError, read_linear

__all__ = [
    "NOMINAL_DISTANCE",
    "NOMINAL_FOV_DEG",
    "LightPositions",
    "export_lp",
    "import_rti",
    "open_field_or_rti",
    "read_lp",
    "rti_camera",
    "write_lp",
]

#: Nominal camera distance (scene units) of an imported RTI view: the data do not record it.
NOMINAL_DISTANCE = 10.0
#: Nominal horizontal field of view (degrees) of an imported RTI view: the data do not record it.
NOMINAL_FOV_DEG = 10.0

#: Vectors shorter than this are "zero": they have no direction to normalise to.
_ZERO_LENGTH = 1e-9


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
    """

    files: list[str]
    directions: NDArray[np.float64]
    lines: tuple[int, ...] = ()
    source: Path | None = None

    def __post_init__(self) -> None:
        count = len(self.files)
        if np.shape(self.directions) != (count, 3):
            raise InputError(
                f"light directions must have shape ({count}, 3) for {count} files, "
                f"got {np.shape(self.directions)}"
            )
        if self.lines and len(self.lines) != count:
            raise InputError(f"{len(self.lines)} line numbers for {count} files")

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


def read_lp(path: str | os.PathLike[str]) -> LightPositions:
    """Read an RTI ``.lp`` file.

    Parameters
    ----------
    path : path to the ``.lp`` file (UTF-8, with or without a byte-order mark; any line endings)

    Returns
    -------
    LightPositions
        N file names as written and N unit directions (N, 3) in the camera frame; every vector
        is normalised, whatever its length.

    Raises
    ------
    DatasetError
        Missing or unreadable file, empty file, a first line that is not a positive count, more
        or fewer entries than the count, a line that is not ``filename x y z``, a non-numeric,
        non-finite or zero-length direction. The message names the file and the line.
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
    for index, (number, line) in enumerate(rows):
        where = f"{file}, line {number}"
        fields = line.rsplit(None, 3)  # the filename keeps any inner spaces
        if len(fields) != 4:
            raise DatasetError(f"{where}: expected 'filename x y z', got {line!r}")
        files.append(fields[0])
        directions[index] = _parse_direction(fields[1:], where)
    return LightPositions(
        files=files,
        directions=directions,
        lines=tuple(number for number, _ in rows),
        source=file,
    )


def write_lp(
    path: str | os.PathLike[str], files: Sequence[str], directions: ArrayLike
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

    Returns
    -------
    LightPositions
        What was written (unit directions), with the line numbers of the file.

    Notes
    -----
    Format: ``N\n`` then ``name x y z\n`` per image; the numbers are written with the shortest
    representation that reads back to the same float64 (``repr``).

    Raises
    ------
    InputError
        No files, a count or shape mismatch, a bad name, or a zero-length or non-finite direction;
        the message names the file and the line the entry would occupy.
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
        unit[index] = vector / length
    body = "".join(
        f"{name} {float(x)!r} {float(y)!r} {float(z)!r}\n"
        for name, (x, y, z) in zip(names, unit, strict=True)
    )
    with atomic_path(file) as temporary:
        temporary.write_text(f"{len(names)}\n{body}", encoding="utf-8")
    return LightPositions(
        files=names,
        directions=unit,
        lines=tuple(range(2, len(names) + 2)),
        source=file,
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


def _read_rti_image(path: Path, where: str) -> NDArray[np.float32]:
    """Linear float32 RGB (H, W, 3) of one RTI photograph; grey is repeated, alpha dropped."""
    try:
        image = read_linear(path)
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3 or image.shape[2] not in (1, 3, 4):
        raise DatasetError(f"{where}: {path}: expected a grey or RGB image, got {image.shape}")
    if image.shape[2] == 1:
        image = np.repeat(image, 3, axis=2)
    image = np.ascontiguousarray(image[:, :, :3], dtype=np.float32)
    if not np.all(np.isfinite(image)):
        raise DatasetError(f"{where}: {path}: NaN or infinite pixel values")
    return image


def import_rti(
    lp_path: str | os.PathLike[str],
    output_store: str | os.PathLike[str],
    *,
    dtype: str = "float32",
    progress: bool = True,
    overwrite: bool = True,
) -> ReflectanceField:
    """Import an RTI capture (an ``.lp`` file and its images) as a single-view pixel field.

    Parameters
    ----------
    lp_path : path to the ``.lp`` file; image names are relative to its folder
    output_store : path of the field store to create
    overwrite : bool, replace an existing field store there (and the fit saved beside it)
    dtype : {"float32", "float16"}, storage dtype of the radiance
    progress : bool, show a progress bar (one step per image)

    Returns
    -------
    ReflectanceField
        The new store, opened: S = 1 camera (:func:`rti_camera` with the images' size), T = N
        lights (unit directions in the rig frame, (T, 3)), P = H W pixels in row-major order;
        radiance (1, T, P, 3) is each image, linear (sRGB-decoded for JPEG/PNG, grey repeated
        to RGB), in the images' relative units (RTI intensities are not calibrated); every pixel
        is visible.

    Raises
    ------
    DatasetError
        A bad ``.lp`` file (see :func:`read_lp`), a missing, unreadable or non-finite image, or
        images of different sizes; the message names the image and its ``.lp`` line.
    InputError
        A bad ``dtype``, or an output path that exists and is not a field store (or is one,
        without ``overwrite``).

    Notes
    -----
    The store is written beside ``output_store`` under a temporary name and renamed into place
    once complete: a failed or interrupted import leaves no half-filled store behind.
    """
    lp_file = Path(lp_path)
    target = Path(output_store)
    if dtype not in ("float16", "float32"):
        raise InputError(f"field dtype must be float16 or float32, got {dtype!r}")
    lights = read_lp(lp_file)
    folder = lp_file.parent
    paths = [_image_path(folder, name) for name in lights.files]
    for index, path in enumerate(paths):
        if not path.is_file():
            raise DatasetError(
                f"{lp_file}, line {lights.line(index)}: image {lights.files[index]!r} not found "
                f"({path})"
            )
    first = _read_rti_image(paths[0], f"{lp_file}, line {lights.line(0)}")
    height, width = first.shape[:2]
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
            "note": "RTI: intensities not calibrated",
        },
        provenance={
            "source": "rti",
            "tool": "processing.rti.import_rti",
            "lp": str(lp_file.resolve()),
            "images": len(lights),
            "first_image": lights.files[0],
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
            image = first if index == 0 else _read_rti_image(path, where)
            if image.shape[:2] != (height, width):
                raise DatasetError(
                    f"{where}: image {lights.files[index]!r} is {image.shape[1]}x"
                    f"{image.shape[0]} pixels, the first ({lights.files[0]!r}) is "
                    f"{width}x{height}"
                )
            writer.write_slab(0, index, image.reshape(-1, 3))
        steps.close()
        writer.write_visibility(0, np.ones(height * width, dtype=bool))
    except BaseException:
        writer.abort()
        raise
    writer.finish()
    return ReflectanceField.open(target)


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
    path: str | os.PathLike[str], *, progress: bool = False
) -> Iterator[ReflectanceField]:
    """Open a field store, or an RTI capture imported into a temporary store for the ``with``.

    Parameters
    ----------
    path : a field store directory, an ``.lp`` file, or a folder holding exactly one ``.lp``
    progress : bool, a progress bar while importing

    Raises
    ------
    DatasetError
        A folder that is neither a store nor holds one ``.lp`` file; what
        :meth:`ReflectanceField.open` and :func:`import_rti` refuse.
    """
    where = Path(path)
    lp = where
    if where.is_dir() and not (where / "zarr.json").exists():
        found = sorted(where.glob("*.lp"))
        if len(found) != 1:
            raise DatasetError(f"{where}: neither a field store nor a folder with one .lp file")
        lp = found[0]
    if lp.suffix.lower() != ".lp":
        yield ReflectanceField.open(where)
        return
    with tempfile.TemporaryDirectory(prefix="rig-rti-") as scratch:
        yield import_rti(lp, Path(scratch) / "field.zarr", progress=progress)
