"""Direction math: the one module that converts angles, directions and panorama pixels.

Conventions (``docs/conventions.md``): right-handed rig frame, ``+z`` up, ``+x`` at azimuth 0,
``+y`` at azimuth 90 degrees. Azimuth phi runs counter-clockwise from ``+x`` seen from above;
inclination theta is the polar angle from ``+z`` (0 = straight above, 90 degrees = horizon)::

    direction = (sin(theta) cos(phi), sin(theta) sin(phi), cos(theta))

Equirectangular panoramas have H rows and W = 2H columns. The centre of pixel (i, j) looks along
theta = pi (i + 0.5) / H and phi = pi - 2 pi (j + 0.5) / W: row 0 is at the zenith, the centre
column looks along ``+x`` and moving right turns clockwise seen from above (a 360-degree photo
viewed from inside the sphere).

Degrees appear only in the ``*_deg`` functions (for people, configs and the CLI); everything
else works in radians and unit vectors. Nothing outside this module converts between them.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError

FloatArray = NDArray[np.float64]

__all__ = [
    "angle_between",
    "angles_deg_from_direction",
    "angles_from_direction",
    "direction_from_angles",
    "direction_from_angles_deg",
    "farthest_point_order",
    "fibonacci_sphere",
    "hemisphere_layout",
    "normalize",
    "panorama_azimuths",
    "panorama_bilinear_cell",
    "panorama_directions",
    "panorama_inclinations",
    "panorama_pixel_from_direction",
    "panorama_pixel_index",
    "panorama_pixel_points",
    "panorama_row_solid_angles",
    "panorama_solid_angles",
    "rotate_directions_yaw",
    "rotate_panorama_yaw",
    "spread_partition",
]


def direction_from_angles(azimuth: ArrayLike, inclination: ArrayLike) -> FloatArray:
    """Unit vectors from azimuth and inclination in radians.

    Parameters
    ----------
    azimuth, inclination : array_like, broadcastable, radians

    Returns
    -------
    ndarray, shape (..., 3), float64
    """
    phi = np.asarray(azimuth, dtype=np.float64)
    theta = np.asarray(inclination, dtype=np.float64)
    sin_t = np.sin(theta)
    return np.stack(
        np.broadcast_arrays(sin_t * np.cos(phi), sin_t * np.sin(phi), np.cos(theta)), -1
    )


def direction_from_angles_deg(azimuth_deg: ArrayLike, inclination_deg: ArrayLike) -> FloatArray:
    """Unit vectors from azimuth and inclination in degrees; shape (..., 3), float64."""
    return direction_from_angles(
        np.deg2rad(np.asarray(azimuth_deg, dtype=np.float64)),
        np.deg2rad(np.asarray(inclination_deg, dtype=np.float64)),
    )


def normalize(vectors: ArrayLike) -> FloatArray:
    """Scale vectors of shape (..., 3) to unit length; zero or non-finite vectors are refused."""
    v = np.asarray(vectors, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise InputError(f"directions must have shape (..., 3), got {v.shape}")
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    bad = ~(np.isfinite(norm) & (norm > 0))
    if np.any(bad):
        index = tuple(int(i) for i in np.argwhere(bad[..., 0])[0])
        raise InputError(f"direction at index {index} is zero or not finite: {v[index]}")
    return v / norm


def angles_from_direction(directions: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Azimuth in [0, 2 pi) and inclination in [0, pi], radians, of directions (..., 3).

    The directions need not be unit length.
    """
    d = normalize(directions)
    azimuth = np.mod(np.arctan2(d[..., 1], d[..., 0]), 2 * np.pi)
    inclination = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    return azimuth, inclination


def angles_deg_from_direction(directions: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Azimuth in [0, 360) and inclination in [0, 180], degrees, of directions (..., 3)."""
    azimuth, inclination = angles_from_direction(directions)
    return np.mod(np.rad2deg(azimuth), 360.0), np.rad2deg(inclination)


def angle_between(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Angle in radians between directions a and b (..., 3), broadcast; exact near 0 and pi."""
    u = normalize(a)
    v = normalize(b)
    # atan2 of |u x v| and u.v keeps full precision for tiny and near-opposite angles,
    # where arccos of the dot product loses half the digits.
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))


