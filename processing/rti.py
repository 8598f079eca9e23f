"""Reflectance Transformation Imaging (RTI) captures as single-view fields.

An RTI capture is one fixed camera and T photographs listed in an ``.lp`` file
(:mod:`core.lp_format`: the format, a fifth column of light intensities, the sidecars). A
simulated capture is written by :func:`sim.rti_capture.write_rti_capture`.

Beside the ``.lp`` file (:func:`import_rti` looks for them; the first name found is used):

- a mask, ``<lp stem>.mask.png`` or else ``mask.png`` (:data:`core.lp_format.MASK_SIDECARS`):
  non-zero pixels are the object, the others are not samples (an explicit ``mask`` argument
  wins over both);
- light intensities (:data:`core.lp_format.INTENSITY_SIDECARS`); a fifth column and a
  sidecar together are refused.

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
import sys
import tempfile
from collections.abc import Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera, camera_to_rig, rig_to_camera
from core.errors import DatasetError, InputError
from core.field_store import BELOW_HORIZON, BelowHorizon, FieldStoreWriter, ReflectanceField
from core.image_io import PixelDepth, TransferChoice
from core.light_set import check_measured_lights
from core.lp_format import LightPositions, read_lp, write_lp
from core.progress import progress_bar
from processing.rti_files import (
    _decoded,
    _depth,
    _image_path,
    _intensities,
    _level_table,
    _linear_rti_image,
    _look_up,
    _mask,
    _read_rti_pixels,
    _transfer_record,
)

__all__ = [
    "NOMINAL_DISTANCE",
    "NOMINAL_FOV_DEG",
    "export_lp",
    "import_rti",
    "open_field_or_rti",
    "rti_camera",
]

#: Nominal camera distance (scene units) of an imported RTI view: the data do not record it.
NOMINAL_DISTANCE = 10.0
#: Nominal horizontal field of view (degrees) of an imported RTI view: the data do not record it.
NOMINAL_FOV_DEG = 10.0


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


def import_rti(
    lp_path: str | os.PathLike[str],
    output_store: str | os.PathLike[str],
    *,
    dtype: str = "auto",
    overwrite: bool = True,
    transfer: TransferChoice = "auto",
    mask: str | os.PathLike[str] | None = None,
    below_horizon: BelowHorizon = "blocked",
    print_assumed: bool = False,
) -> ReflectanceField:
    """Import an RTI capture (an ``.lp`` file and its images) as a single-view pixel field.

    Parameters
    ----------
    lp_path : path to the ``.lp`` file; image names are relative to its folder
    output_store : path of the field store to create
    overwrite : bool, replace an existing field store there (and the fit saved beside it)
    dtype : {"auto", "float32", "float16"}
        Storage dtype of the radiance. ``"auto"``: float16 for 8-bit images (each of the 256
        levels keeps a distinct float16, within 0.05 % of its linear value, and reads back to
        the same level: nothing is lost, and the store and every read of it are half the
        float32 size), float32 for 16-bit and float images and for images divided by light
        intensities.
    print_assumed : bool
        Print what the import assumed (the ``assumed`` line below) to stderr first. The images
        read are counted with a bar (:mod:`core.progress`), shown by the caller's hook.
    transfer : {"auto", "srgb", "linear"}
        How the images' integer values encode light. ``"auto"``: 8-bit images (JPEG, PNG, TGA,
        BMP...) are sRGB, 16-bit (PNG, TIFF) linear; float images (EXR, HDR, PFM, float TIFF)
        are linear whatever is asked.
    mask : path of a mask image, or None
        Non-zero pixels are the object: the others are not samples (visibility False). None
        looks for a sidecar beside the ``.lp`` file (:data:`core.lp_format.MASK_SIDECARS`:
        ``<stem>.mask.png``, then ``mask.png``); without one, every pixel counts.
    below_horizon : {"blocked", "open"}
        What lies below the horizon of the object's base (:data:`core.field_store.BELOW_HORIZON`):
        an RTI object lies on a table or stands on a base, so the default is ``"blocked"`` and
        environment relighting drops the light from below.

    Returns
    -------
    ReflectanceField
        The new store, opened: S = 1 camera (:func:`rti_camera` with the images' size), T = N
        lights (unit directions in the rig frame, (T, 3)), P = H W pixels in row-major order;
        radiance (1, T, P, 3) is each image, linear (grey repeated to RGB), divided by its
        light's intensity when the ``.lp`` file's fifth column or a sidecar
        (:data:`core.lp_format.INTENSITY_SIDECARS`) gives intensities, in the images' relative
        units (RTI intensities are not calibrated); visibility (1, P) is the mask (all True
        without one).
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
        selects no pixel; lights nothing can use (:func:`core.light_set.check_measured_lights`:
        all in one direction, none above a blocking horizon).
    InputError
        A bad ``dtype`` or ``transfer``, or an output path that exists and is not a field store
        (or is one, without ``overwrite``).

    Notes
    -----
    The store is written beside ``output_store`` under a temporary name and renamed into place
    once complete: a failed or interrupted import leaves no half-filled store behind.

    The images stream: each is decoded once (the next ones on a thread meanwhile, at most
    :data:`~processing.rti_files.DECODE_AHEAD` ahead), converted through a table of its levels
    and written as its slab, so the import holds a few images whatever the capture's length
    (measured at 24 megapixels x 60 lights: ``docs/scale.md``). The files are read by
    :mod:`processing.rti_files`.
    """
    lp_file = Path(lp_path)
    target = Path(output_store)
    if dtype not in ("auto", "float16", "float32"):
        raise InputError(f"field dtype must be auto, float16 or float32, got {dtype!r}")
    if transfer not in ("auto", "srgb", "linear"):
        raise InputError(f"transfer must be 'auto', 'srgb' or 'linear', got {transfer!r}")
    if below_horizon not in BELOW_HORIZON:
        raise InputError(
            f"below the horizon must be one of {', '.join(BELOW_HORIZON)}, got {below_horizon!r}"
        )
    lights = read_lp(lp_file)
    # Refused before any image is read: degenerate lights would be imported, then fitted.
    # The camera straight above the object: a light's camera z is its rig z (its elevation).
    check_measured_lights(lp_file, lights.directions, blocked_below=below_horizon == "blocked")
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
    stored = _store_dtype(dtype, depth, intensities)
    table = _level_table(applied, depth, np.float32 if intensities is not None else stored)
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
            "below the horizon: blocked by the base (environment light from below is dropped)"
            if below_horizon == "blocked"
            else "below the horizon: open (the object is lit from below too)",
            f"stored as {stored}"
            + (
                " (8-bit levels: float16 keeps each one distinct, nothing is lost)"
                if dtype == "auto" and stored == "float16"
                else ""
            ),
        ]
    )
    if print_assumed:
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
        dtype=stored,
        light_model={
            "type": "directional",
            "irradiance": 1.0,
            "below_horizon": below_horizon,
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
        steps = progress_bar(total=len(paths), desc="rti", unit="image")
        buffer: NDArray[np.floating] | None = None
        for index, pixels in enumerate(_decoded(paths, first, lp_file, lights)):
            where = f"{lp_file}, line {lights.line(index)}"
            path, name = paths[index], lights.files[index]
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
            if table is not None:
                # One look-up a value: the curve's powers cost seconds a 24-megapixel image;
                # into one buffer, as fresh pages for every image cost the kernel's time too.
                if buffer is None or buffer.shape != pixels.shape:
                    buffer = np.empty(pixels.shape, dtype=table.dtype)
                image = _look_up(table, pixels, buffer)
            else:
                image = _linear_rti_image(pixels, applied, path, where)
            del pixels
            if intensities is not None:
                # Radiance per unit irradiance: the lights' differences leave the data.
                image = image / np.float32(intensities[index])
            writer.write_slab(0, index, image.reshape(-1, 3))
            del image
            steps.update()
        steps.close()
        writer.write_visibility(0, visible)
    except BaseException:
        writer.abort()
        raise
    writer.finish()
    return ReflectanceField.open(target)


def _store_dtype(
    dtype: str, depth: PixelDepth, intensities: NDArray[np.float64] | None
) -> Literal["float16", "float32"]:
    """The radiance dtype of the store: as asked, or ``"auto"``'s choice (see import_rti)."""
    if dtype == "float16":
        return "float16"
    if dtype == "float32":
        return "float32"
    # Every 8-bit level's linear value keeps a float16 of its own (within 0.05 % of it) and
    # reads back to the same level: half the store and its reading, nothing of the data lost.
    # Divided by intensities, the values are no longer the 256 levels: they stay float32.
    return "float16" if depth == "8-bit" and intensities is None else "float32"


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
    transfer: TransferChoice = "auto",
    mask: str | os.PathLike[str] | None = None,
    below_horizon: BelowHorizon | None = None,
    print_assumed: bool = False,
) -> Iterator[ReflectanceField]:
    """Open a field store, or an RTI capture imported into a temporary store for the ``with``.

    Parameters
    ----------
    path : a field store directory, an ``.lp`` file, or a folder holding exactly one ``.lp``
    transfer, mask : passed to :func:`import_rti` (a store is opened as it is: giving either
        for one is refused)
    print_assumed : bool, passed to :func:`import_rti` (a store assumes nothing)
    below_horizon : {"blocked", "open"} or None
        What lies below the horizon (:data:`core.field_store.BELOW_HORIZON`): for a capture,
        passed to :func:`import_rti` (None: its default, ``"blocked"``); for a store, it
        replaces the store's statement for this opening (None: the store's own)

    Raises
    ------
    DatasetError
        A folder that is neither a store nor holds one ``.lp`` file; what
        :meth:`ReflectanceField.open` and :func:`import_rti` refuse; a store whose lights no
        fit or relighting can use (:func:`core.light_set.check_measured_lights`).
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
        opened = ReflectanceField.open(where)
        if below_horizon is not None:
            opened = opened.stating(below_horizon=below_horizon)
        check_measured_lights(
            where, opened.light_directions, blocked_below=opened.below_horizon == "blocked"
        )
        yield opened
        return
    with tempfile.TemporaryDirectory(prefix="rig-rti-") as scratch:
        yield import_rti(
            lp, Path(scratch) / "field.zarr", transfer=transfer, mask=mask,
            below_horizon=below_horizon or "blocked",
            print_assumed=print_assumed,
        )  # fmt: skip
