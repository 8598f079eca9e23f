"""A capture dataset to a field store, with what the dataset does not say given by the caller.

:func:`process_dataset` is ``rig process``: it finds the camera model (given, from the rig
config snapshot, or the first image's size), takes the manifest's calibration unless told not
to, and builds the field (:func:`processing.field_builder.build_field`). The object's surface
samples and the camera's radiometric scale come from a :class:`FieldSources`: a point-cloud
file (:func:`point_cloud_sources`), or for a simulated capture the simulator's scene and sensor
(``sim.capture_sources``; this package does not import the simulator, the protocol is the seam).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from capture.dataset import Dataset
from capture.verify import VerifyReport
from core.camera_model import RigCamera
from core.errors import DatasetError, InputError
from core.field_store import BELOW_HORIZON
from processing.decode import DEMOSAIC_ALGORITHMS, decode_image
from processing.field_builder import FieldBuildReport, build_field
from processing.point_cloud import PointCloud, read_point_cloud

__all__ = [
    "FieldSources",
    "PointCloudSources",
    "point_cloud_sources",
    "process_dataset",
    "verify_for_processing",
]


class FieldSources(Protocol):
    """What a field needs beyond a dataset's images.

    Attributes
    ----------
    points, normals : ndarray, shape (P, 3), the object's surface samples, rig frame
    spacing : float or None, the points' spacing (None: estimated from the points)
    radiance_scale : float or None, decoded value per unit radiance per millisecond (None: 1,
        the field stays in camera units)
    light_model : dict or None, the store's light model (None: directional, unit intensity)
    provenance : mapping, merged into the store's provenance
    """

    @property
    def points(self) -> NDArray[np.floating]:
        """The object's surface samples, shape (P, 3), rig frame."""
        ...

    @property
    def normals(self) -> NDArray[np.floating]:
        """The surface samples' normals, shape (P, 3), rig frame."""
        ...

    @property
    def spacing(self) -> float | None:
        """The points' spacing (None: estimated from the points)."""
        ...

    @property
    def radiance_scale(self) -> float | None:
        """Decoded value per unit radiance per millisecond (None: 1, camera units)."""
        ...

    @property
    def light_model(self) -> dict[str, Any] | None:
        """The store's light model (None: directional, unit intensity)."""
        ...

    @property
    def provenance(self) -> Mapping[str, Any]:
        """Merged into the store's provenance."""
        ...


@dataclass(frozen=True)
class PointCloudSources:
    """:class:`FieldSources` of a point cloud (a scan of the object) and an optional scale."""

    points: NDArray[np.float32]
    normals: NDArray[np.float32]
    spacing: float | None
    radiance_scale: float | None = None
    light_model: dict[str, Any] | None = None
    provenance: Mapping[str, Any] = field(default_factory=dict)


def point_cloud_sources(
    path: str | os.PathLike[str],
    *,
    spacing: float | None = None,
    radiance_scale: float | None = None,
) -> PointCloudSources:
    """The sources of a real capture: the object's points read from ``.ply`` or ``.npz``."""
    cloud = read_point_cloud(path)
    return PointCloudSources(
        cloud.points,
        cloud.normals,
        cloud.spacing if spacing is None else spacing,
        radiance_scale,
        provenance={"points_file": str(path)},
    )


def dataset_camera_model(
    dataset: Dataset,
    *,
    distance: float | None = None,
    fov_deg: float | None = None,
    size: tuple[int, int] | None = None,
) -> RigCamera | None:
    """The rig's camera model; None when distance or field of view is known nowhere.

    Each value is the one given, else the config snapshot's, else (for the size) the first
    image's.

    Parameters
    ----------
    distance : float, camera distance from the object centre, scene units
    fov_deg : float, horizontal field of view
    size : (width, height) in pixels
    """
    camera: dict[str, Any] = dict(dataset.rig_config.get("camera") or {})
    distance = distance if distance is not None else camera.get("distance")
    fov_deg = fov_deg if fov_deg is not None else camera.get("fov_deg")
    if size is not None:
        width, height = size
    elif camera.get("width") and camera.get("height"):
        width, height = int(camera["width"]), int(camera["height"])
    else:
        first = next((r for r in dataset.records if r.kind == "light"), None)
        if first is None:
            return None
        height, width = decode_image(dataset.image_path(first)).shape
    if distance is None or fov_deg is None:
        return None
    return RigCamera(float(distance), float(fov_deg), width, height)


def _light_model(dataset: Dataset, sources: FieldSources) -> dict[str, Any]:
    """The store's light model: the sources', stating what lies below the horizon.

    The sources' statement wins (a simulated scene knows it floats), else the rig config
    snapshot's, else ``"blocked"`` (an object stands on a base or turntable).
    """
    model = dict(sources.light_model or {"type": "directional", "irradiance": 1.0})
    stated = model.get("below_horizon", dataset.rig_config.get("below_horizon", "blocked"))
    if stated not in BELOW_HORIZON:
        raise DatasetError(
            f"{dataset.path}: the rig config snapshot says below_horizon = {stated!r}; it must "
            f"be one of {', '.join(BELOW_HORIZON)}"
        )
    return model | {"below_horizon": stated}


