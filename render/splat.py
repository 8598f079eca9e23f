"""Point splatting for relit point clouds: plan once per view, then splat every new lighting.

For a fixed view, which pixels each visible point covers and with what weight does not depend
on the lighting. :func:`plan_splats` finds it once (a z-buffer of disks one point spacing wide,
then every splat within a depth tolerance of the front surface, weighted by 1 - (d / r)^2 and
normalised per pixel) and stores the (pixel, point, weight) records band by band of image
rows; :func:`splat` then costs one pass over the records per frame. The disk loop is
:func:`core.splat.for_each_cover`, shared with the simulator.

Both run on the bands of :class:`core.splat.RowBands` in parallel: one band's z-buffer and its
records are one task (its rows stay in cache between them), and no two bands write one pixel.
Within a pixel the records come in increasing point order, so a frame sums exactly as a
serial loop over the points would.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.point_spacing import point_spacing
from core.splat import camera_disks, for_each_cover, splat_weight, zbuffer_band

__all__ = ["SplatPlan", "plan_splats", "splat"]


@dataclass(frozen=True)
class SplatPlan:
    """The splats of one view: (pixel, point, weight) records, grouped by band of image rows.

    Attributes
    ----------
    height, width : int, image size
    record_start, record_count : ndarray, shape (B,), int64, the records of band b are
        ``[record_start[b], record_start[b] + record_count[b])`` (between bands, unused room)
    pixel_index : ndarray, shape (n,), int32, flat pixel i W + j of each record
    point_index : ndarray, shape (n,), int32, contributing point of each record
    weight : ndarray, shape (n,), float32, normalised to sum 1 over each covered pixel
    coverage : ndarray, shape (H, W), bool, pixels the object covers
    visible : ndarray, shape (P,), bool, points at the front surface (they need relighting)
    """

    height: int
    width: int
    record_start: NDArray[np.int64]
    record_count: NDArray[np.int64]
    pixel_index: NDArray[np.int32]
    point_index: NDArray[np.int32]
    weight: NDArray[np.float32]
    coverage: NDArray[np.bool_]
    visible: NDArray[np.bool_]

    @property
    def records(self) -> NDArray[np.int64]:
        """Indices of the used records, band by band; shape (nnz,)."""
        return np.concatenate(
            [np.arange(s, s + c) for s, c in zip(self.record_start, self.record_count, strict=True)]
        )


def plan_splats(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    camera: PinholeCamera,
    spacing: float | None = None,
) -> SplatPlan:
    """Find the splats of ``points`` (P, 3) with ``normals`` (P, 3) for ``camera``.

    ``spacing`` is the surface distance between neighbouring points (estimated by
    :func:`point_spacing` when None); splats one spacing wide leave no holes.
    """
    cloud = np.asarray(points)
    if spacing is None:
        spacing = point_spacing(cloud)
    if not spacing > 0:
        raise InputError(f"point spacing must be positive, got {spacing}")
    if len(cloud) >= 2**31 or camera.height * camera.width >= 2**31:
        raise InputError(
            f"{len(cloud)} points in a {camera.width}x{camera.height} view: splat plans index "
            "points and pixels with 32-bit integers; split the cloud or the view"
        )
    disks = camera_disks(cloud, normals, camera, spacing)
    bands = disks.bands
    # Each band gets room for every pixel of its disks' bounding boxes (an upper bound on its
    # records); the pages of room left unused are never touched.
    record_start = np.zeros(len(bands.cells), dtype=np.int64)
    np.cumsum(bands.cells[:-1], out=record_start[1:])
    room = int(bands.cells.sum())
    pixel_index = np.empty(room, dtype=np.int32)
    point_index = np.empty(room, dtype=np.int32)
    weight = np.empty(room, dtype=np.float32)
    record_count = np.zeros(len(bands.cells), dtype=np.int64)
    buffer = np.full((camera.height, camera.width), np.inf)
    total = np.zeros(camera.height * camera.width)
    visible = np.zeros(len(cloud), dtype=bool)
    _plan(
        bands.start, bands.points, bands.disks, bands.rows_per_band, disks.tolerance, buffer,
        record_start, record_count, pixel_index, point_index, weight, total, visible,
    )  # fmt: skip
    return SplatPlan(
        camera.height, camera.width, record_start, record_count, pixel_index, point_index,
        weight, (total > 0).reshape(camera.height, camera.width), visible,
    )  # fmt: skip


def splat(plan: SplatPlan, radiance: NDArray[np.floating]) -> NDArray[np.float32]:
    """The image (H, W, 3), float32, of points of radiance (P, 3) through ``plan``; 0 uncovered."""
    colours = np.asarray(radiance, dtype=np.float32)
    if colours.ndim != 2 or colours.shape[1] != 3 or len(colours) != len(plan.visible):
        raise InputError(
            f"radiance must be ({len(plan.visible)}, 3) for this plan, got {colours.shape}"
        )
    image = np.zeros((plan.height * plan.width, 3), dtype=np.float32)
    _splat(
        plan.record_start, plan.record_count, plan.pixel_index, plan.point_index, plan.weight,
        colours, image,
    )  # fmt: skip
    return image.reshape(plan.height, plan.width, 3)


@numba.njit(cache=True, inline="always")
def _record_cover(p: int, pixel: int, d2: float, r2: float, z: float, state: Any) -> bool:
    pixel_index, point_index, weight, total, visible, next_record = state
    k = next_record[0]
    w = splat_weight(d2, r2)
    pixel_index[k] = pixel
    point_index[k] = p
    weight[k] = w
    total[pixel] += np.float32(w)  # the sum of the stored (float32) weights, in float64
    visible[p] = True
    next_record[0] = k + 1
    return False


@numba.njit(cache=True)
def _plan_band(
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    row_lo: int,
    row_hi: int,
    tolerance: float,
    buffer: NDArray[np.float64],
    first: int,
    pixel_index: NDArray[np.int32],
    point_index: NDArray[np.int32],
    weight: NDArray[np.float32],
    total: NDArray[np.float64],
    visible: NDArray[np.bool_],
) -> int:
    """One band: its z-buffer, its records from ``first`` on, normalised; returns their count."""
    # A function of its own, called from the parallel loop: numba's parfors lose the writes
    # through a tuple of arrays built in (or passed into) a prange body. A point in two bands
    # may be marked visible by both: the same value, so the order does not matter.
    zbuffer_band(members, disks, row_lo, row_hi, buffer)
    next_record = np.array([first])
    state = (pixel_index, point_index, weight, total, visible, next_record)
    for_each_cover(members, disks, row_lo, row_hi, buffer, tolerance, False, _record_cover,
                   state)  # fmt: skip
    for k in range(first, next_record[0]):
        weight[k] = weight[k] / total[pixel_index[k]]
    return int(next_record[0]) - first


# The bands' and the records' arrays one by one on purpose: numba kernels take arrays, not
# dataclasses, and a tuple of arrays passed into a prange body loses its writes.
@numba.njit(cache=True, parallel=True)
def _plan(
    start: NDArray[np.int64],
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    rows_per_band: int,
    tolerance: float,
    buffer: NDArray[np.float64],
    record_start: NDArray[np.int64],
    record_count: NDArray[np.int64],
    pixel_index: NDArray[np.int32],
    point_index: NDArray[np.int32],
    weight: NDArray[np.float32],
    total: NDArray[np.float64],
    visible: NDArray[np.bool_],
) -> None:
    for band in numba.prange(start.shape[0] - 1):
        a, b = start[band], start[band + 1]
        record_count[band] = _plan_band(
            members[a:b], disks[a:b], band * rows_per_band, (band + 1) * rows_per_band,
            tolerance, buffer, record_start[band], pixel_index, point_index, weight, total,
            visible,
        )  # fmt: skip


# The plan's arrays one by one on purpose: numba kernels take arrays, not a SplatPlan.
@numba.njit(cache=True, parallel=True)
def _splat(
    record_start: NDArray[np.int64],
    record_count: NDArray[np.int64],
    pixel_index: NDArray[np.int32],
    point_index: NDArray[np.int32],
    weight: NDArray[np.float32],
    colours: NDArray[np.float32],
    image: NDArray[np.float32],
) -> None:
    for band in numba.prange(record_start.shape[0]):
        for k in range(record_start[band], record_start[band] + record_count[band]):
            pixel, p, w = pixel_index[k], point_index[k], weight[k]
            image[pixel, 0] += w * colours[p, 0]
            image[pixel, 1] += w * colours[p, 1]
            image[pixel, 2] += w * colours[p, 2]
