"""Visibility beyond the measured lights (point fields), from the point cloud's shadow maps.

Shadow marks from the point cloud's own shadow maps, completing the fitted marks with them, and
scoring them against the measured ones.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from core.directions import fibonacci_sphere
from core.errors import InputError
from core.point_spacing import median_neighbour_distance
from core.splat import depth_at_points, zbuffer
from processing.interpolation import interpolation_weights
from processing.sample_models.fits import Fit, ParametricFit, ParametricModelName, SampleModels
from processing.sample_models.loo import leave_one_out_weights

__all__ = ["geometric_shadow_marks", "shadow_mark_errors", "with_geometric_visibility"]

#: Geometric shadow maps: cells per point spacing, splat radius (cells), depth bias (spacings),
#: largest map side (cells).
SHADOW_MAP_CELLS, SHADOW_SPLAT_CELLS, SHADOW_BIAS, SHADOW_MAP_MAX = 1.5, 1.5, 2.0, 4096
#: Directions (a Fibonacci sphere) of the geometric shadow marks that complete the measured ones.
GEOMETRY_DIRECTIONS = 512


def geometric_shadow_marks(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    directions: NDArray[np.floating],
    spacing: float | None = None,
) -> NDArray[np.uint8]:
    """Shadow marks of every point for directional lights, from the point cloud's own geometry.

    One orthographic shadow map per direction: the points as disks one spacing wide in a
    z-buffer seen from the light (``core.splat``), a point lit when it is no deeper than the
    front surface plus a slope-scaled bias. Marks follow the fitted ones' convention: 1 lit
    or facing away (the attached shadow is the model's cosine), 0 shadowed.

    Parameters
    ----------
    points, normals : ndarray, shape (P, 3), rig frame (normals unit, outward)
    directions : ndarray, shape (G, 3), unit vectors toward the lights
    spacing : float, optional, surface distance between neighbouring points (default: the
        median nearest-neighbour distance)

    Returns
    -------
    ndarray, shape (P, G), uint8 (1 lit, 0 shadowed)
    """
    cloud = np.asarray(points, dtype=np.float64)
    normal = np.asarray(normals, dtype=np.float64)
    toward = np.asarray(directions, dtype=np.float64)
    if cloud.ndim != 2 or cloud.shape[1] != 3 or normal.shape != cloud.shape or len(cloud) < 2:
        raise InputError(
            f"points and normals must be (P, 3) with P >= 2, got {cloud.shape}, {normal.shape}"
        )
    if toward.ndim != 2 or toward.shape[1] != 3:
        raise InputError(f"shadow directions must be (G, 3), got {toward.shape}")
    gap = median_neighbour_distance(cloud, 20_000) if spacing is None else float(spacing)
    if not gap > 0:
        raise InputError(f"point spacing must be positive, got {gap}")
    marks = np.ones((len(cloud), len(toward)), dtype=np.uint8)
    for g, direction in enumerate(toward / np.linalg.norm(toward, axis=1, keepdims=True)):
        helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0, 1.0, 0])
        a = np.cross(direction, helper)
        a /= np.linalg.norm(a)
        b = np.cross(direction, a)
        depth = -(cloud @ direction)  # distance along the light, up to a constant
        depth -= depth.min() - 1.0
        cols = (cloud @ a - (cloud @ a).min()) / gap * SHADOW_MAP_CELLS + 2.0
        rows = (cloud @ b - (cloud @ b).min()) / gap * SHADOW_MAP_CELLS + 2.0
        radius = np.full(len(cloud), SHADOW_SPLAT_CELLS)
        width, height = int(np.ceil(cols.max())) + 3, int(np.ceil(rows.max())) + 3
        if max(width, height) > SHADOW_MAP_MAX:
            shrink = SHADOW_MAP_MAX / max(width, height)
            cols, rows = cols * shrink, rows * shrink
            radius = np.maximum(radius * shrink, 0.75)
            width, height = int(width * shrink) + 1, int(height * shrink) + 1
        front = depth_at_points(cols, rows, zbuffer(cols, rows, depth, radius, height, width))
        cosine = normal @ direction
        # A neighbour one spacing away on the same tilted surface is spacing x tan(theta)
        # nearer the light: the bias grows with the slope.
        clipped = np.clip(cosine, 0.05, 1.0)
        slope = np.sqrt(1.0 - clipped**2) / clipped
        lit = depth <= front + SHADOW_BIAS * gap * (1.0 + slope)
        marks[:, g] = np.where(cosine > 0, lit, True)
    return marks


def with_geometric_visibility(
    models: SampleModels,
    normals: NDArray[np.floating],
    *,
    count: int = GEOMETRY_DIRECTIONS,
    everywhere: bool = False,
    spacing: float | None = None,
) -> SampleModels:
    """Complete the fitted shadow marks with geometric ones where no light was measured.

    The measured marks know the shadows only at the T measured lights; relighting interpolates
    them, and beyond the measured region (below the lowest ring, below the horizon) it could
    only clamp. This adds the marks of :func:`geometric_shadow_marks` at the directions of a
    ``count``-point Fibonacci sphere outside the measured region (``everywhere``: all of them,
    sharpening shadow edges between the measured lights too), so the marks cover the whole
    sphere. Measured marks keep their place at the measured lights.

    Parameters
    ----------
    models : SampleModels of a point field
    normals : ndarray, shape (P, 3), the field's stored normals (the shadow maps' slope bias)
    count : int, directions of the Fibonacci sphere
    everywhere : bool, also inside the measured region
    spacing : float, optional, point spacing (default: median nearest-neighbour distance)

    Returns
    -------
    SampleModels, with ``mark_directions`` (T + G, 3) and every parametric fit's ``lit``
    (P, T + G)
    """
    if models.points is None:
        raise InputError("geometric shadow marks need surface points; a pixel field has none")
    if models.mark_directions is not None:
        raise InputError("the models' shadow marks are completed already")
    if count < 1:
        raise InputError(f"geometric directions must be at least 1, got {count}")
    measured = models.light_directions
    candidates = fibonacci_sphere(count)
    if not everywhere:
        outside = interpolation_weights(measured, candidates, "nearest").outside
        candidates = candidates[outside]
    # Directions that (nearly) coincide with a measured light add nothing and would be refused
    # as duplicates by the triangulation.
    apart = np.min(np.arccos(np.clip(candidates @ measured.T, -1.0, 1.0)), axis=1) > 1e-3
    candidates = candidates[apart]
    marks = geometric_shadow_marks(models.points, normals, candidates, spacing)
    fits: dict[str, Fit] = {}
    for name, fit in models.fits.items():
        if isinstance(fit, ParametricFit):
            fit = replace(fit, lit=np.ascontiguousarray(np.concatenate([fit.lit, marks], axis=1)))
        fits[name] = fit
    return replace(
        models, fits=fits, mark_directions=np.concatenate([measured, candidates], axis=0)
    )


def shadow_mark_errors(
    models: SampleModels,
    normals: NDArray[np.floating],
    *,
    name: ParametricModelName | None = None,
    spacing: float | None = None,
) -> dict[str, float]:
    """How well each visibility predictor recovers the measured shadow marks of held-out lights.

    For every fitted sample and measured light in front of it, the measured mark is predicted
    (a) by interpolating the other lights' marks (barycentric, leave one light out: what
    relighting does between measured lights) and (b) by the geometric shadow map of
    :func:`geometric_shadow_marks`. The score is the mean absolute difference from the
    measured mark; the better predictor is the one to trust where nothing was measured.

    Parameters
    ----------
    models : SampleModels of a point field
    normals : ndarray, shape (P, 3), the stored normals
    name : {"lambert", "lambert+ggx"}, optional, the fitted parametric model whose marks are
        the reference (default: the last parametric fit in fitting order, ``lambert+ggx``
        in the default order)
    spacing : float, optional, point spacing of the shadow maps

    Returns
    -------
    dict with "interpolated" and "geometry" (mean absolute mark error, 0..1) and "compared"
    (the number of sample-light pairs)
    """
    if models.points is None:
        raise InputError("shadow marks of a pixel field have no geometry to compare with")
    parametric = [n for n, f in models.fits.items() if isinstance(f, ParametricFit)]
    if not parametric:
        raise InputError("no parametric model was fitted: there are no shadow marks")
    fit = models.fit(name if name is not None else parametric[-1])
    assert isinstance(fit, ParametricFit)
    lights = models.light_directions
    t_count = len(lights)
    measured = fit.lit[:, :t_count]
    indices, weights = leave_one_out_weights(lights)
    interpolated = np.einsum("tj,ptj->pt", weights, measured[:, indices])
    geometry = geometric_shadow_marks(models.points, normals, lights, spacing)
    facing = (np.asarray(normals, dtype=np.float64) @ lights.T > 0) & fit.fitted[:, None]
    compared = int(facing.sum())
    if compared == 0:
        return {"interpolated": 0.0, "geometry": 0.0, "compared": 0.0}
    return {
        "interpolated": float(np.abs(interpolated - measured)[facing].mean()),
        "geometry": float(np.abs(geometry.astype(np.float32) - measured)[facing].mean()),
        "compared": float(compared),
    }
