"""Light disassembling: gather all of a panorama's light into K sampled directions.

Every panorama pixel is assigned to its nearest sample by angle (a spherical Voronoi
decomposition, the paper's section 4.3, eq. 4), and each cell's light is gathered as
sum(radiance x pixel solid angle) per RGB channel. The total is the solid-angle integral of the
panorama, so no light is discarded, only redistributed.

The nearest-sample search prunes by blocks of pixels: a sample can be the nearest for some pixel
of a block only if its angle to the block centre is within the smallest such angle plus twice
the block's angular radius (triangle inequality). On an equirectangular grid the point of a block
farthest from its centre is one of its corners (the distance to points along a meridian is
unimodal), so the radius, and hence the pruning, is exact.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from core.directions import (
    panorama_azimuths,
    panorama_inclinations,
    panorama_row_solid_angles,
)
from core.errors import InputError
from core.light_set import LightSet

__all__ = ["disassemble_lights", "gather_cells", "nearest_sample_labels"]

BLOCK = 8  # pixels per block side for the pruned nearest-sample search


def _check_directions(directions: NDArray[Any]) -> NDArray[np.float64]:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] < 1:
        raise InputError(f"sample directions must have shape (K, 3) with K >= 1, got {d.shape}")
    norm = np.linalg.norm(d, axis=1)
    if not np.all(np.isfinite(norm) & (norm > 0)):
        raise InputError("sample directions contain zero or non-finite vectors")
    return d / norm[:, None]


def nearest_sample_labels(
    directions: NDArray[np.floating], height: int, width: int
) -> NDArray[np.int32]:
    """Index of the nearest sample (by angle) for every pixel of an H x W panorama.

    Parameters
    ----------
    directions : ndarray, shape (K, 3)
        Sample directions (normalised here).
    height, width : int
        Panorama size, W = 2H.

    Returns
    -------
    ndarray, shape (H, W), int32
    """
    if width != 2 * height or height < 1:
        raise InputError(f"panorama must be W = 2H pixels, got {width}x{height}")
    samples = _check_directions(directions)
    labels = np.empty((height, width), dtype=np.int32)
    theta_edges = np.pi * np.arange(height + 1, dtype=np.float64) / height
    phi = panorama_azimuths(width)
    _label_blocks(samples, panorama_inclinations(height), theta_edges, phi, BLOCK, labels)
    return labels


def disassemble_lights(rgb: NDArray[np.floating], directions: NDArray[np.floating]) -> LightSet:
    """Gather the light of a panorama into the Voronoi cells of sample directions.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3)
        Linear radiance of an equirectangular panorama, W = 2H.
    directions : ndarray, shape (K, 3)
        Sample directions (rig frame); need not be unit length.

    Returns
    -------
    LightSet
        ``rgb.sum(0)`` equals the solid-angle integral of the panorama to float64 rounding.
    """
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"panorama must have shape (H, W, 3), got {image.shape}")
    height, width = image.shape[:2]
    samples = _check_directions(directions)
    labels = nearest_sample_labels(samples, height, width)
    gathered, area = gather_cells(image, labels, samples.shape[0])
    return LightSet(directions=samples, rgb=gathered, solid_angle_sr=area, labels=labels)


def gather_cells(
    rgb: NDArray[np.floating], labels: NDArray[np.int32], count: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A panorama's light summed per cell: radiance x solid angle, and each cell's solid angle.

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), linear radiance
    labels : ndarray, shape (H, 2H), int32, each pixel's cell (:func:`nearest_sample_labels`)
    count : int, the cells

    Returns
    -------
    gathered : ndarray, shape (count, 3), float64, radiance x sr
    area : ndarray, shape (count,), float64, sr
    """
    height, width = labels.shape
    gathered = np.zeros((count, 3), dtype=np.float64)
    area = np.zeros(count, dtype=np.float64)
    omega = panorama_row_solid_angles(height, width)
    _gather(np.ascontiguousarray(rgb, dtype=np.float32), labels, omega, gathered, area)
    return gathered, area


@numba.njit(cache=True, parallel=True)
def _label_blocks(
    samples: NDArray[np.float64],
    theta: NDArray[np.float64],
    theta_edges: NDArray[np.float64],
    phi: NDArray[np.float64],
    block: int,
    labels: NDArray[np.int32],
) -> None:
    height, width = labels.shape
    k = samples.shape[0]
    sin_t, cos_t = np.sin(theta), np.cos(theta)
    cos_p, sin_p = np.cos(phi), np.sin(phi)
    step = 2.0 * np.pi / width
    n_block_rows = (height + block - 1) // block
    n_block_cols = (width + block - 1) // block
    for b in numba.prange(n_block_rows * n_block_cols):
        r0 = (b // n_block_cols) * block
        c0 = (b % n_block_cols) * block
        r1 = min(r0 + block, height)
        c1 = min(c0 + block, width)
        # Block bounds on the sphere: inclination edges, azimuth edges of its pixels.
        t_lo, t_hi = theta_edges[r0], theta_edges[r1]
        p_hi = phi[c0] + 0.5 * step
        p_lo = phi[c1 - 1] - 0.5 * step
        tc, pc = 0.5 * (t_lo + t_hi), 0.5 * (p_lo + p_hi)
        cx, cy, cz = math.sin(tc) * math.cos(pc), math.sin(tc) * math.sin(pc), math.cos(tc)
        radius = 0.0
        for t in (t_lo, t_hi):
            for p in (p_lo, p_hi):
                dot = (
                    cx * math.sin(t) * math.cos(p)
                    + cy * math.sin(t) * math.sin(p)
                    + cz * math.cos(t)
                )
                radius = max(radius, math.acos(min(1.0, max(-1.0, dot))))
        dots = np.empty(k)
        best_dot = -1.0
        for s in range(k):
            dots[s] = cx * samples[s, 0] + cy * samples[s, 1] + cz * samples[s, 2]
            best_dot = max(best_dot, dots[s])
        # Keep samples within (smallest angle + 2 radius) of the centre, compared as cosines.
        limit = math.acos(min(1.0, best_dot)) + 2.0 * radius + 1e-9
        floor = math.cos(limit) if limit < np.pi else -2.0
        candidates = np.empty(k, dtype=np.int64)
        n = 0
        for s in range(k):
            if dots[s] >= floor:
                candidates[n] = s
                n += 1
        for i in range(r0, r1):
            for j in range(c0, c1):
                px, py, pz = sin_t[i] * cos_p[j], sin_t[i] * sin_p[j], cos_t[i]
                nearest = -2.0
                label = 0
                for m in range(n):
                    s = candidates[m]
                    dot = px * samples[s, 0] + py * samples[s, 1] + pz * samples[s, 2]
                    if dot > nearest:
                        nearest = dot
                        label = s
                labels[i, j] = label


@numba.njit(cache=True)
def _gather(
    rgb: NDArray[np.float32],
    labels: NDArray[np.int32],
    omega: NDArray[np.float64],
    gathered: NDArray[np.float64],
    area: NDArray[np.float64],
) -> None:
    height, width = labels.shape
    for i in range(height):
        w = omega[i]
        for j in range(width):
            s = labels[i, j]
            gathered[s, 0] += rgb[i, j, 0] * w
            gathered[s, 1] += rgb[i, j, 1] * w
            gathered[s, 2] += rgb[i, j, 2] * w
            area[s] += w
