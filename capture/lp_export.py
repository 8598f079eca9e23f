"""RTI ``.lp`` export of a dataset: one light-position file per camera pose.

An ``.lp`` file is ``N`` on the first line, then ``filename x y z`` per image, the direction from
the object toward the light in the CAMERA frame: x to the image's right, y to the image's top, z
toward the camera (the frame of ``processing.rti``, which reads these files back). The camera frame
is :meth:`core.camera_model.PinholeCamera.axes` of the image's camera pose. A turntable angle turns
the object, not the camera-light pair, so it does not change these directions and is ignored.
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
from core.atomic import atomic_path
from core.camera_model import PinholeCamera
from core.directions import direction_from_angles_deg
from core.errors import DatasetError, InputError

__all__ = ["export_lp", "light_in_camera_frame"]

_POSE_KEYS = (
    "camera_azimuth_deg",
    "camera_inclination_deg",
    "light_azimuth_deg",
    "light_inclination_deg",
)


def light_in_camera_frame(
    camera_azimuth_deg: float,
    camera_inclination_deg: float,
    light_azimuth_deg: float,
    light_inclination_deg: float,
) -> NDArray[np.float64]:
    """The unit direction toward a light in a camera's frame (x right, y up, z toward camera).

    Parameters
    ----------
    camera_azimuth_deg, camera_inclination_deg : float, direction from the object to the camera
    light_azimuth_deg, light_inclination_deg : float, direction from the object to the light

    Returns
    -------
    ndarray, shape (3,), float64
    """
    camera = PinholeCamera(azimuth_deg=camera_azimuth_deg, inclination_deg=camera_inclination_deg)
    right, up, forward = camera.axes()
    # The camera looks along forward, so "toward the camera" is -forward.
    frame = np.stack([right, up, -forward])
    return frame @ direction_from_angles_deg(light_azimuth_deg, light_inclination_deg)


def _direction(dataset: Dataset, record: ImageRecord, pose: str) -> NDArray[np.float64]:
    angles = record.measured_pose if pose == "measured" else record.commanded_pose
    where = f"{dataset.manifest_path}, {record.key} ({record.file})"
    missing = [key for key in _POSE_KEYS if key not in angles]
    if missing:
        raise DatasetError(f"{where}: the {pose} pose has no {', '.join(missing)}")
    try:
        return light_in_camera_frame(*(angles[key] for key in _POSE_KEYS))
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
        An unknown ``pose``, or a dataset without light images.
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
    folder = Path(out_dir)
    written: list[Path] = []
    for (camera, exposure), records in sorted(groups.items()):
        records.sort(key=lambda record: record.key.order())
        name = f"camera_{camera:03d}" + (f"_exposure_{exposure:02d}" if bracketed else "")
        lines = [f"{len(records)}"]
        for record in records:
            x, y, z = _direction(dataset, record, pose)
            image = Path(os.path.relpath(dataset.image_path(record).absolute(), folder.absolute()))
            lines.append(f"{image.as_posix()} {float(x)!r} {float(y)!r} {float(z)!r}")
        target = folder / f"{name}.lp"
        with atomic_path(target) as temporary:
            temporary.write_text("\n".join(lines) + "\n", encoding="utf-8")
        written.append(target)
    return written
