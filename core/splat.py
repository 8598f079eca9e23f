"""Point splatting kernels: a z-buffer of disks, and depth-tested blending (numba).

Shared by the simulator's camera and the renderer (``render.splat``), so both live beside the
camera model they project with.

Points are disks of a given pixel radius at continuous image coordinates (pixel (i, j) is centred
at (i + 0.5, j + 0.5)). The same z-buffer serves the camera (visibility) and the light (shadow
map). Blending keeps every splat within a depth tolerance of the front surface, weighted by
1 - (d / r)^2, so neighbouring points of one surface mix and hidden surfaces do not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError

__all__ = [
    "DEPTH_TOLERANCE",
    "MIN_RADIUS_PX",
    "SPLAT_RADIUS",
    "CameraSplats",
    "blend_splats",
    "camera_splats",
    "depth_at_points",
    "disk_bounds",
    "for_each_cover",
    "require_outside",
    "shown_points",
    "splat_weight",
    "zbuffer",
]

#: Splat radius and depth tolerance in splat sizes; the smallest splat radius, in pixels.
SPLAT_RADIUS = 1.0
DEPTH_TOLERANCE = 2.0
MIN_RADIUS_PX = 0.75


@dataclass(frozen=True)
class CameraSplats:
    """Points as disks in one camera's image.

    Attributes
    ----------
    cols, rows : ndarray, shape (P,), continuous pixel coordinates
    depth : ndarray, shape (P,), along the viewing axis (inf for back faces: never shown)
    radius : ndarray, shape (P,), pixels, at least MIN_RADIUS_PX
    buffer : ndarray, shape (H, W), the z-buffer of the disks
    tolerance : float, scene units: splats this close behind the front surface blend
    """

    cols: NDArray[np.float64]
    rows: NDArray[np.float64]
    depth: NDArray[np.float64]
    radius: NDArray[np.float64]
    buffer: NDArray[np.float64]
    tolerance: float


def require_outside(points: NDArray[np.floating], camera: PinholeCamera) -> None:
    """Refuse a camera within the points' bounding sphere (about the rig's origin).

    Inside it a camera sees the surface from behind or not at all: the picture would be black,
    not an error. Callers with slow work before the first view check this first.

    Raises
    ------
    InputError
        Naming the distance and the object's radius.
    """
    cloud = np.asarray(points, dtype=np.float64)
    if len(cloud) == 0:
        raise InputError("the object has no points")
    bounding = float(np.sqrt(np.max(np.einsum("pk,pk->p", cloud, cloud))))
    if camera.distance <= bounding:
        raise InputError(
            f"camera distance {camera.distance:g} is inside the object (bounding radius "
            f"{bounding:.3g}); move the camera further out (--distance)"
        )


def camera_splats(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    camera: PinholeCamera,
    spacing: float,
) -> CameraSplats:
    """Project points (P, 3) with normals (P, 3) spaced ``spacing`` apart as splats.

    Raises :class:`~core.errors.InputError` when the camera stands within the points'
    bounding sphere (about the rig's origin, where the object stands).

    A splat is one point spacing wide, or MIN_RADIUS_PX when points are denser than pixels;
    the depth tolerance follows the splat's size in the scene (not only the spacing), so the
    points one small splat covers on a steep surface near the silhouette still blend.
    """
    cloud = np.asarray(points, dtype=np.float64)
    require_outside(cloud, camera)
    cols, rows, depth = camera.project(cloud)
    facing = np.einsum("pk,pk->p", np.asarray(normals, np.float64), camera.position - cloud) > 0
    depth = np.where(facing, depth, np.inf)
    radius = np.maximum(SPLAT_RADIUS * spacing * camera.focal_px / depth, MIN_RADIUS_PX)
    buffer = zbuffer(cols, rows, depth, radius, camera.height, camera.width)
    size = max(SPLAT_RADIUS * spacing, MIN_RADIUS_PX * camera.distance / camera.focal_px)
    return CameraSplats(cols, rows, depth, radius, buffer, DEPTH_TOLERANCE * size)


def zbuffer(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    height: int,
    width: int,
) -> NDArray[np.float64]:
    """Nearest depth over every pixel that a disk covers; (H, W), ``inf`` where nothing is."""
    buffer = np.full((height, width), np.inf)
    _zbuffer(cols, rows, depth, radius, buffer)
    return buffer


def depth_at_points(
    cols: NDArray[np.float64], rows: NDArray[np.float64], buffer: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The z-buffer value at the pixel under each point's centre; ``inf`` off the image."""
    height, width = buffer.shape
    i = np.floor(rows).astype(np.int64)
    j = np.floor(cols).astype(np.int64)
    inside = (i >= 0) & (i < height) & (j >= 0) & (j < width)
    out = np.full(cols.shape, np.inf)
    out[inside] = buffer[i[inside], j[inside]]
    return out


def shown_points(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
) -> NDArray[np.bool_]:
    """Points (P,) whose splat blends into at least one pixel: the points an image shows.

    A point on a steep (grazing) surface can fail the depth test at its own centre yet show
    at a neighbouring pixel; it is seen, and its radiance is needed.
    """
    shown = np.zeros(cols.shape, dtype=np.bool_)
    _shown(cols, rows, depth, radius, buffer, tolerance, shown)
    return shown


def blend_splats(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    colours: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Blend the front surface's splats.

    Returns
    -------
    image : ndarray, shape (H, W, 3), float32, weighted mean colour (0 where uncovered)
    weight : ndarray, shape (H, W), float32, summed splat weight (0 where uncovered)
    """
    height, width = buffer.shape
    total = np.zeros((height, width, 3))
    weight = np.zeros((height, width))
    _blend(cols, rows, depth, radius, colours, buffer, tolerance, total, weight)
    image = np.divide(
        total, weight[:, :, None], out=np.zeros_like(total), where=weight[:, :, None] > 0
    )
    return image.astype(np.float32), weight.astype(np.float32)


@numba.njit(cache=True, inline="always")
def disk_bounds(
    row: float, col: float, depth: float, r: float, height: int, width: int
) -> tuple[int, int, int, int]:
    """Row and column ranges (i0, i1, j0, j1) whose pixel centres may lie within r of (row, col).

    An empty range for a point behind the camera or off any finite position.
    """
    if not (depth > 0.0 and math.isfinite(depth) and math.isfinite(row) and math.isfinite(col)):
        return 0, -1, 0, -1
    return (
        max(0, math.floor(row - r - 0.5)),
        min(height - 1, math.ceil(row + r - 0.5)),
        max(0, math.floor(col - r - 0.5)),
        min(width - 1, math.ceil(col + r - 0.5)),
    )


@numba.njit(cache=True, inline="always")
def splat_weight(d2: float, r2: float) -> float:
    """Weight of a splat at squared distance ``d2`` from its centre, radius squared ``r2``.

    1 - (d / r)^2, plus a floor so that the rim still counts where it is all that covers a
    pixel.
    """
    return 1.0 - d2 / (r2 + 1e-12) + 1e-3


@numba.njit(cache=True, inline="always")
def for_each_cover(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    nearer: bool,
    visit: Any,
    state: Any,
) -> None:
    """The one disk loop: call ``visit`` for every (point, pixel) a splat covers.

    A pixel counts when its centre lies within the point's disk and the point passes the depth
    test against ``buffer``: nearer than the buffer (``nearer``: building a z-buffer), or no
    more than ``tolerance`` behind it (blending the front surface). ``visit(p, pixel, d2, r2,
    z, state)`` gets the point, the pixel's flat index i W + j, the squared distance from the
    centre, the squared radius and the point's depth; it returns True to leave the point's
    remaining pixels out. Compiled into each caller (``inline``), so the visitor costs no call.
    """
    height, width = buffer.shape
    for p in range(cols.shape[0]):
        z = depth[p]
        r2 = radius[p] * radius[p]
        i0, i1, j0, j1 = disk_bounds(rows[p], cols[p], z, radius[p], height, width)
        stop = False
        for i in range(i0, i1 + 1):
            dy = i + 0.5 - rows[p]
            for j in range(j0, j1 + 1):
                dx = j + 0.5 - cols[p]
                d2 = dx * dx + dy * dy
                front = z < buffer[i, j] if nearer else z <= buffer[i, j] + tolerance
                if d2 <= r2 and front and visit(p, i * width + j, d2, r2, z, state):
                    stop = True
                    break
            if stop:
                break


@numba.njit(cache=True, inline="always")
def _nearest_depth(
    p: int, pixel: int, d2: float, r2: float, z: float, buffer: NDArray[np.float64]
) -> bool:
    buffer[pixel] = z
    return False


@numba.njit(cache=True)
def _zbuffer(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    buffer: NDArray[np.float64],
) -> None:
    flat = buffer.reshape(-1)
    for_each_cover(cols, rows, depth, radius, buffer, 0.0, True, _nearest_depth, flat)


@numba.njit(cache=True, inline="always")
def _accumulate(p: int, pixel: int, d2: float, r2: float, z: float, state: Any) -> bool:
    colours, total, weight = state
    w = splat_weight(d2, r2)
    total[pixel, 0] += w * colours[p, 0]
    total[pixel, 1] += w * colours[p, 1]
    total[pixel, 2] += w * colours[p, 2]
    weight[pixel] += w
    return False


@numba.njit(cache=True)
def _blend(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    colours: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    total: NDArray[np.float64],
    weight: NDArray[np.float64],
) -> None:
    state = (colours, total.reshape(-1, 3), weight.reshape(-1))
    for_each_cover(cols, rows, depth, radius, buffer, tolerance, False, _accumulate, state)


@numba.njit(cache=True, inline="always")
def _mark_shown(
    p: int, pixel: int, d2: float, r2: float, z: float, shown: NDArray[np.bool_]
) -> bool:
    shown[p] = True
    return True


@numba.njit(cache=True)
def _shown(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    shown: NDArray[np.bool_],
) -> None:
    for_each_cover(cols, rows, depth, radius, buffer, tolerance, False, _mark_shown, shown)
