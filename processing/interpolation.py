"""Interpolation weights over measured directions (lights or cameras) for query directions.

A reflectance field is measured at a few directions (unit vectors, rig frame, pointing from the
object toward the light or the camera). Relighting needs, for every query direction (a sampled
environment light, a panorama pixel, the wanted view), sparse weights over the measured ones:
``value(query) = sum_j weights[q, j] * value[indices[q, j]]``. Four schemes
(``docs/interpolation.md``):

``paper``
    The paper's section 4.1, eq. 1, literally: the m nearest measured directions by angle, each
    weighted by the cosine of its angle to the query, normalised to sum 1. Not interpolating: a
    query equal to a measured direction still blends its m - 1 neighbours in.
``nearest``
    The single nearest measured direction.
``barycentric``
    Planar barycentric coordinates of the point where the query ray crosses the flat (chord)
    triangle that contains it, in a spherical Delaunay triangulation of the measured set
    (:class:`processing.measured_region.MeasuredRegion`). Exact at measured directions, linear
    along edges, continuous.
``rbf``
    A Gaussian in angle over the 8 nearest, lowered by its value at the 9th nearest so that the
    weights stay continuous as the query moves, normalised.

Outside the measured region. The region is the spherical convex hull of the measured directions
(for a rig's upper-hemisphere set: everything above the polygon of its lowest lights; below the
horizon is always outside). Every result flags the queries outside it (``outside``), so callers
can measure how much light or view it concerns, and a policy handles them: ``clamp`` (default)
moves the query to the nearest point of the region (barycentric: weights on the two ends of the
nearest boundary edge, or on one corner; the other methods already pick the nearest measured
directions), ``zero`` gives them all-zero weights (their light is dropped). The region, its
triangulation and the clamp are :mod:`processing.measured_region`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from core.directions import (
    angle_between,
    angles_deg_from_direction,
    direction_from_angles,
    direction_from_angles_deg,
)
from core.errors import InputError
from processing.measured_region import DUPLICATE_CHORD, MeasuredRegion

__all__ = [
    "METHODS",
    "POLICIES",
    "RBF_NEIGHBOURS",
    "DirectionWeights",
    "InterpolationMethod",
    "OutsidePolicy",
    "interpolation_weights",
    "mean_spacing_deg",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Interpolation schemes of :func:`interpolation_weights`.
InterpolationMethod = Literal["paper", "nearest", "barycentric", "rbf"]
METHODS: tuple[InterpolationMethod, ...] = get_args(InterpolationMethod)
#: Handling of queries outside the measured region.
OutsidePolicy = Literal["clamp", "zero"]
POLICIES: tuple[OutsidePolicy, ...] = get_args(OutsidePolicy)
#: Measured directions an ``rbf`` weight row spans (one more sets the kernel's zero level).
RBF_NEIGHBOURS = 8
#: Up to this many measured directions, neighbours are found by trying each (faster than a
#: k-d tree's query for the queries of a view or a panorama).
BRUTE_FORCE_LIMIT = 64


@dataclass(frozen=True)
class DirectionWeights:
    """Sparse weights of Q query directions over N measured directions.

    Attributes
    ----------
    indices : ndarray, shape (Q, k), int64
        Measured directions each query uses; always valid indices (unused slots repeat one).
    weights : ndarray, shape (Q, k), float64
        Their weights, >= 0; each row sums to 1, except rows of outside queries under the
        ``zero`` policy, which are all 0. Unused slots have weight 0.
    outside : ndarray, shape (Q,), bool
        Queries outside the measured region (the spherical convex hull of the measured set).
    """

    indices: IntArray
    weights: FloatArray
    outside: NDArray[np.bool_]

    def __post_init__(self) -> None:
        if self.indices.ndim != 2 or self.weights.shape != self.indices.shape:
            raise InputError(
                f"indices and weights must have one shape (Q, k), got {self.indices.shape} "
                f"and {self.weights.shape}"
            )
        if self.outside.shape != self.indices.shape[:1]:
            raise InputError(
                f"outside must have shape ({self.indices.shape[0]},), got {self.outside.shape}"
            )

    def _check_count(self, count: int, what: str) -> None:
        needed = int(self.indices.max()) + 1 if self.indices.size else 0
        if count < needed:
            raise InputError(f"{what} has {count} measured directions; the weights use {needed}")

    def dense(self, count: int) -> FloatArray:
        """The weights as a dense matrix of shape (Q, count), float64 (count >= N)."""
        self._check_count(count, "dense matrix")
        rows = np.arange(self.indices.shape[0], dtype=np.int64)[:, None]
        flat = (rows * count + self.indices).ravel()
        size = self.indices.shape[0] * count
        dense = np.bincount(flat, weights=self.weights.ravel(), minlength=size)
        return dense.astype(np.float64, copy=False).reshape(self.indices.shape[0], count)

    def apply(self, values: ArrayLike) -> FloatArray:
        """Interpolate per-direction values of shape (N, ...) to the queries: (Q, ...), float64."""
        v = np.asarray(values)
        if v.ndim < 1:
            raise InputError(f"values must have shape (N, ...), got a scalar {v!r}")
        self._check_count(v.shape[0], f"values of shape {v.shape}")
        out = np.zeros(self.indices.shape[:1] + v.shape[1:], dtype=np.float64)
        expand = (slice(None),) + (None,) * (v.ndim - 1)
        for j in range(self.indices.shape[1]):
            out += self.weights[:, j][expand] * v[self.indices[:, j]]
        return out


def interpolation_weights(
    measured: ArrayLike,
    queries: ArrayLike,
    method: InterpolationMethod,
    *,
    m: int = 3,
    width_deg: float | None = None,
    policy: OutsidePolicy = "clamp",
) -> DirectionWeights:
    """Weights of each query direction over the measured directions.

    Parameters
    ----------
    measured : array_like, shape (N, 3)
        Measured directions (rig frame; normalised here). N >= 1, no zero, non-finite or
        duplicate (closer than 1e-9 rad) directions.
    queries : array_like, shape (Q, 3)
        Query directions (normalised here); Q may be 0.
    method : {"paper", "nearest", "barycentric", "rbf"}
        See the module docstring. Weight columns k: ``paper`` min(m, N), ``nearest`` 1,
        ``barycentric`` 3, ``rbf`` min(8, N).
    m : int, >= 1
        Neighbours of the ``paper`` method (capped at N); the other methods ignore it.
    width_deg : float, optional, degrees in (0, 180]
        Standard deviation of the ``rbf`` Gaussian; default :func:`mean_spacing_deg` of the
        measured set (any width for N = 1). Only for ``rbf``.
    policy : {"clamp", "zero"}
        Queries outside the measured region: ``clamp`` moves them to its nearest point,
        ``zero`` gives them zero weights. Either way they are flagged in ``outside``.

    Returns
    -------
    DirectionWeights
        ``indices`` (Q, k) int64, ``weights`` (Q, k) float64, ``outside`` (Q,) bool.

    Raises
    ------
    InputError
        Bad shapes, zero or non-finite vectors, duplicate measured directions, m < 1, an
        unknown method or policy, a width out of range or given to another method.
    """
    if method not in METHODS:
        raise InputError(f"unknown interpolation method {method!r}; use one of {METHODS}")
    if policy not in POLICIES:
        raise InputError(f"unknown outside policy {policy!r}; use one of {POLICIES}")
    if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 1:
        raise InputError(f"m (neighbours of the paper method) must be an integer >= 1, got {m!r}")
    if width_deg is not None and method != "rbf":
        raise InputError(f"width_deg applies to method 'rbf' only, got it for {method!r}")
    points, tree = _measured(measured)
    q = _unit_rows(queries, "queries", "query", "Q", allow_empty=True)
    region = MeasuredRegion.build(points)
    if method == "barycentric":
        return DirectionWeights(*region.barycentric(q, clamp=policy == "clamp"))
    if method == "paper":
        indices, weights = _paper(tree, q, int(m), len(points))
    elif method == "nearest":
        indices, weights = _nearest(tree, q)
    else:
        if width_deg is None:
            width = _mean_spacing(tree) if len(points) > 1 else 1.0
        else:
            width = _width_radians(width_deg)
        indices, weights = _rbf(tree, q, len(points), width)
    outside = region.outside(q)
    if policy == "zero":
        weights[outside] = 0.0
    return DirectionWeights(indices, weights, outside)


def mean_spacing_deg(measured: ArrayLike) -> float:
    """Mean angle, in degrees, from each measured direction to its nearest neighbour.

    Parameters
    ----------
    measured : array_like, shape (N, 3), N >= 2 (normalised here)

    Returns
    -------
    float, degrees
    """
    points, tree = _measured(measured)
    if len(points) < 2:
        raise InputError(f"the spacing of a set needs two directions or more, got {len(points)}")
    spacing = _mean_spacing(tree)
    return float(angles_deg_from_direction(direction_from_angles(0.0, spacing))[1])


# --- input ------------------------------------------------------------------------------------


def _unit_rows(
    value: ArrayLike, name: str, item: str, letter: str, *, allow_empty: bool
) -> FloatArray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name} must be an array of shape ({letter}, 3): {error}") from None
    least = 0 if allow_empty else 1
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < least:
        raise InputError(
            f"{name} must have shape ({letter}, 3) with {letter} >= {least}, got {a.shape}"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.linalg.norm(a, axis=1)
    bad = np.flatnonzero(~(np.isfinite(norm) & (norm > 0)))
    if bad.size:
        raise InputError(
            f"{item} direction {int(bad[0])} is zero or not finite: {a[bad[0]].tolist()}"
        )
    return a / norm[:, None]


def _measured(measured: ArrayLike) -> tuple[FloatArray, Any]:
    points = _unit_rows(measured, "measured", "measured", "N", allow_empty=False)
    return _measured_tree(points.tobytes(), len(points))


@functools.lru_cache(maxsize=64)
def _measured_tree(data: bytes, count: int) -> tuple[FloatArray, Any]:
    """The unit directions held in ``data`` (read-only) and their tree, duplicates refused.

    Kept for the next call: a fit and the rung choices ask for one light set's weights
    thousands of times (per predicted light, per held-out light).
    """
    points = np.frombuffer(data, dtype=np.float64).reshape(count, 3)
    tree = cKDTree(points)
    if len(points) > 1:
        chord, other = tree.query(points, k=2)
        close = np.flatnonzero(chord[:, 1] < DUPLICATE_CHORD)
        if close.size:
            i = int(close[0])
            j = int(other[i, 1]) if int(other[i, 1]) != i else int(other[i, 0])
            raise InputError(
                f"measured directions {min(i, j)} and {max(i, j)} coincide: {points[i].tolist()}"
            )
    return points, tree


def _width_radians(width_deg: float) -> float:
    try:
        w = float(width_deg)
    except (TypeError, ValueError):
        w = math.nan
    if not (math.isfinite(w) and 0.0 < w <= 180.0):
        raise InputError(f"width_deg must be in (0, 180] degrees, got {width_deg!r}")
    return float(angle_between((0.0, 0.0, 1.0), direction_from_angles_deg(0.0, w)))


def _mean_spacing(tree: Any) -> float:
    chord, _ = tree.query(tree.data, k=2)
    return float(np.mean(_chord_angle(chord[:, 1])))


def _chord_angle(chord: FloatArray) -> FloatArray:
    return 2.0 * np.arcsin(np.minimum(0.5 * chord, 1.0))


def _knn(tree: Any, queries: FloatArray, k: int) -> tuple[FloatArray, IntArray]:
    shape = (queries.shape[0], k)
    if tree.n <= BRUTE_FORCE_LIMIT:
        chord, index = np.empty(shape), np.empty(shape, dtype=np.int64)
        _knn_brute(np.ascontiguousarray(tree.data), queries, chord, index)
        return chord, index
    chord, index = tree.query(queries, k=k, workers=-1)
    return np.reshape(chord, shape), np.reshape(index, shape).astype(np.int64)


@numba.njit(cache=True, parallel=True)
def _knn_brute(
    measured: FloatArray, queries: FloatArray, chord: FloatArray, index: IntArray
) -> None:
    # The k nearest by chord, ascending (the lower index first on a tie), by trying every
    # measured direction: for a rig's few cameras a tree's query cost 27 ms of a 250k-sample
    # view's blend, this 2.
    k = chord.shape[1]
    for q in numba.prange(queries.shape[0]):
        for j in range(k):
            chord[q, j] = np.inf
            index[q, j] = 0
        for m in range(measured.shape[0]):
            dx = queries[q, 0] - measured[m, 0]
            dy = queries[q, 1] - measured[m, 1]
            dz = queries[q, 2] - measured[m, 2]
            d = dx * dx + dy * dy + dz * dz  # squared here; the k kept get their root below
            if d < chord[q, k - 1]:
                j = k - 1
                while j > 0 and chord[q, j - 1] > d:
                    chord[q, j] = chord[q, j - 1]
                    index[q, j] = index[q, j - 1]
                    j -= 1
                chord[q, j] = d
                index[q, j] = m
        for j in range(k):
            chord[q, j] = math.sqrt(chord[q, j])


# --- the kNN methods --------------------------------------------------------------------------


def _paper(tree: Any, queries: FloatArray, m: int, count: int) -> tuple[IntArray, FloatArray]:
    # Eq. 1: w_t = cos(angle(query, t)) over the m nearest t, normalised; cosines below 0 (more
    # than 90 degrees away) count 0, and a query with all m beyond 90 degrees takes the nearest.
    # For unit vectors at chord distance c, cos(angle) = 1 - c^2 / 2 exactly.
    chord, index = _knn(tree, queries, min(m, count))
    cosine = np.maximum(1.0 - 0.5 * chord * chord, 0.0)
    total = cosine.sum(axis=1)
    none = total <= 0.0
    cosine[none, 0] = 1.0
    total[none] = 1.0
    return index, cosine / total[:, None]


def _nearest(tree: Any, queries: FloatArray) -> tuple[IntArray, FloatArray]:
    _, index = _knn(tree, queries, 1)
    return index, np.ones(index.shape)


def _rbf(tree: Any, queries: FloatArray, count: int, width: float) -> tuple[IntArray, FloatArray]:
    # g_i = exp(-angle_i^2 / (2 width^2)), taken relative to the nearest (no underflow far from
    # the set) and lowered by g at the (k+1)-th nearest, so a direction enters or leaves the k
    # nearest with weight 0 and the weights are continuous in the query.
    k = min(RBF_NEIGHBOURS, count)
    chord, index = _knn(tree, queries, min(k + 1, count))
    angle = _chord_angle(chord)
    g = np.exp(-(angle**2 - angle[:, :1] ** 2) / (2.0 * width * width))
    weights = g[:, :k] - g[:, k:] if g.shape[1] > k else g.copy()
    total = weights.sum(axis=1)
    tied = total < 1e-9  # the k+1 nearest (nearly) equidistant: keep the plain Gaussian
    weights[tied] = g[tied, :k]
    total[tied] = weights[tied].sum(axis=1)
    return index[:, :k], weights / total[:, None]
