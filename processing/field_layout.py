"""What a capture dataset's field will hold, before any image is decoded.

The cameras (posed from the measured poses and the rig's camera model, or from a calibration),
the light directions and intensities, the exposure brackets and dark frames of each (camera,
light) pair, and the pairs without an image. :func:`processing.field_builder.build_field` then
decodes the images in this order.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from capture.dataset import Dataset
from capture.journal import ImageKey
from capture.manifest import ImageRecord
from core.camera_model import PinholeCamera, RigCamera
from core.directions import angles_deg_from_direction, direction_from_angles_deg, normalize
from core.errors import DatasetError, InputError

__all__ = ["CALIBRATION_KINDS", "FieldLayout", "field_layout"]


@dataclass(frozen=True)
class FieldLayout:
    """What a dataset's field will hold, before any image is decoded.

    Attributes
    ----------
    camera_indices, light_indices : tuple of int, the dataset indices of field rows s and t
    cameras : list of PinholeCamera, length S
    light_directions : ndarray, shape (T, 3), float64, unit, toward each light
    intensities : ndarray, shape (T, 3), float64, each light's intensity per channel
    brackets : dict of (s, t) to the light records of that image, by exposure index
    darks : dict of (s, exposure_ms) to the dark record
    camera_spread_deg, light_spread_deg : float, largest angle between one pose's measured
        direction in any record and the one used (encoder jitter, or a light moved between
        cameras)
    missing : list of (camera_index, light_index) with no image
    """

    camera_indices: tuple[int, ...]
    light_indices: tuple[int, ...]
    cameras: list[PinholeCamera]
    light_directions: NDArray[np.float64]
    intensities: NDArray[np.float64]
    brackets: dict[tuple[int, int], list[ImageRecord]]
    darks: dict[tuple[int, float], ImageRecord]
    camera_spread_deg: float
    light_spread_deg: float
    missing: list[tuple[int, int]] = field(default_factory=list)


def _pose_angle(record: ImageRecord, key: str) -> float:
    try:
        return float(record.measured_pose[key])
    except KeyError:
        raise DatasetError(f"{record.file}: the measured pose has no {key}") from None


def _record_camera_direction(record: ImageRecord) -> NDArray[np.float64]:
    """Unit vector toward the camera in the object's frame (the turntable turns the object)."""
    turn = record.measured_pose.get("turntable_deg", 0.0)
    return direction_from_angles_deg(
        _pose_angle(record, "camera_azimuth_deg") - turn,
        _pose_angle(record, "camera_inclination_deg"),
    )


def _record_light_direction(record: ImageRecord) -> NDArray[np.float64]:
    turn = record.measured_pose.get("turntable_deg", 0.0)
    return direction_from_angles_deg(
        _pose_angle(record, "light_azimuth_deg") - turn,
        _pose_angle(record, "light_inclination_deg"),
    )


def _spread_deg(directions: Sequence[NDArray[np.float64]], centre: NDArray[np.float64]) -> float:
    cosines = np.clip(np.asarray(directions) @ centre, -1.0, 1.0)
    return float(np.rad2deg(np.arccos(cosines.min())))


#: Calibration keys whose empty value means "not calibrated".
CALIBRATION_KINDS = ("cameras", "lights")


def _calibration_entry(calibration: Mapping[str, Any], kind: str, index: int) -> Any:
    entries = calibration.get(kind)
    try:
        return entries[index]  # type: ignore[index]
    except (IndexError, KeyError, TypeError):
        raise DatasetError(f"calibration[{kind!r}] has no entry for index {index}") from None


def _calibrated_camera(
    entry: Any, camera: RigCamera | None, index: int, intrinsics: Any = None
) -> PinholeCamera:
    """The pinhole camera of a calibration entry.

    Entries of :meth:`processing.calibration.Calibration.to_dict` (``position``, ``axes`` and the
    derived angles and distance) take the field of view and size from the calibration's
    ``intrinsics`` (horizontal focal length), else from ``camera``; the pinhole looks at the
    origin, so roll and an off-centre aim are not kept.
    """
    try:
        if "azimuth_deg" not in entry and "position" in entry:
            position = np.asarray(entry["position"], dtype=np.float64).reshape(3)
            azimuth, inclination = angles_deg_from_direction(position)
            entry = {
                **entry,
                "azimuth_deg": float(azimuth),
                "inclination_deg": float(inclination),
                "distance": float(np.linalg.norm(position)),
            }
        fov = camera.fov_deg if camera else float("nan")
        width, height = (camera.width, camera.height) if camera else (0, 0)
        if isinstance(intrinsics, Mapping):
            width, height = int(intrinsics["width"]), int(intrinsics["height"])
            fov = float(np.rad2deg(2.0 * np.arctan(0.5 * width / float(intrinsics["fx"]))))
        return PinholeCamera(
            float(entry["azimuth_deg"]),
            float(entry["inclination_deg"]),
            float(entry.get("distance", camera.distance if camera else float("nan"))),
            float(entry.get("fov_deg", fov)),
            int(entry.get("width", width)),
            int(entry.get("height", height)),
        )
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise DatasetError(f"calibration camera {index}: {error!r}") from None


