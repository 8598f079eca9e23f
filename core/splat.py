"""Over 500 lines because it is one numba kernel family over one disk loop and its row bands.

Point splatting kernels: a z-buffer of disks, and depth-tested blending (numba).

Shared by the simulator's camera and the renderer (``render.splat``), so both live beside the
camera model they project with.

Points are disks of a given pixel radius at continuous image coordinates (pixel (i, j) is centred
at (i + 0.5, j + 0.5)). The same z-buffer serves the camera (visibility) and the light (shadow
map). Blending keeps every splat within a depth tolerance of the front surface, weighted by
1 - (d / r)^2, so neighbouring points of one surface mix and hidden surfaces do not.

Every pass over the disks runs on bands of image rows in parallel (:class:`RowBands`): a
point whose disk spans two bands is visited by both, each covering its own rows, so no two
threads write one pixel and each pixel still sees its points in increasing order (results
are the serial loop's, bit for bit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera, project_point
from core.errors import InputError

__all__ = [
    "DEPTH_TOLERANCE",
    "MIN_RADIUS_PX",
    "ROWS_PER_BAND",
    "SPLAT_RADIUS",
    "CameraDisks",
    "CameraSplats",
    "RowBands",
    "blend_splats",
    "camera_disks",
    "camera_splats",
    "depth_at_points",
    "disk_bounds",
    "for_each_cover",
    "require_outside",
    "row_bands",
    "shown_points",
    "splat_weight",
    "zbuffer",
    "zbuffer_band",
]

#: Splat radius and depth tolerance in splat sizes; the smallest splat radius, in pixels.
SPLAT_RADIUS = 1.0
DEPTH_TOLERANCE = 2.0
MIN_RADIUS_PX = 0.75
#: Image rows per band of the parallel disk loops: small enough that two cores share an
#: object's rows evenly, large enough that few disks straddle two bands.
ROWS_PER_BAND = 16
#: Chunks of points that sort into bands in parallel.
_BAND_CHUNKS = 8


@dataclass(frozen=True)
class RowBands:
    """The points whose disks reach each band of ``rows_per_band`` image rows.

    Attributes
    ----------
    rows_per_band : int
    start : ndarray, shape (B + 1,), int64, where each band's points begin in ``points``
    points : ndarray, shape (n,), int64, point indices, increasing within each band
    disks : ndarray, shape (n, 4), float64, (col, row, depth, radius) of each entry of
        ``points``: the passes over a band read them in order, not scattered over the cloud
    cells : ndarray, shape (B,), int64, pixels of the disks' bounding boxes in each band (at
        most that many covers: room for a pass that records them)
    """

    rows_per_band: int
    start: NDArray[np.int64]
    points: NDArray[np.int64]
    disks: NDArray[np.float64]
    cells: NDArray[np.int64]


@dataclass(frozen=True)
class CameraDisks:
    """Points as disks in one camera's image.

    Attributes
    ----------
    cols, rows : ndarray, shape (P,), continuous pixel coordinates
    depth : ndarray, shape (P,), along the viewing axis (inf for back faces: never shown)
    radius : ndarray, shape (P,), pixels, at least MIN_RADIUS_PX
    tolerance : float, scene units: splats this close behind the front surface blend
    bands : RowBands of the disks
    """

    cols: NDArray[np.float64]
    rows: NDArray[np.float64]
    depth: NDArray[np.float64]
    radius: NDArray[np.float64]
    tolerance: float
    bands: RowBands


@dataclass(frozen=True)
class CameraSplats(CameraDisks):
    """The disks and their z-buffer ``buffer`` (H, W): the nearest depth over every pixel."""

    buffer: NDArray[np.float64]


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


def camera_disks(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    camera: PinholeCamera,
    spacing: float,
) -> CameraDisks:
    """Project points (P, 3) with normals (P, 3) spaced ``spacing`` apart as disks.

    Raises :class:`~core.errors.InputError` when the camera stands within the points'
    bounding sphere (about the rig's origin, where the object stands).

    A disk is one point spacing wide, or MIN_RADIUS_PX when points are denser than pixels;
    the depth tolerance follows the disk's size in the scene (not only the spacing), so the
    points one small splat covers on a steep surface near the silhouette still blend.
    """
    cloud = np.asarray(points)
    facing = np.asarray(normals)
    if cloud.dtype not in (np.float32, np.float64):
        cloud = cloud.astype(np.float64)
    if facing.dtype != cloud.dtype:
        facing = facing.astype(cloud.dtype)
    count = len(cloud)
    if count == 0:
        raise InputError("the object has no points")
    cols, rows, depth, radius = (np.empty(count) for _ in range(4))
    # One parallel pass: projection, the facing test, the radius and the bounding sphere
    # (numpy's temporaries took 8 of the 23 ms of this function at 250k points).
    far = _splat_geometry(
        np.ascontiguousarray(cloud), np.ascontiguousarray(facing), camera.position,
        camera.axes(), camera.focal_px, 0.5 * camera.width, 0.5 * camera.height,
        SPLAT_RADIUS * spacing * camera.focal_px, cols, rows, depth, radius,
    )  # fmt: skip
    if camera.distance <= math.sqrt(far):
        require_outside(cloud, camera)  # raises, naming the distance and the radius
    bands = row_bands(cols, rows, depth, radius, camera.height, camera.width)
    size = max(SPLAT_RADIUS * spacing, MIN_RADIUS_PX * camera.distance / camera.focal_px)
    return CameraDisks(cols, rows, depth, radius, DEPTH_TOLERANCE * size, bands)


def camera_splats(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    camera: PinholeCamera,
    spacing: float,
) -> CameraSplats:
    """The disks of :func:`camera_disks` and their z-buffer."""
    d = camera_disks(points, normals, camera, spacing)
    buffer = np.full((camera.height, camera.width), np.inf)
    _zbuffer(d.bands, buffer)
    return CameraSplats(d.cols, d.rows, d.depth, d.radius, d.tolerance, d.bands, buffer)


def row_bands(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    height: int,
    width: int,
    rows_per_band: int = ROWS_PER_BAND,
) -> RowBands:
    """Sort disks into the bands of image rows they reach (a disk off the image in none)."""
    count = (height + rows_per_band - 1) // rows_per_band
    # Counted and filled in chunks of points in parallel; each chunk's stretch of a band
    # follows the chunk before it, so the points stay in increasing order.
    counts = np.zeros((_BAND_CHUNKS, count), dtype=np.int64)
    cells = np.zeros((_BAND_CHUNKS, count), dtype=np.int64)
    _count_bands(cols, rows, depth, radius, height, width, rows_per_band, counts, cells)
    start = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(counts.sum(axis=0), out=start[1:])
    cursor = start[:-1] + np.cumsum(counts, axis=0) - counts
    points = np.empty(start[-1], dtype=np.int64)
    disks = np.empty((start[-1], 4))
    _fill_bands(cols, rows, depth, radius, height, width, rows_per_band, cursor, points, disks)
    return RowBands(rows_per_band, start, points, disks, cells.sum(axis=0))


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
    _zbuffer(row_bands(cols, rows, depth, radius, height, width), buffer)
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


def shown_points(splats: CameraSplats) -> NDArray[np.bool_]:
    """Points (P,) whose splat blends into at least one pixel: the points an image shows.

    A point on a steep (grazing) surface can fail the depth test at its own centre yet show
    at a neighbouring pixel; it is seen, and its radiance is needed.
    """
    shown = np.zeros(splats.cols.shape, dtype=np.bool_)
    _shown(splats.bands, splats.buffer, splats.tolerance, shown)
    return shown


def blend_splats(
    splats: CameraSplats, colours: NDArray[np.float64]
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Blend the front surface's splats of ``colours`` (P, 3).

    Returns
    -------
    image : ndarray, shape (H, W, 3), float32, weighted mean colour (0 where uncovered)
    weight : ndarray, shape (H, W), float32, summed splat weight (0 where uncovered)
    """
    height, width = splats.buffer.shape
    total = np.zeros((height, width, 3))
    weight = np.zeros((height, width))
    _blend(splats.bands, colours, splats.buffer, splats.tolerance, total, weight)
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
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    row_lo: int,
    row_hi: int,
    buffer: NDArray[np.float64],
    tolerance: float,
    nearer: bool,
    visit: Any,
    state: Any,
) -> None:
    """The one disk loop: call ``visit`` for every (point, pixel) a splat covers in a band.

    The points are ``members`` (in that order) with their ``disks`` (col, row, depth,
    radius), the pixels those of rows [row_lo, row_hi) of ``buffer``. A pixel counts when its
    centre lies within the point's disk and the point passes the depth test against
    ``buffer``: nearer than the buffer (``nearer``: building a z-buffer), or no more than
    ``tolerance`` behind it (blending the front surface). ``visit(p, pixel, d2, r2, z,
    state)`` gets the point, the pixel's flat index i W + j, the squared distance from the
    centre, the squared radius and the point's depth; it returns True to leave the point's
    remaining pixels (in this band) out. Compiled into each caller (``inline``), so the
    visitor costs no call.
    """
    height, width = buffer.shape
    for q in range(members.shape[0]):
        p = members[q]
        col, row, z, r = disks[q, 0], disks[q, 1], disks[q, 2], disks[q, 3]
        r2 = r * r
        i0, i1, j0, j1 = disk_bounds(row, col, z, r, height, width)
        stop = False
        for i in range(max(i0, row_lo), min(i1, row_hi - 1) + 1):
            dy = i + 0.5 - row
            for j in range(j0, j1 + 1):
                dx = j + 0.5 - col
                d2 = dx * dx + dy * dy
                front = z < buffer[i, j] if nearer else z <= buffer[i, j] + tolerance
                if d2 <= r2 and front and visit(p, i * width + j, d2, r2, z, state):
                    stop = True
                    break
            if stop:
                break


