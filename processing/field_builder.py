"""Building a reflectance field store from a capture dataset, image by image.

For every camera pose s and light t of the dataset: decode the image (every exposure of its
bracket), subtract the dark frame of the same camera pose and exposure, merge the bracket
(:mod:`processing.hdr`), project every surface point into that view, sample the image at the
points the view shows (the depth test the simulator uses: :func:`core.splat.camera_splats` and
:func:`core.splat.shown_points`), and write the slab (P, 3) to a
:class:`core.field_store.FieldStoreWriter`. Only one camera's dark frames and one bracket are in
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
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from capture.dataset import Dataset
from capture.journal import ImageKey
from core.camera_model import PinholeCamera, RigCamera
from core.errors import DatasetError, InputError
from core.field_store import FieldStoreWriter, SlabWriter
from core.image_io import Transfer
from core.progress import progress_bar
from core.splat import CameraSplats, camera_splats, shown_points
from processing.decode import DecodedImage, decode_image
from processing.field_layout import CALIBRATION_KINDS, FieldLayout, field_layout
from processing.hdr import Exposure, merge_exposures
from processing.interpolation import interpolation_weights
from processing.point_cloud import PointCloud

__all__ = ["CameraJob", "CameraResult", "FieldBuildReport", "build_field", "sample_view"]


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
    camera_indices : the dataset's camera indices of the field's cameras, in order
    left_out : files (or planned images) missing or not taken, left out (``allow_missing``)
    absent_cameras : planned camera indices with no image at all: not in the field
    removed_partials : partial stores of the output left by builds that were killed (their
        process gone), removed before this one began
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
    camera_indices: tuple[int, ...] = ()
    left_out: list[str] = field(default_factory=list)
    absent_cameras: list[int] = field(default_factory=list)
    removed_partials: list[Path] = field(default_factory=list)


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
    splats : CameraSplats of the view (from :func:`core.splat.camera_splats`)
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
    overwrite: bool = False,
    exclude: Collection[ImageKey] = (),
    client: Any = None,
) -> FieldBuildReport:
    """Build the reflectance field store of a capture dataset, streaming image by image.

    Parameters
    ----------
    dataset : Dataset, or its directory
    output : path of the new field store (a Zarr group; see ``overwrite``)
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
    overwrite : bool, replace a store already at ``output`` (and the fit saved beside it)
    exclude : image keys to leave out, as if never taken (files found missing or corrupt)
    client : distributed.Client, optional
        Build each camera pose as a Dask task on its cluster (the workers read the images and
        write their slabs into the store under construction); the store is the same.

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
        data,
        camera=camera,
        calibration=calibration,
        light_intensity=light_intensity,
        exclude=exclude,
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
        overwrite=overwrite,
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
            "calibrated": sorted(k for k in CALIBRATION_KINDS if (calibration or {}).get(k)),
            "point_spacing": cloud.spacing,
            **dict(provenance or {}),
        },
    )
    # From here on the partial store exists: whatever stops the build (an error, Ctrl-C, or
    # SIGTERM, which rig raises as Ctrl-C) removes it, wherever it comes.
    try:
        decoding = {"demosaic": demosaic, "transfer": transfer}
        counts = _build_into(store, data, layout, cloud, client, decoding, radiance_scale)
    except BaseException:
        store.abort()
        raise
    s_count, t_count, p_count = len(layout.cameras), len(layout.light_indices), len(cloud.points)
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
        camera_indices=layout.camera_indices,
        removed_partials=store.removed_partials,
    )


def _build_into(
    store: FieldStoreWriter,
    data: Dataset,
    layout: FieldLayout,
    cloud: PointCloud,
    client: Any,
    decoding: dict[str, Any],
    radiance_scale: float,
) -> dict[str, int]:
    """Build every camera's slabs into ``store`` and finish it; returns the build's counts."""
    # Each camera's images, by path: what a task needs of the dataset.
    brackets: list[dict[int, list[tuple[Path, float]]]] = [{} for _ in layout.cameras]
    darks: list[dict[float, Path]] = [{} for _ in layout.cameras]
    for (c, t), records in layout.brackets.items():
        brackets[c][t] = [(data.image_path(r), r.exposure_ms) for r in records]
    for (c, exposure_ms), record in layout.darks.items():
        darks[c][exposure_ms] = data.image_path(record)
    # One format per capture: every file is decoded against the first one's.
    first = next(path for camera in brackets for taken in camera.values() for path, _ in taken)
    reference = decode_image(first, **decoding).format
    options = decoding | {"expected": reference}
    scales = (radiance_scale * layout.intensities).astype(np.float32)
    writer = store.slab_writer()
    jobs = [CameraJob(s, pinhole, brackets[s], darks[s], layout.light_directions, scales,
                      options, writer) for s, pinhole in enumerate(layout.cameras)]  # fmt: skip
    counts = {"exposures": 0, "darks": 0, "without_dark": 0, "visible": 0, "saturated": 0}
    for result in _built_cameras(jobs, cloud, client):
        store.write_visibility(result.camera, result.visible)
        for t, (digest, peak) in result.slabs.items():
            store.record_slab(result.camera, t, digest, peak)
        for key, value in result.counts.items():
            counts[key] += value
    store.finish()
    return counts