def field_layout(
    dataset: Dataset,
    *,
    camera: RigCamera | None = None,
    calibration: Mapping[str, Any] | None = None,
    light_intensity: float = 1.0,
    exclude: Collection[ImageKey] = (),
) -> FieldLayout:
    """Cameras, lights and images of the field a dataset gives (nothing is decoded).

    Parameters
    ----------
    dataset : the capture
    camera : RigCamera, the rig's camera model; posed by each camera index's measured pose
        (its first light image's, in light and exposure order). Needed unless ``calibration``
        has every camera.
    calibration : mapping, optional
        ``calibration["cameras"][i]``: {azimuth_deg, inclination_deg, distance, fov_deg[,
        width, height]} for camera index i, or the entries of
        :meth:`processing.calibration.Calibration.to_dict` (``position``, ``axes``, with the
        field of view from its ``intrinsics``); ``calibration["lights"][t]``: {direction: [x,
        y, z][, intensity: float or [r, g, b] or null]} for light index t. Either key may be
        absent or empty (not calibrated).
    light_intensity : float, the intensity of every light not calibrated
    exclude : image keys to leave out (files missing or corrupt): their pairs count as missing

    Raises
    ------
    DatasetError
        No light images, a pose without the needed angles, a calibration without an index.
    """
    calibration = {k: v for k, v in (calibration or {}).items() if k not in CALIBRATION_KINDS or v}
    light_records = sorted(
        (r for r in dataset.records if r.kind == "light" and r.key not in exclude),
        key=lambda r: (r.camera_index, r.light_index, r.exposure_index),
    )
    if not light_records:
        raise DatasetError(f"{dataset.path}: the dataset has no light images")
    camera_indices = tuple(sorted({r.camera_index for r in light_records}))
    light_indices = tuple(sorted({int(r.light_index or 0) for r in light_records}))
    s_of = {c: s for s, c in enumerate(camera_indices)}
    t_of = {t_index: t for t, t_index in enumerate(light_indices)}
    brackets: dict[tuple[int, int], list[ImageRecord]] = {}
    for record in light_records:
        brackets.setdefault((s_of[record.camera_index], t_of[int(record.light_index or 0)]), [])
        brackets[s_of[record.camera_index], t_of[int(record.light_index or 0)]].append(record)
    darks = {
        (s_of[r.camera_index], round(r.exposure_ms, 9)): r
        for r in dataset.records
        if r.kind == "dark" and r.camera_index in s_of
    }
    missing = [
        (c, t_index)
        for c in camera_indices
        for t_index in light_indices
        if (s_of[c], t_of[t_index]) not in brackets
    ]

    cameras, camera_spread = [], 0.0
    for s, c in enumerate(camera_indices):
        records = [r for r in light_records if r.camera_index == c]
        if "cameras" in calibration:
            entry = _calibration_entry(calibration, "cameras", c)
            cameras.append(_calibrated_camera(entry, camera, c, calibration.get("intrinsics")))
            continue
        if camera is None:
            raise InputError("a camera model (RigCamera) or calibrated cameras are needed")
        first = records[0]
        turn = first.measured_pose.get("turntable_deg", 0.0)
        cameras.append(
            camera.at(
                _pose_angle(first, "camera_azimuth_deg") - turn,
                _pose_angle(first, "camera_inclination_deg"),
            )
        )
        camera_spread = max(
            camera_spread,
            _spread_deg([_record_camera_direction(r) for r in records], cameras[s].direction),
        )

    directions, intensities, light_spread = [], [], 0.0
    for t_index in light_indices:
        entry = (
            _calibration_entry(calibration, "lights", t_index) if "lights" in calibration else {}
        )
        if not isinstance(entry, Mapping):
            raise DatasetError(f"calibration light {t_index} must be a mapping, got {entry!r}")
        intensity = entry.get("intensity")
        intensity = light_intensity if intensity is None else intensity
        intensities.append(np.broadcast_to(np.asarray(intensity, dtype=np.float64), (3,)))
        if "direction" in entry:
            directions.append(normalize(np.asarray(entry["direction"], dtype=np.float64)))
            continue
        seen = [_record_light_direction(r) for r in light_records if r.light_index == t_index]
        mean = normalize(np.mean(seen, axis=0))
        directions.append(mean)
        light_spread = max(light_spread, _spread_deg(seen, mean))
    intensity_array = np.array(intensities, dtype=np.float64)
    if not (np.isfinite(intensity_array).all() and (intensity_array > 0).all()):
        raise DatasetError(f"light intensities must be positive, got {intensity_array.tolist()}")
    return FieldLayout(
        camera_indices=camera_indices,
        light_indices=light_indices,
        cameras=cameras,
        light_directions=np.array(directions, dtype=np.float64),
        intensities=intensity_array,
        brackets=brackets,
        darks=darks,
        camera_spread_deg=camera_spread,
        light_spread_deg=light_spread,
        missing=missing,
    )