# _count_bands and _fill_bands take the same disks on purpose: the first pass sizes each
# band, the second fills it in the room made; numba kernels take arrays, not CameraDisks.
@numba.njit(cache=True, parallel=True)
def _count_bands(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    height: int,
    width: int,
    rows_per_band: int,
    counts: NDArray[np.int64],
    cells: NDArray[np.int64],
) -> None:
    chunks, total = counts.shape[0], cols.shape[0]
    for chunk in numba.prange(chunks):
        for p in range(chunk * total // chunks, (chunk + 1) * total // chunks):
            i0, i1, j0, j1 = disk_bounds(rows[p], cols[p], depth[p], radius[p], height, width)
            if i1 >= i0 and j1 >= j0:
                for band in range(i0 // rows_per_band, i1 // rows_per_band + 1):
                    counts[chunk, band] += 1
                    lo = max(i0, band * rows_per_band)
                    hi = min(i1, (band + 1) * rows_per_band - 1)
                    cells[chunk, band] += (hi - lo + 1) * (j1 - j0 + 1)


# The disks of _count_bands again, on purpose (the note there).
@numba.njit(cache=True, parallel=True)
def _fill_bands(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    height: int,
    width: int,
    rows_per_band: int,
    cursor: NDArray[np.int64],
    points: NDArray[np.int64],
    disks: NDArray[np.float64],
) -> None:
    chunks, total = cursor.shape[0], cols.shape[0]
    for chunk in numba.prange(chunks):
        for p in range(chunk * total // chunks, (chunk + 1) * total // chunks):
            i0, i1, j0, j1 = disk_bounds(rows[p], cols[p], depth[p], radius[p], height, width)
            if i1 >= i0 and j1 >= j0:
                for band in range(i0 // rows_per_band, i1 // rows_per_band + 1):
                    k = cursor[chunk, band]
                    points[k] = p
                    disks[k, 0], disks[k, 1] = cols[p], rows[p]
                    disks[k, 2], disks[k, 3] = depth[p], radius[p]
                    cursor[chunk, band] = k + 1


# The camera's numbers one by one on purpose, as core.camera_model's _project takes them:
# numba kernels take arrays and scalars, not a PinholeCamera.
@numba.njit(cache=True, parallel=True)
def _splat_geometry(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    position: NDArray[np.float64],
    axes: NDArray[np.float64],
    focal: float,
    centre_col: float,
    centre_row: float,
    spacing_focal: float,
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
) -> float:
    """Fill the disks (back faces at infinite depth); returns the largest squared norm."""
    far = 0.0
    for p in numba.prange(points.shape[0]):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        cols[p], rows[p], d = project_point(x, y, z, position, axes, focal, centre_col, centre_row)
        to_eye = (
            normals[p, 0] * (position[0] - x)
            + normals[p, 1] * (position[1] - y)
            + normals[p, 2] * (position[2] - z)
        )
        d = d if to_eye > 0.0 else np.inf
        depth[p] = d
        radius[p] = max(spacing_focal / d, MIN_RADIUS_PX)
        far = max(far, float(x * x + y * y + z * z))
    return far


@numba.njit(cache=True, inline="always")
def _nearest_depth(
    p: int, pixel: int, d2: float, r2: float, z: float, buffer: NDArray[np.float64]
) -> bool:
    buffer[pixel] = z
    return False


@numba.njit(cache=True, inline="always")
def zbuffer_band(
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    row_lo: int,
    row_hi: int,
    buffer: NDArray[np.float64],
) -> None:
    """The z-buffer ``buffer`` (H, W) over rows [row_lo, row_hi) of one band's disks."""
    for_each_cover(members, disks, row_lo, row_hi, buffer, 0.0, True, _nearest_depth,
                   buffer.reshape(-1))  # fmt: skip


@numba.njit(cache=True, parallel=True)
def _zbuffer_bands(
    start: NDArray[np.int64],
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    rows_per_band: int,
    buffer: NDArray[np.float64],
) -> None:
    for band in numba.prange(start.shape[0] - 1):
        a, b = start[band], start[band + 1]
        zbuffer_band(members[a:b], disks[a:b], band * rows_per_band,
                     (band + 1) * rows_per_band, buffer)  # fmt: skip


def _zbuffer(bands: RowBands, buffer: NDArray[np.float64]) -> None:
    _zbuffer_bands(bands.start, bands.points, bands.disks, bands.rows_per_band, buffer)


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
def _blend_band(
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    row_lo: int,
    row_hi: int,
    colours: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    total: NDArray[np.float64],
    weight: NDArray[np.float64],
) -> None:
    # A function of its own, called from the parallel loop: numba's parfors lose the writes
    # through a tuple of arrays built in (or passed into) a prange body.
    state = (colours, total, weight)
    for_each_cover(members, disks, row_lo, row_hi, buffer, tolerance, False, _accumulate,
                   state)  # fmt: skip


@numba.njit(cache=True, parallel=True)
def _blend_bands(
    start: NDArray[np.int64],
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    rows_per_band: int,
    colours: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    total: NDArray[np.float64],
    weight: NDArray[np.float64],
) -> None:
    flat_total, flat_weight = total.reshape(-1, 3), weight.reshape(-1)
    for band in numba.prange(start.shape[0] - 1):
        a, b = start[band], start[band + 1]
        _blend_band(members[a:b], disks[a:b], band * rows_per_band, (band + 1) * rows_per_band,
                    colours, buffer, tolerance, flat_total, flat_weight)  # fmt: skip


def _blend(
    bands: RowBands,
    colours: NDArray[np.float64],
    buffer: NDArray[np.float64],
    tolerance: float,
    total: NDArray[np.float64],
    weight: NDArray[np.float64],
) -> None:
    _blend_bands(bands.start, bands.points, bands.disks, bands.rows_per_band, colours, buffer,
                 tolerance, total, weight)  # fmt: skip


@numba.njit(cache=True, inline="always")
def _mark_shown(
    p: int, pixel: int, d2: float, r2: float, z: float, shown: NDArray[np.bool_]
) -> bool:
    shown[p] = True
    return True


@numba.njit(cache=True, parallel=True)
def _shown_bands(
    start: NDArray[np.int64],
    members: NDArray[np.int64],
    disks: NDArray[np.float64],
    rows_per_band: int,
    buffer: NDArray[np.float64],
    tolerance: float,
    shown: NDArray[np.bool_],
) -> None:
    # A disk in two bands may be marked by both: the same value, so the order does not matter.
    for band in numba.prange(start.shape[0] - 1):
        a, b = start[band], start[band + 1]
        for_each_cover(members[a:b], disks[a:b], band * rows_per_band,
                       (band + 1) * rows_per_band, buffer, tolerance, False, _mark_shown,
                       shown)  # fmt: skip


def _shown(
    bands: RowBands, buffer: NDArray[np.float64], tolerance: float, shown: NDArray[np.bool_]
) -> None:
    _shown_bands(bands.start, bands.points, bands.disks, bands.rows_per_band, buffer,
                 tolerance, shown)  # fmt: skip