def _check_panorama_size(height: int, width: int) -> None:
    if height < 1 or width != 2 * height:
        raise InputError(f"an equirectangular panorama must be W = 2H pixels, got {width}x{height}")


def panorama_inclinations(height: int) -> FloatArray:
    """Inclination in radians of the centre of each panorama row; shape (H,)."""
    return np.pi * (np.arange(height, dtype=np.float64) + 0.5) / height


def panorama_azimuths(width: int) -> FloatArray:
    """Azimuth in radians (in (-pi, pi]) of the centre of each panorama column; shape (W,)."""
    return np.pi - 2.0 * np.pi * (np.arange(width, dtype=np.float64) + 0.5) / width


def panorama_directions(height: int, width: int) -> FloatArray:
    """Unit direction of every panorama pixel centre; shape (H, W, 3), float64."""
    _check_panorama_size(height, width)
    return direction_from_angles(
        panorama_azimuths(width)[None, :], panorama_inclinations(height)[:, None]
    )


def panorama_row_solid_angles(height: int, width: int) -> FloatArray:
    """Solid angle in steradians of one pixel of each row; shape (H,).

    A pixel of row i spans (2 pi / W)(cos theta_top - cos theta_bottom); the map sums to 4 pi.
    """
    _check_panorama_size(height, width)
    edges = np.cos(np.pi * np.arange(height + 1, dtype=np.float64) / height)
    return (2.0 * np.pi / width) * (edges[:-1] - edges[1:])


def panorama_solid_angles(height: int, width: int) -> FloatArray:
    """Solid angle in steradians of every pixel; shape (H, W) (a broadcast, read-only view)."""
    return np.broadcast_to(panorama_row_solid_angles(height, width)[:, None], (height, width))


def panorama_pixel_from_direction(
    directions: ArrayLike, height: int, width: int
) -> tuple[FloatArray, FloatArray]:
    """Continuous (row, col) panorama coordinates of directions (..., 3).

    Pixel centres are at integer coordinates; ``col`` is wrapped into [-0.5, W - 0.5).
    """
    _check_panorama_size(height, width)
    azimuth, inclination = angles_from_direction(directions)
    row = inclination * height / np.pi - 0.5
    col = np.mod((np.pi - azimuth) * width / (2.0 * np.pi), width) - 0.5
    return row, col


@numba.njit(cache=True, inline="always")
def panorama_bilinear_cell(
    x: float, y: float, z: float, yaw: float, height: int, width: int
) -> tuple[int, int, int, int, float, float]:
    """The bilinear cell of a direction in a panorama turned by ``yaw``: a numba kernel's lookup.

    The scalar, numba-callable twin of :func:`panorama_pixel_from_direction` (same mapping)
    for the kernels that read a panorama (or maps of it) per direction: the direction
    (x, y, z), unit, is turned back by ``yaw`` (radians, counter-clockwise seen from above;
    the panorama is held at yaw 0). Returns rows r0, r1 = r0 + 1, columns c0, c1 and the
    fractions (row - r0, col - c0); columns wrap, rows clamp to the panorama.
    """
    azimuth = math.atan2(y, x) - yaw
    inclination = math.acos(min(1.0, max(-1.0, z)))
    col = ((math.pi - azimuth) * width / (2.0 * math.pi)) % width - 0.5
    row = min(max(inclination * height / math.pi - 0.5, 0.0), height - 1.0)
    c0 = math.floor(col)
    r0 = min(int(row), height - 2)
    return r0, r0 + 1, int(c0) % width, (int(c0) + 1) % width, row - r0, col - c0


