"""Point splatting for relit point clouds: plan once per view, then splat every new lighting.

For a fixed view, which pixels each visible point covers and with what weight does not depend
on the lighting. :func:`plan_splats` finds it once (a z-buffer of disks one point spacing wide,
then every splat within a depth tolerance of the front surface, weighted by 1 - (d / r)^2 and
normalised per pixel) and stores it as a sparse pixel x point matrix; :func:`splat` then costs
one sparse product per frame. The disk loop is :func:`core.splat.for_each_cover`, shared with
the simulator.
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
from core.splat import camera_splats, for_each_cover, splat_weight

__all__ = ["SplatPlan", "plan_splats", "splat"]


@dataclass(frozen=True)
class SplatPlan:
    """The splats of one view: a sparse (pixels x points) matrix in CSR order over pixels.

    Attributes
    ----------
    height, width : int, image size
    pixel_start : ndarray, shape (H W + 1,), int64, row pointers
    point_index : ndarray, shape (nnz,), int64, contributing point of each entry
    weight : ndarray, shape (nnz,), float32, normalised to sum 1 over each covered pixel
    visible : ndarray, shape (P,), bool, points at the front surface (they need relighting)
    """

    height: int
    width: int
    pixel_start: NDArray[np.int64]
    point_index: NDArray[np.int64]
    weight: NDArray[np.float32]
    visible: NDArray[np.bool_]

    @property
    def coverage(self) -> NDArray[np.bool_]:
        """Pixels the object covers; shape (H, W)."""
        return (np.diff(self.pixel_start) > 0).reshape(self.height, self.width)


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
    cloud = np.asarray(points, dtype=np.float64)
    if spacing is None:
        spacing = point_spacing(cloud)
    if not spacing > 0:
        raise InputError(f"point spacing must be positive, got {spacing}")
    splats = camera_splats(cloud, normals, camera, spacing)
    cols, rows, depth, radius = splats.cols, splats.rows, splats.depth, splats.radius
    buffer, tolerance = splats.buffer, splats.tolerance
    counts = np.zeros(camera.height * camera.width + 1, dtype=np.int64)
    _count(cols, rows, depth, radius, buffer, tolerance, counts)
    pixel_start = np.concatenate([[0], np.cumsum(counts[:-1])]).astype(np.int64)
    point_index = np.empty(pixel_start[-1], dtype=np.int64)
    weight = np.empty(pixel_start[-1], dtype=np.float64)
    _fill(cols, rows, depth, radius, buffer, tolerance, pixel_start.copy(), point_index, weight)
    _normalise(pixel_start, weight)
    visible = np.zeros(len(cloud), dtype=bool)
    visible[point_index] = True
    return SplatPlan(
        camera.height, camera.width, pixel_start, point_index, weight.astype(np.float32), visible
    )


def splat(plan: SplatPlan, radiance: NDArray[np.floating]) -> NDArray[np.float32]:
    """The image (H, W, 3), float32, of points of radiance (P, 3) through ``plan``; 0 uncovered."""
    colours = np.asarray(radiance, dtype=np.float32)
    if colours.ndim != 2 or colours.shape[1] != 3 or len(colours) != len(plan.visible):
        raise InputError(
            f"radiance must be ({len(plan.visible)}, 3) for this plan, got {colours.shape}"
        )
    image = np.zeros((plan.height * plan.width, 3), dtype=np.float32)
    _gather(plan.pixel_start, plan.point_index, plan.weight, colours, image)
    return image.reshape(plan.height, plan.width, 3)


@numba.njit(cache=True, inline="always")
def _count_cover(
    p: int, pixel: int, d2: float, r2: float, z: float, counts: NDArray[np.int64]
) -> bool:
    counts[pixel] += 1
    return False


@numba.njit(cache=True)
def _count(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    counts: NDArray[np.int64],
) -> None:
    for_each_cover(cols, rows, depth, radius, buffer, tolerance, False, _count_cover, counts)


@numba.njit(cache=True, inline="always")
def _fill_cover(p: int, pixel: int, d2: float, r2: float, z: float, state: Any) -> bool:
    cursor, point_index, weight = state
    k = cursor[pixel]
    point_index[k] = p
    weight[k] = splat_weight(d2, r2)
    cursor[pixel] = k + 1
    return False


@numba.njit(cache=True)
def _fill(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    cursor: NDArray[np.int64],
    point_index: NDArray[np.int64],
    weight: NDArray[np.float64],
) -> None:
    state = (cursor, point_index, weight)
    for_each_cover(cols, rows, depth, radius, buffer, tolerance, False, _fill_cover, state)


@numba.njit(cache=True, parallel=True)
def _normalise(pixel_start: NDArray[np.int64], weight: NDArray[np.float64]) -> None:
    for pixel in numba.prange(pixel_start.shape[0] - 1):
        total = 0.0
        for k in range(pixel_start[pixel], pixel_start[pixel + 1]):
            total += weight[k]
        for k in range(pixel_start[pixel], pixel_start[pixel + 1]):
            weight[k] /= total


@numba.njit(cache=True, parallel=True)
def _gather(
    pixel_start: NDArray[np.int64],
    point_index: NDArray[np.int64],
    weight: NDArray[np.float32],
    colours: NDArray[np.float32],
    image: NDArray[np.float32],
) -> None:
    for pixel in numba.prange(pixel_start.shape[0] - 1):
        r = g = b = numba.float32(0.0)
        for k in range(pixel_start[pixel], pixel_start[pixel + 1]):
            p = point_index[k]
            w = weight[k]
            r += w * colours[p, 0]
            g += w * colours[p, 1]
            b += w * colours[p, 2]
        image[pixel, 0] = r
        image[pixel, 1] = g
        image[pixel, 2] = b
