"""RTI ``.lp`` export of a dataset: one light-position file per camera pose.

The format is :mod:`core.lp_format`'s (written by its :func:`~core.lp_format.write_lp`, read back
by :func:`~core.lp_format.read_lp`): ``N`` on the first line, then ``filename x y z`` per image,
the direction from the object toward the light in the CAMERA frame of the image's camera pose
(:func:`core.camera_model.rig_to_camera`: x to the image's right, y to the image's top, z toward
the camera). A turntable angle turns the object, not the camera-light pair, so it does not change
these directions and is ignored.
"""

from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from capture.dataset import Dataset
from capture.manifest import ImageRecord
from core.camera_model import PinholeCamera, rig_to_camera
from core.directions import direction_from_angles_deg
from core.errors import DatasetError, InputError
from core.lp_format import write_lp

__all__ = ["export_lp"]

_POSE_KEYS = (
    "camera_azimuth_deg",
    "camera_inclination_deg",
    "light_azimuth_deg",
    "light_inclination_deg",
)


def _direction(dataset: Dataset, record: ImageRecord, pose: str) -> NDArray[np.float64]:
    angles = record.measured_pose if pose == "measured" else record.commanded_pose
    where = f"{dataset.manifest_path}, {record.key} ({record.file})"
    missing = [key for key in _POSE_KEYS if key not in angles]
    if missing:
        raise DatasetError(f"{where}: the {pose} pose has no {', '.join(missing)}")
    camera_azimuth, camera_inclination, light_azimuth, light_inclination = (
        angles[key] for key in _POSE_KEYS
    )
    try:
        camera = PinholeCamera(azimuth_deg=camera_azimuth, inclination_deg=camera_inclination)
        return rig_to_camera(direction_from_angles_deg(light_azimuth, light_inclination), camera)
    except InputError as error:
        raise DatasetError(f"{where}: {error}") from None


def export_lp(
    dataset: Dataset,
    out_dir: str | os.PathLike[str],
    *,
    pose: Literal["measured", "commanded"] = "measured",
) -> list[Path]:
    """Write an RTI ``.lp`` file per camera pose of a dataset's light images.

    Parameters
    ----------
    dataset : Dataset
    out_dir : folder for the ``.lp`` files (created if needed); the image names in them are
        relative to it
    pose : which pose of each record gives the camera and light directions

    Returns
    -------
    list of Path
        ``camera_<c>.lp`` per camera index c (``camera_<c>_exposure_<e>.lp`` per exposure index
        when the dataset brackets exposures), lines ordered by light index. Dark and calibration
        frames are left out.

    Raises
    ------
    InputError
        An unknown ``pose``, a dataset without light images, or an image path an ``.lp`` file
        cannot hold (:func:`core.lp_format.write_lp`).
    DatasetError
        A record whose pose lacks a camera or light angle, or is out of range.
    """
    if pose not in ("measured", "commanded"):
        raise InputError(f"pose must be 'measured' or 'commanded', got {pose!r}")
    lights = [record for record in dataset.records if record.kind == "light"]
    if not lights:
        raise InputError(f"{dataset.path}: no light images to export")
    groups: dict[tuple[int, int], list[ImageRecord]] = defaultdict(list)
    for record in lights:
        groups[record.camera_index, record.exposure_index].append(record)
    bracketed = len({record.exposure_index for record in lights}) > 1
    dataset.refuse_output_in_images(out_dir)
    folder = Path(out_dir)
    written: list[Path] = []
    for (camera, exposure), records in sorted(groups.items()):
        records.sort(key=lambda record: record.key.order())
        name = f"camera_{camera:03d}" + (f"_exposure_{exposure:02d}" if bracketed else "")
        directions = np.stack([_direction(dataset, record, pose) for record in records])
        images = [
            Path(
                os.path.relpath(dataset.image_path(record).absolute(), folder.absolute())
            ).as_posix()
            for record in records
        ]
        target = folder / f"{name}.lp"
        write_lp(target, images, directions)
        written.append(target)
    return written