def panorama_pixel_index(
    directions: ArrayLike, height: int, width: int
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Integer (row, col) of the panorama pixel that contains each direction (..., 3)."""
    row, col = panorama_pixel_from_direction(directions, height, width)
    rows = np.clip(np.floor(row + 0.5), 0, height - 1).astype(np.intp)
    cols = np.mod(np.floor(col + 0.5), width).astype(np.intp)
    return rows, cols


def panorama_pixel_points(
    rows: ArrayLike, cols: ArrayLike, u: ArrayLike, v: ArrayLike, height: int, width: int
) -> FloatArray:
    """Directions inside panorama pixels, uniform in solid angle for uniform ``u``, ``v``.

    Parameters
    ----------
    rows, cols : array_like of int, pixel indices
    u, v : array_like in [0, 1), position across the pixel's azimuth and cos(inclination) spans
    height, width : int, panorama size

    Returns
    -------
    ndarray, shape (..., 3), float64
    """
    _check_panorama_size(height, width)
    r = np.asarray(rows, dtype=np.float64)
    cos_top = np.cos(np.pi * r / height)
    cos_bottom = np.cos(np.pi * (r + 1.0) / height)
    cos_theta = cos_top + (cos_bottom - cos_top) * np.asarray(v, dtype=np.float64)
    azimuth = np.pi - 2.0 * np.pi * (np.asarray(cols, dtype=np.float64) + np.asarray(u)) / width
    return direction_from_angles(azimuth, np.arccos(np.clip(cos_theta, -1.0, 1.0)))


def rotate_directions_yaw(directions: ArrayLike, yaw_deg: float) -> FloatArray:
    """Rotate directions (..., 3) about ``+z`` by ``yaw_deg`` (counter-clockwise from above)."""
    d = np.asarray(directions, dtype=np.float64)
    c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return d @ rotation.T


def rotate_panorama_yaw(image: NDArray[np.floating], yaw_deg: float) -> NDArray[np.floating]:
    """Rotate an environment about ``+z`` by ``yaw_deg`` (counter-clockwise seen from above).

    Light that arrived from azimuth phi arrives from phi + yaw afterwards. Whole-pixel shifts are
    exact; fractional shifts interpolate linearly between neighbouring columns, which keeps every
    row's sum (and so the total energy) unchanged.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    yaw_deg : float, degrees

    Returns
    -------
    ndarray, same shape and dtype as ``image``
    """
    width = image.shape[1]
    shift = (yaw_deg / 360.0) * width  # columns to the left
    whole = int(np.floor(shift))
    frac = shift - whole
    # new[:, j] = old[:, j + shift]
    base = np.roll(image, -whole, axis=1)
    if frac == 0.0:
        return base
    following = np.roll(base, -1, axis=1)
    return ((1.0 - frac) * base + frac * following).astype(image.dtype, copy=False)


def farthest_point_order(directions: ArrayLike, *, seed: int = 0) -> NDArray[np.int64]:
    """The N directions (N, 3) in farthest-point order: indices (N,) int64.

    The first is drawn with ``seed``; each next one is the farthest from those before it, so
    any prefix of the order is spread over the set.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if not len(d):
        return np.zeros(0, dtype=np.int64)
    first = int(np.random.default_rng(seed).integers(len(d)))
    order = [first]
    distance = np.linalg.norm(d - d[first], axis=1)
    distance[first] = -1.0
    for _ in range(len(d) - 1):
        nxt = int(np.argmax(distance))
        order.append(nxt)
        distance = np.minimum(distance, np.linalg.norm(d - d[nxt], axis=1))
        distance[order] = -1.0
    return np.asarray(order, dtype=np.int64)


#: Seeds :func:`spread_partition` tries.
PARTITION_TRIES = 8


def spread_partition(directions: ArrayLike, count: int, *, seed: int = 0) -> NDArray[np.int64]:
    """Each of N directions (N, 3) dealt into one of ``count`` groups, each group spread: (N,).

    Directions are taken in farthest-point order (:func:`farthest_point_order`) and each goes
    to the group, among those not yet full (sizes differ by at most one), whose nearest member
    is farthest from it: a group's members are rarely each other's neighbours, so holding a
    group out leaves gaps of about the set's own spacing. Of the orders started by
    :data:`PARTITION_TRIES` seeds from ``seed``, the partition whose closest pair within a
    group is farthest apart is kept.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if count < 1:
        raise InputError(f"a partition needs 1 group or more, got {count}")
    best, closest = np.zeros(len(d), dtype=np.int64), -1.0
    for start in range(seed, seed + PARTITION_TRIES):
        group, pair = _partition(d, count, start)
        if pair > closest:
            best, closest = group, pair
    return best


def _partition(d: FloatArray, count: int, seed: int) -> tuple[NDArray[np.int64], float]:
    """One greedy partition (:func:`spread_partition`) and its closest pair within a group."""
    group = np.full(len(d), -1, dtype=np.int64)
    nearest = np.full((count, len(d)), np.inf)  # each group's distance to each direction
    size = np.zeros(count, dtype=np.int64)
    full = -(-len(d) // count)
    pair = math.inf
    for index in farthest_point_order(d, seed=seed):
        score = np.where(size < full, nearest[:, index], -np.inf)
        best = np.flatnonzero(score == score.max())
        g = int(best[np.argmin(size[best])])
        group[index] = g
        size[g] += 1
        pair = min(pair, float(nearest[g, index]))
        nearest[g] = np.minimum(nearest[g], np.linalg.norm(d - d[index], axis=1))
    return group, pair


#: Azimuth step of the spherical Fibonacci lattice, radians (the golden angle).
GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def fibonacci_sphere(count: int) -> FloatArray:
    """``count`` near-uniform unit vectors over the whole sphere (spherical Fibonacci lattice).

    Point i sits at azimuth i x golden angle and z = 1 - (2 i + 1) / count; shape (count, 3).
    """
    if count < 1:
        raise InputError(f"a lattice needs at least one direction, got {count}")
    i = np.arange(count, dtype=np.float64) + 0.5
    return direction_from_angles(GOLDEN_ANGLE * (i - 0.5), np.arccos(1.0 - 2.0 * i / count))


def hemisphere_layout(count: int, layout: str = "grid") -> FloatArray:
    """``count`` directions over the upper hemisphere (inclination below 90 degrees).

    Parameters
    ----------
    count : int, >= 1
    layout : {"grid", "fibonacci"}
        ``grid``: rings of equal inclination step (centres at (i + 0.5) 90 / rings degrees), the
        count shared among rings in proportion to sin(inclination) and spread evenly in azimuth
        (rings = round(sqrt(count / 2))), as a gantry sweeps them; ``fibonacci``: the
        near-uniform spherical Fibonacci lattice restricted to z > 0.

    Returns
    -------
    ndarray, shape (count, 3), float64
    """
    if count < 1:
        raise InputError(f"a layout needs at least one direction, got {count}")
    i = np.arange(count, dtype=np.float64) + 0.5
    if layout == "fibonacci":
        return direction_from_angles(GOLDEN_ANGLE * i, np.arccos(1.0 - i / count))
    if layout != "grid":
        raise InputError(f"unknown layout {layout!r}; use 'grid' or 'fibonacci'")
    rings = max(1, round(float(np.sqrt(count / 2.0))))
    inclination = (np.arange(rings) + 0.5) * (0.5 * np.pi / rings)
    share = np.sin(inclination) / np.sin(inclination).sum() * count
    per_ring = np.floor(share).astype(int)
    # Hand out the remainder to the rings that lost the most to rounding.
    for ring in np.argsort(per_ring - share)[: count - per_ring.sum()]:
        per_ring[ring] += 1
    azimuths = [
        2.0 * np.pi * (np.arange(n) + 0.5 * (r % 2)) / n for r, n in enumerate(per_ring) if n
    ]
    inclinations = [np.full(n, inclination[r]) for r, n in enumerate(per_ring) if n]
    return direction_from_angles(np.concatenate(azimuths), np.concatenate(inclinations))