def _built_cameras(jobs: list[CameraJob], cloud: PointCloud, client: Any) -> Iterator[CameraResult]:
    """Each camera's result as it is built: in turn here, or as Dask tasks finish."""
    if client is None:
        for job in progress_bar(jobs, desc="process", unit="camera"):
            yield job.build(cloud)
        return
    from dask.delayed import delayed

    from core.cluster import compute_each

    shared = client.scatter(cloud, broadcast=True, hash=False)  # to each worker once
    tasks = [delayed(CameraJob.build, pure=False)(job, shared) for job in jobs]
    for _, result in compute_each(client, tasks, what="process"):
        yield result


@dataclass(frozen=True)
class CameraResult:
    """What one camera's task built: its visibility, its slabs' digests and peaks, counts."""

    camera: int
    visible: NDArray[np.bool_]
    slabs: dict[int, tuple[bytes, float]]
    counts: dict[str, int]


@dataclass(frozen=True, eq=False)
class CameraJob:
    """One camera pose's part of a field: every light's bracket decoded, merged and sampled.

    Plain data (image paths, not the dataset), so a Dask task carries it; the slabs go
    straight into the store under construction (:class:`core.field_store.SlabWriter`) and
    only their digests come back. In memory at a time: one camera's dark frames, one
    bracket and one slab; a slab the capture lacks is interpolated from three written ones,
    read back from the store.

    Attributes
    ----------
    camera : int, the field's camera row s
    pinhole : PinholeCamera of that pose
    brackets : dict of light row t to its exposures' (image path, exposure_ms)
    darks : dict of exposure_ms (rounded to 1e-9) to the dark frame's path
    light_directions : ndarray, shape (T, 3), toward each light
    scales : ndarray, shape (T, 3), float32, radiance_scale x each light's intensity
    options : decode options (demosaic, transfer)
    slabs : SlabWriter of the store
    """

    camera: int
    pinhole: PinholeCamera
    brackets: dict[int, list[tuple[Path, float]]]
    darks: dict[float, Path]
    light_directions: NDArray[np.float64]
    scales: NDArray[np.float32]
    options: dict[str, Any]
    slabs: SlabWriter

    def build(self, cloud: PointCloud) -> CameraResult:
        """Write this camera's visibility-sampled slabs; returns what the writer records."""
        shape = (self.pinhole.height, self.pinhole.width)
        t_count, p_count = len(self.light_directions), len(cloud.points)
        splats = camera_splats(cloud.points, cloud.normals, self.pinhole, cloud.spacing)
        visible = shown_points(splats)
        index = np.flatnonzero(visible)
        counts = {"exposures": 0, "darks": 0, "without_dark": 0, "visible": len(index),
                  "saturated": 0}  # fmt: skip
        darks: dict[float, DecodedImage] = {}
        written: dict[int, tuple[bytes, float]] = {}
        for t in range(t_count):
            bracket = self.brackets.get(t)
            if bracket is None:
                continue
            exposures = []
            for path, exposure_ms in bracket:
                key = round(exposure_ms, 9)
                dark_path = self.darks.get(key)
                if dark_path is not None and key not in darks:
                    darks[key] = decode_image(dark_path, expected_shape=shape, **self.options)
                    counts["darks"] += 1
                counts["without_dark"] += dark_path is None
                image = decode_image(path, expected_shape=shape, **self.options)
                exposures.append(Exposure(image, exposure_ms, darks.get(key)))
            counts["exposures"] += len(exposures)
            merged = merge_exposures(exposures)
            slab = np.zeros((p_count, 3), dtype=np.float32)
            slab[index] = sample_view(merged.rate, splats, index) / self.scales[t]
            clipped = sample_view(merged.saturated.astype(np.float32), splats, index) > 0
            counts["saturated"] += int(clipped.sum())
            written[t] = self.slabs.write(self.camera, t, slab)
        for t in sorted(set(range(t_count)) - set(written)):
            slab = _interpolated_slab(self, sorted(written), t)
            written[t] = self.slabs.write(self.camera, t, slab)
        return CameraResult(self.camera, visible, written, counts)


def _interpolated_slab(job: CameraJob, taken: list[int], missing: int) -> NDArray[np.float32]:
    """The slab of light ``missing`` interpolated (barycentric) from the camera's taken ones.

    ``taken`` are lights whose slabs this camera wrote (measured ones); the three the
    weights name are read back from the store.
    """
    if not taken:
        raise DatasetError(f"a camera pose has no light images to interpolate light {missing}")
    directions = np.asarray(job.light_directions, dtype=np.float64)
    weights = interpolation_weights(
        directions[taken], directions[missing : missing + 1], "barycentric"
    )
    slab: NDArray[np.float32] | None = None
    for j, w in zip(weights.indices[0], weights.weights[0], strict=True):
        part = np.float32(w) * job.slabs.read(job.camera, taken[int(j)])
        slab = part if slab is None else slab + part
    assert slab is not None
    return slab