def process_dataset(
    dataset: Dataset | str | os.PathLike[str],
    output: str | os.PathLike[str],
    sources: FieldSources,
    *,
    camera_distance: float | None = None,
    fov_deg: float | None = None,
    size: tuple[int, int] | None = None,
    ignore_calibration: bool = False,
    light_intensity: float = 1.0,
    allow_missing: bool = False,
    dtype: str = "float32",
    demosaic: str = "linear",
    overwrite: bool = False,
    client: Any = None,
) -> FieldBuildReport:
    """Build the field store of a dataset (``rig process``).

    Parameters
    ----------
    dataset : Dataset, or its directory
    output : path of the new field store
    sources : FieldSources, the object's points and the camera's scale
    camera_distance, fov_deg, size : the camera model where the dataset does not say it (see
        :func:`dataset_camera_model`)
    ignore_calibration : bool, use the measured poses, not the manifest's calibration
    light_intensity, allow_missing, dtype, demosaic, overwrite, client : see
        :func:`processing.field_builder.build_field`

    Raises
    ------
    InputError
        No camera model and no calibrated cameras.
    DatasetError
        The dataset does not verify (``rig verify``): corrupt image files, images its journal
        does not vouch for, and (without ``allow_missing``) missing files or planned images
        not taken. With ``allow_missing`` the missing ones are left out and listed in the
        report (``left_out``), their slabs interpolated; a camera with no image at all is
        absent from the field (``absent_cameras``).
    """
    data = dataset if isinstance(dataset, Dataset) else Dataset.open(dataset)
    data.refuse_output_in_images(output)
    if demosaic not in DEMOSAIC_ALGORITHMS:  # before the verification's minutes
        raise InputError(f"--demosaic {demosaic!r}: use one of {', '.join(DEMOSAIC_ALGORITHMS)}")
    check = verify_for_processing(data, allow_missing=allow_missing)
    calibration = None if ignore_calibration else (data.calibration or None)
    camera = dataset_camera_model(data, distance=camera_distance, fov_deg=fov_deg, size=size)
    if camera is None and not (calibration and "cameras" in calibration):
        raise InputError(
            f"{data.path}: no camera model; give --camera-distance and --fov (and --size), or "
            f"calibrate the cameras"
        )
    cloud = PointCloud.from_arrays(sources.points, sources.normals, sources.spacing)
    report = build_field(
        data,
        output,
        cloud,
        camera=camera,
        calibration=calibration,
        radiance_scale=1.0 if sources.radiance_scale is None else sources.radiance_scale,
        light_intensity=light_intensity,
        allow_missing=allow_missing,
        dtype=dtype,
        demosaic=demosaic,
        light_model=_light_model(data, sources),
        provenance={"tool": "rig process", **sources.provenance},
        overwrite=overwrite,
        exclude={record.key for record in check.missing},
        client=client,
    )
    planned_cameras = {key.camera_index for key in data.planned or () if key.kind == "light"}
    built = set(report.camera_indices)
    return replace(
        report,
        left_out=[r.file for r in check.missing] + [str(k) for k in check.not_taken],
        absent_cameras=sorted(planned_cameras - built),
    )


def verify_for_processing(dataset: Dataset, *, allow_missing: bool) -> VerifyReport:
    """The dataset's verification, refused where a field built from it would be wrong.

    Raises
    ------
    DatasetError
        Naming the first files: corrupt images (a field is never built from them), images the
        journal does not vouch for, and without ``allow_missing`` missing files or planned
        images not taken.
    """
    report = dataset.verify()
    where = dataset.path

    def listed(names: Sequence[str]) -> str:
        return ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")

    if report.corrupt:
        raise DatasetError(
            f"{where}: {len(report.corrupt)} image files are corrupt ("
            f"{listed([f'{b.record.file}: {b.reason}' for b in report.corrupt])}); re-take "
            "them (rig capture --resume) before processing"
        )
    if report.unvouched:
        raise DatasetError(
            f"{where}: the journal does not vouch for {len(report.unvouched)} images; see "
            "rig verify"
        )
    lost = [r.file for r in report.missing] + [str(k) for k in report.not_taken]
    if lost and not allow_missing:
        raise DatasetError(
            f"{where}: {len(lost)} planned images are missing or were not taken "
            f"({listed(lost)}); finish the capture (rig capture --resume), or build a field "
            "without them (--allow-missing: interpolated, and cameras without any image left "
            "out)"
        )
    return report
