"""Building a reflectance field store from a capture dataset, image by image.

For every camera pose s and light t of the dataset: decode the image (every exposure of its
bracket), subtract the dark frame of the same camera pose and exposure, merge the bracket
(:mod:`processing.hdr`), project every surface point into that view, sample the image at the
points the view shows (the depth test the simulator uses: :func:`rig.splat.camera_splats` and
:func:`rig.splat.shown_points`), and write the slab (P, 3) to a
:class:`rig.field_store.FieldStoreWriter`. Only one camera's dark frames and one bracket are in
memory at a time; the field itself goes to the store slab by slab.

Radiometry: a field value is linear radiance for a light of unit intensity after dark-frame
subtraction,

    L = (v - v_dark) / (exposure_ms * radiance_scale * intensity)

with v the decoded value (1.0 = saturation, :mod:`processing.decode`), ``radiance_scale`` the
camera's response in decoded units per unit radiance per millisecond (for the simulated camera
``sensitivity / (1000 full_well)`` of its sensor) and ``intensity`` the light's (1 unless a
calibration says otherwise). Geometry: each camera pose gives a :class:`PinholeCamera` from the
measured pose and the rig's camera model (:class:`RigCamera`), or from a calibration; each light
index a direction from its measured pose (or the calibration). See ``docs/processing.md``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from capture.dataset import Dataset, ImageRecord
from processing.decode import DecodedImage, Transfer, decode_image
from processing.hdr import Exposure, merge_exposures
from processing.interpolation import interpolation_weights
from rig.camera_model import PinholeCamera
from rig.directions import angles_deg_from_direction, direction_from_angles_deg, normalize
from rig.errors import DatasetError, InputError
from rig.field_store import FieldStoreWriter
from rig.splat import CameraSplats, camera_splats, shown_points

__all__ = [
    "FieldBuildReport",
    "FieldLayout",
    "PointCloud",
    "RigCamera",
    "build_field",
    "field_layout",
    "read_point_cloud",
    "sample_view",
]

#: Neighbours averaged by the spacing estimate of :meth:`PointCloud.from_arrays`.
SPACING_NEIGHBOURS = 4


@dataclass(frozen=True)
class RigCamera:
    """The rig's camera model without its pose: where it sits and what it images.

    Attributes
    ----------
    distance : float, from the object centre, scene units
    fov_deg : float, horizontal field of view
    width, height : int, image size in pixels
    """

    distance: float
    fov_deg: float
    width: int
    height: int

    def at(self, azimuth_deg: float, inclination_deg: float) -> PinholeCamera:
        """The pinhole camera at a direction; an arm past the zenith is turned into [0, 180]."""
        if not 0.0 <= inclination_deg <= 180.0:
            azimuth, inclination = angles_deg_from_direction(
                direction_from_angles_deg(azimuth_deg, inclination_deg)
            )
            azimuth_deg, inclination_deg = float(azimuth), float(inclination)
        return PinholeCamera(
            azimuth_deg, inclination_deg, self.distance, self.fov_deg, self.width, self.height
        )


@dataclass(frozen=True)
class PointCloud:
    """The object's surface samples.

    Attributes
    ----------
    points, normals : ndarray, shape (P, 3), float32 (normals unit, outward), rig frame
    spacing : float, mean distance between neighbouring points (sizes the splats of the depth
        test; the simulator's is sqrt(area / P))
    """

    points: NDArray[np.float32]
    normals: NDArray[np.float32]
    spacing: float

    @classmethod
    def from_arrays(
        cls, points: ArrayLike, normals: ArrayLike, spacing: float | None = None
    ) -> PointCloud:
        """Check and wrap arrays; ``spacing`` defaults to an estimate from neighbour distances.

        The estimate is the median over points of the mean distance to their 4 nearest
        neighbours: within 2 % of sqrt(area / P) on the uniform samplings of the synthetic
        scenes (Fibonacci sphere, rank-1 lattice torus) from 500 to 20k points. Pass the
        spacing when it is known (the scanner's, or the simulator's).
        """
        p = np.asarray(points, dtype=np.float32)
        n = np.asarray(normals, dtype=np.float32)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2 or n.shape != p.shape:
            raise InputError(
                f"points and normals must both be (P, 3) with P >= 2, got {p.shape}, {n.shape}"
            )
        if not (np.isfinite(p).all() and np.isfinite(n).all()):
            raise InputError("points and normals must be finite")
        n = normalize(n).astype(np.float32)
        if spacing is None:
            from scipy.spatial import cKDTree

            distance, _ = cKDTree(p).query(p, k=min(SPACING_NEIGHBOURS + 1, len(p)))
            spacing = float(np.median(distance[:, 1:].mean(axis=1)))
        if not (np.isfinite(spacing) and spacing > 0):
            raise InputError(f"point spacing must be positive, got {spacing}")
        return cls(p, n, float(spacing))


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


@dataclass(frozen=True)
class FieldBuildReport:
    """What :func:`build_field` did.

    Attributes
    ----------
    path : Path of the store
    shape : (S, T, P)
    images, exposures, dark_frames : int, light images built, exposure files decoded, dark
        frames decoded
    without_dark : int, exposures with no dark frame of their camera and time (not subtracted)
    visible_fraction : float, visible samples over S x P
    saturated_fraction : float, visible samples (x channels) saturated in every exposure (their
        value is a lower bound)
    camera_spread_deg, light_spread_deg : float, see :class:`FieldLayout`
    missing : list of (camera_index, light_index) without an image (plan-skipped pairs, or
        with ``allow_missing`` lost ones), interpolated from the camera's other lights
    seconds : float, wall time
    """

    path: Path
    shape: tuple[int, int, int]
    images: int
    exposures: int
    dark_frames: int
    without_dark: int
    visible_fraction: float
    saturated_fraction: float
    camera_spread_deg: float
    light_spread_deg: float
    missing: list[tuple[int, int]]
    seconds: float


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
_EMPTY = ("cameras", "lights")


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

    Raises
    ------
    DatasetError
        No light images, a pose without the needed angles, a calibration without an index.
    """
    calibration = {k: v for k, v in (calibration or {}).items() if k not in _EMPTY or v}
    light_records = sorted(
        (r for r in dataset.records if r.kind == "light"),
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


def sample_view(
    image: NDArray[np.floating], splats: CameraSplats, index: NDArray[np.intp]
) -> NDArray[np.float32]:
    """Bilinear samples (K, 3) of ``image`` at the projections of the points ``index``.

    Depth-aware: of the four pixels around a point's projection only those whose z-buffer depth
    is within the splat tolerance of the point's own depth (the pixels that show the point's
    surface, not the background or an occluder), renormalised; a point with none of them takes
    the nearest pixel.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
    splats : CameraSplats of the view (from :func:`rig.splat.camera_splats`)
    index : ndarray, shape (K,), int, the points to sample

    Returns
    -------
    ndarray, shape (K, 3), float32
    """
    height, width = image.shape[:2]
    x = splats.cols[index] - 0.5
    y = splats.rows[index] - 0.5
    depth = splats.depth[index]
    j0, i0 = np.floor(x).astype(np.intp), np.floor(y).astype(np.intp)
    fx, fy = x - j0, y - i0
    total = np.zeros((len(index), 3))
    weights = np.zeros(len(index))
    corners = ((0, 0, (1 - fy) * (1 - fx)), (0, 1, (1 - fy) * fx), (1, 0, fy * (1 - fx)))
    for di, dj, w in (*corners, (1, 1, fy * fx)):
        i, j = i0 + di, j0 + dj
        inside = (i >= 0) & (i < height) & (j >= 0) & (j < width)
        ic, jc = np.clip(i, 0, height - 1), np.clip(j, 0, width - 1)
        front = np.abs(splats.buffer[ic, jc] - depth) <= splats.tolerance
        weight = np.where(inside & front, w, 0.0)
        total += weight[:, None] * image[ic, jc]
        weights += weight
    nearest = image[
        np.clip(np.floor(y + 0.5).astype(np.intp), 0, height - 1),
        np.clip(np.floor(x + 0.5).astype(np.intp), 0, width - 1),
    ]
    some = weights > 1e-9
    out = np.where(some[:, None], total / np.where(some, weights, 1.0)[:, None], nearest)
    return out.astype(np.float32)


def _decode(
    record: ImageRecord, dataset: Dataset, shape: tuple[int, int], **options: Any
) -> DecodedImage:
    return decode_image(dataset.image_path(record), expected_shape=shape, **options)


def build_field(
    dataset: Dataset | str | os.PathLike[str],
    output: str | os.PathLike[str],
    cloud: PointCloud,
    *,
    camera: RigCamera | None = None,
    calibration: Mapping[str, Any] | None = None,
    radiance_scale: float = 1.0,
    light_intensity: float = 1.0,
    allow_missing: bool = False,
    dtype: str = "float32",
    demosaic: str = "linear",
    transfer: Transfer | None = None,
    light_model: dict[str, Any] | None = None,
    provenance: Mapping[str, Any] | None = None,
    progress: bool = False,
) -> FieldBuildReport:
    """Build the reflectance field store of a capture dataset, streaming image by image.

    Parameters
    ----------
    dataset : Dataset, or its directory
    output : path of the new field store (a Zarr group; replaced if it exists)
    cloud : PointCloud, the object's surface samples (P points with normals and spacing)
    camera, calibration, light_intensity : see :func:`field_layout`
    radiance_scale : float, > 0
        Decoded value (1.0 = saturation) per unit radiance per millisecond of exposure: the
        camera's radiometric response. For the simulated camera it is its sensor's
        ``sensitivity / (1000 * full_well)``; for a real camera, from a white reference (or 1,
        leaving the field in camera units).
    allow_missing : bool
        Interpolate the slabs of planned images the dataset lacks instead of refusing (slabs
        of pairs the plan skipped are always interpolated from the camera's other lights).
    dtype : {"float32", "float16"}, the store's radiance type
    demosaic, transfer : passed to :func:`processing.decode.decode_image`
    light_model : dict, optional, the store's light model (default directional, unit intensity)
    provenance : mapping, optional, merged into the store's provenance
    progress : bool, show a tqdm progress bar

    Returns
    -------
    FieldBuildReport

    Raises
    ------
    DatasetError
        Missing images (unless ``allow_missing``), an undecodable or wrongly sized file
        (:class:`processing.decode.DecodeError`, naming it), a camera inside the object.
    """
    started = time.perf_counter()
    if not (np.isfinite(radiance_scale) and radiance_scale > 0):
        raise InputError(f"radiance_scale must be positive, got {radiance_scale}")
    data = dataset if isinstance(dataset, Dataset) else Dataset.open(dataset)
    layout = field_layout(
        data, camera=camera, calibration=calibration, light_intensity=light_intensity
    )
    # Pairs the plan skipped (the light where the camera is, a forbidden zone) were never to be
    # taken: their slabs are interpolated from the camera's other lights. Planned images that
    # are missing are an incomplete capture.
    planned = (
        None
        if data.planned is None
        else {(k.camera_index, k.light_index) for k in data.planned if k.kind == "light"}
    )
    unplanned = [pair for pair in layout.missing if planned is not None and pair not in planned]
    lost = [pair for pair in layout.missing if pair not in unplanned]
    if lost and not allow_missing:
        listed = ", ".join(f"camera {c} light {t}" for c, t in lost[:5])
        raise DatasetError(
            f"{data.path}: {len(lost)} planned images missing ({listed}"
            f"{', ...' if len(lost) > 5 else ''}); re-take them (rig capture --resume) or "
            "allow missing"
        )
    radius = float(np.linalg.norm(cloud.points, axis=1).max())
    for pinhole in layout.cameras:
        if pinhole.distance <= radius:
            raise DatasetError(f"camera {pinhole} is inside the object (radius {radius:.3g})")
    store = FieldStoreWriter(
        output,
        points=cloud.points,
        normals=cloud.normals,
        light_directions=layout.light_directions,
        cameras=layout.cameras,
        dtype=dtype,
        light_model=light_model,
        provenance={
            "source": "capture",
            "tool": "processing.field_builder",
            "dataset": str(data.path),
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "camera_indices": list(layout.camera_indices),
            "light_indices": list(layout.light_indices),
            "radiance_scale": radiance_scale,
            "light_intensities": layout.intensities.tolist(),
            "calibrated": sorted(k for k in _EMPTY if (calibration or {}).get(k)),
            "point_spacing": cloud.spacing,
            **dict(provenance or {}),
        },
    )
    options = {"demosaic": demosaic, "transfer": transfer}
    s_count, t_count, p_count = len(layout.cameras), len(layout.light_indices), len(cloud.points)
    counts = {"exposures": 0, "darks": 0, "without_dark": 0, "visible": 0, "saturated": 0}
    bar = tqdm(total=s_count * t_count, desc="process", unit="image", disable=not progress)
    try:
        for s, pinhole in enumerate(layout.cameras):
            shape = (pinhole.height, pinhole.width)
            splats = camera_splats(cloud.points, cloud.normals, pinhole, cloud.spacing)
            visible = shown_points(
                splats.cols, splats.rows, splats.depth, splats.radius, splats.buffer,
                splats.tolerance,
            )  # fmt: skip
            store.write_visibility(s, visible)
            index = np.flatnonzero(visible)
            counts["visible"] += len(index)
            darks: dict[float, DecodedImage] = {}
            taken: dict[int, NDArray[np.float32]] = {}
            for t in range(t_count):
                bracket = layout.brackets.get((s, t))
                if bracket is None:
                    bar.update()
                    continue
                exposures = []
                for record in bracket:
                    key = round(record.exposure_ms, 9)
                    dark_record = layout.darks.get((s, key))
                    if dark_record is not None and key not in darks:
                        darks[key] = _decode(dark_record, data, shape, **options)
                        counts["darks"] += 1
                    counts["without_dark"] += dark_record is None
                    image = _decode(record, data, shape, **options)
                    exposures.append(Exposure(image, record.exposure_ms, darks.get(key)))
                counts["exposures"] += len(exposures)
                merged = merge_exposures(exposures)
                scale = radiance_scale * layout.intensities[t]
                slab = np.zeros((p_count, 3), dtype=np.float32)
                slab[index] = sample_view(merged.rate, splats, index) / scale.astype(np.float32)
                clipped = sample_view(merged.saturated.astype(np.float32), splats, index) > 0
                counts["saturated"] += int(clipped.sum())
                store.write_slab(s, t, slab)
                taken[t] = slab
                bar.update()
            for t in set(range(t_count)) - set(taken):
                store.write_slab(s, t, _interpolated_slab(layout.light_directions, taken, t))
    finally:
        bar.close()
    visible_total = max(counts["visible"], 1)
    return FieldBuildReport(
        path=Path(output),
        shape=(s_count, t_count, p_count),
        images=sum(1 for key in layout.brackets),
        exposures=counts["exposures"],
        dark_frames=counts["darks"],
        without_dark=counts["without_dark"],
        visible_fraction=counts["visible"] / (s_count * p_count),
        saturated_fraction=counts["saturated"] / (visible_total * t_count * 3),
        camera_spread_deg=layout.camera_spread_deg,
        light_spread_deg=layout.light_spread_deg,
        missing=list(layout.missing),
        seconds=time.perf_counter() - started,
    )


def _interpolated_slab(
    directions: NDArray[np.floating], taken: Mapping[int, NDArray[np.float32]], missing: int
) -> NDArray[np.float32]:
    """The slab of light ``missing`` interpolated (barycentric) from the camera's taken ones."""
    if not taken:
        raise DatasetError(f"a camera pose has no light images to interpolate light {missing}")
    have = sorted(taken)
    measured = np.asarray(directions, dtype=np.float64)[have]
    weights = interpolation_weights(
        measured, np.asarray(directions, dtype=np.float64)[missing : missing + 1], "barycentric"
    )
    slab = np.zeros_like(taken[have[0]])
    for j, w in zip(weights.indices[0], weights.weights[0], strict=True):
        slab += np.float32(w) * taken[have[int(j)]]
    return slab


def read_point_cloud(path: str | os.PathLike[str]) -> PointCloud:
    """Read the object's points and normals from ``.npz`` or ``.ply``.

    ``.npz``: arrays ``points`` and ``normals`` (P, 3), optional scalar ``spacing``. ``.ply``:
    the ``vertex`` element (the first) with float properties x, y, z, nx, ny, nz, in ASCII or
    binary little/big-endian encoding; spacing is estimated (:meth:`PointCloud.from_arrays`).

    Raises
    ------
    DatasetError
        Unreadable, truncated or missing the needed arrays or properties; names the file.
    """
    file = Path(path)
    if not file.is_file():
        raise DatasetError(f"{file}: no such point cloud file")
    suffix = file.suffix.lower()
    try:
        if suffix == ".npz":
            with np.load(file) as data:
                spacing = float(data["spacing"]) if "spacing" in data else None
                return PointCloud.from_arrays(data["points"], data["normals"], spacing)
        if suffix == ".ply":
            columns = _read_ply_vertices(file)
            missing = [c for c in ("x", "y", "z", "nx", "ny", "nz") if c not in columns]
            if missing:
                raise DatasetError(f"{file}: PLY vertices lack {', '.join(missing)}")
            points = np.stack([columns[c] for c in "xyz"], axis=1)
            normals = np.stack([columns[c] for c in ("nx", "ny", "nz")], axis=1)
            return PointCloud.from_arrays(points, normals)
    except (KeyError, ValueError, OSError, EOFError) as error:
        raise DatasetError(f"{file}: cannot read the point cloud: {error}") from error
    raise DatasetError(f"{file}: point clouds are read from .npz or .ply, not {suffix!r}")


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def _read_ply_vertices(file: Path) -> dict[str, NDArray[np.float64]]:
    with open(file, "rb") as handle:
        if handle.readline().strip() != b"ply":
            raise DatasetError(f"{file}: not a PLY file")
        encoding, count, names, types, element = "", 0, [], [], ""
        while True:
            line = handle.readline()
            if not line:
                raise DatasetError(f"{file}: PLY header has no end_header")
            words = line.decode("ascii", errors="replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                encoding = words[1]
            elif words[0] == "element":
                if element == "" and words[1] != "vertex":
                    raise DatasetError(f"{file}: the first PLY element must be vertex")
                element = words[1]
                if element == "vertex":
                    count = int(words[2])
            elif words[0] == "property" and element == "vertex":
                if words[1] == "list" or words[1] not in _PLY_TYPES:
                    raise DatasetError(f"{file}: unsupported vertex property {' '.join(words[1:])}")
                types.append(_PLY_TYPES[words[1]])
                names.append(words[2])
        if encoding == "ascii":
            rows = [handle.readline().split()[: len(names)] for _ in range(count)]
            if any(len(row) < len(names) for row in rows):
                raise DatasetError(f"{file}: PLY vertex list is truncated")
            table = np.array(rows, dtype=np.float64).reshape(count, len(names))
            return {name: table[:, k] for k, name in enumerate(names)}
        order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(encoding)
        if order is None:
            raise DatasetError(f"{file}: unknown PLY format {encoding!r}")
        dtype = np.dtype([(name, order + kind) for name, kind in zip(names, types, strict=True)])
        raw = handle.read(dtype.itemsize * count)
        if len(raw) < dtype.itemsize * count:
            raise DatasetError(f"{file}: PLY vertex data is truncated")
        vertices = np.frombuffer(raw, dtype=dtype, count=count)
        return {name: vertices[name].astype(np.float64) for name in names}
