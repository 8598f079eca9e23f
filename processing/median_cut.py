"""Debevec's median-cut light-probe sampling, with solid-angle weights.

P. Debevec, "A Median Cut Algorithm for Light Probe Sampling", SIGGRAPH 2005 poster: split the
equirectangular image into regions of equal energy, always cutting a region across its longest
dimension (its width shrunk by sin(inclination), as on the sphere), and put one light at the
energy centroid of each region. Energy here is luminance x pixel solid angle, so regions have
equal light on the sphere rather than in image area.

Debevec splits every region once per round, giving 2^n regions. For other K the regions of the
shallowest depth are split first, the most energetic first, so K = 2^n is exactly his method.
"""

from __future__ import annotations

import heapq

import numpy as np
from numpy.typing import NDArray

from core.directions import panorama_directions, panorama_inclinations

__all__ = ["median_cut_regions", "median_cut_sample"]

Region = tuple[int, int, int, int]  # row0, row1, col0, col1 (half-open)


def median_cut_regions(energy: NDArray[np.floating], k: int) -> list[Region]:
    """Split an (H, W) energy image into ``k`` rectangles of (nearly) equal energy.

    Parameters
    ----------
    energy : ndarray, shape (H, W), non-negative (luminance x solid angle)
    k : int, number of regions wanted; at most H x W

    Returns
    -------
    list of (row0, row1, col0, col1), half-open pixel ranges
    """
    height, width = energy.shape
    sin_theta = np.sin(panorama_inclinations(height))
    heap: list[tuple[int, float, int, Region]] = []
    counter = 0
    heapq.heappush(heap, (0, -float(energy.sum()), counter, (0, height, 0, width)))
    done: list[Region] = []
    while heap and len(heap) + len(done) < k:
        depth, _, _, region = heapq.heappop(heap)
        halves = _split(energy, sin_theta, region)
        if halves is None:
            done.append(region)  # a single pixel cannot be split
            continue
        for half in halves:
            counter += 1
            r0, r1, c0, c1 = half
            heapq.heappush(heap, (depth + 1, -float(energy[r0:r1, c0:c1].sum()), counter, half))
    return done + [entry[3] for entry in heap]


def _split(
    energy: NDArray[np.floating], sin_theta: NDArray[np.float64], region: Region
) -> tuple[Region, Region] | None:
    r0, r1, c0, c1 = region
    rows, cols = r1 - r0, c1 - c0
    if rows * cols <= 1:
        return None
    # Angular extents: a column step spans 2 pi / W radians of azimuth, shrunk by sin(theta);
    # a row step spans pi / H = 2 pi / W radians of inclination.
    width_on_sphere = cols * float(sin_theta[(r0 + r1) // 2])
    across_columns = cols > 1 and (width_on_sphere >= rows or rows == 1)
    block = energy[r0:r1, c0:c1]
    profile = block.sum(axis=0) if across_columns else block.sum(axis=1)
    n = profile.size
    total = float(profile.sum())
    if total > 0:
        cut = int(np.searchsorted(np.cumsum(profile), 0.5 * total))
        cut = min(max(cut, 1), n - 1)  # both halves keep at least one pixel
    else:
        cut = n // 2
    if across_columns:
        return (r0, r1, c0, c0 + cut), (r0, r1, c0 + cut, c1)
    return (r0, r0 + cut, c0, c1), (r0 + cut, r1, c0, c1)


def median_cut_sample(energy: NDArray[np.floating], k: int) -> NDArray[np.float64]:
    """Directions (K, 3) of the energy centroids of ``k`` median-cut regions.

    A region without energy gets its geometric centre.
    """
    height, width = energy.shape
    directions = panorama_directions(height, width)
    centres = []
    for r0, r1, c0, c1 in median_cut_regions(energy, k):
        weights = np.asarray(energy[r0:r1, c0:c1], dtype=np.float64)
        block = directions[r0:r1, c0:c1]
        if weights.sum() > 0:
            centroid = np.einsum("ij,ijk->k", weights, block)
        else:
            centroid = block.reshape(-1, 3).sum(axis=0)
        norm = np.linalg.norm(centroid)
        centres.append(centroid / norm if norm > 0 else block[0, 0])
    return np.array(centres, dtype=np.float64)
