"""How far apart a cloud's surface points are: the one estimator every splat is sized by.

The simulator knows its surfaces' area and splats with sqrt(area / P); a scan or a field store
has only the points. :func:`point_spacing` estimates the same quantity from them, and
:func:`median_neighbour_distance` is the statistic it starts from (a shadow map's cell size is
set by it).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.errors import InputError

__all__ = ["DENSITY_RADIUS", "median_neighbour_distance", "point_spacing"]

#: The neighbourhood that measures the point density, in median nearest-neighbour distances.
DENSITY_RADIUS = 6.5


def _probe(cloud: NDArray[np.float64], sample: int, seed: int) -> NDArray[np.float64]:
    if len(cloud) < 2:
        raise InputError(f"a point cloud needs at least 2 points to splat, got {len(cloud)}")
    if not np.isfinite(cloud).all():
        bad = int((~np.isfinite(cloud).all(axis=1)).sum())
        raise InputError(f"the point cloud has {bad} points with NaN or infinite coordinates")
    rng = np.random.default_rng(seed)
    return cloud[rng.choice(len(cloud), size=min(sample, len(cloud)), replace=False)]


def median_neighbour_distance(
    points: NDArray[np.floating], sample: int = 2_000, seed: int = 0
) -> float:
    """Median distance from a point to its nearest neighbour, over a random subset.

    Parameters
    ----------
    points : ndarray, shape (P, 3), P >= 2
    sample : int, points of the subset the median is taken over
    seed : int, of the subset

    Returns
    -------
    float, scene units
    """
    cloud = np.asarray(points, dtype=np.float64)
    probe = _probe(cloud, sample, seed)
    distance, _ = cKDTree(cloud).query(probe, k=2)
    return float(np.median(distance[:, 1]))


def point_spacing(points: NDArray[np.floating], sample: int = 2_000, seed: int = 0) -> float:
    """The side of the surface area per point, sqrt(area / P), estimated from the points alone.

    Within a radius R of DENSITY_RADIUS median nearest-neighbour distances (not a whole
    number: a lattice has whole shells of neighbours there) a surface holds
    n(R) points on about pi R^2 of area, so the area per point is pi R^2 / n(R) (median over a
    random subset of ``sample`` points). This is the spacing the simulator splats with (it knows
    the area); the nearest-neighbour distance itself is about 5 % smaller on the near-uniform
    layouts of a capture, and splats that much smaller differ visibly at silhouettes and
    highlights (docs/models.md, "Splat size").

    Parameters
    ----------
    points : ndarray, shape (P, 3), P >= 2
    sample, seed : the random subset of points the medians are taken over

    Returns
    -------
    float, scene units
    """
    cloud = np.asarray(points, dtype=np.float64)
    probe = _probe(cloud, sample, seed)
    tree = cKDTree(cloud)
    distance, _ = tree.query(probe, k=2)
    nearest = float(np.median(distance[:, 1]))
    if not nearest > 0:
        raise InputError("the point cloud has coincident points; cannot estimate its spacing")
    radius = DENSITY_RADIUS * nearest
    counts = tree.query_ball_point(probe, radius, return_length=True)
    return float(np.sqrt(np.pi * radius**2 / np.median(counts)))
