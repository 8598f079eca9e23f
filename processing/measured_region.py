"""The measured region of a set of directions: its triangulation, barycentric weights and clamp.

The region is the spherical convex hull of the measured directions (for a rig's
upper-hemisphere set: everything above the polygon of its lowest lights; below the horizon is
always outside). :class:`MeasuredRegion` tells which queries lie outside it, gives the
``barycentric`` weights of :func:`processing.interpolation.interpolation_weights` (planar
barycentric coordinates of the point where the query ray crosses the flat (chord) triangle that
contains it) and clamps outside queries to the nearest point of the region (weights on the two
ends of the nearest boundary edge, or on one corner).

The triangulation is the convex hull of the measured directions together with the origin: its
faces that do not touch the origin tile the region (they are the spherical Delaunay triangles),
the faces through the origin are the region's bounding planes. Measured sets on one great circle
(or of one or two directions) have no triangles: their region is that arc (or those points),
and queries off it are outside.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError

__all__ = ["DUPLICATE_CHORD", "MeasuredRegion"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

DUPLICATE_CHORD = 1e-9
"""Measured directions closer than this (radians, as a chord) are duplicates; a query this close
to an arc region's arcs is on them."""

#: A hull face whose plane passes within this of the origin bounds the region (no triangle).
_PLANE = 1e-12
#: A query is inside a triangle when no barycentric coordinate is below -this x their sum.
_LAMBDA = 1e-10
#: Queries per block of the point-location kernel (each block walks from its last triangle).
_BLOCK = 256


@dataclass(frozen=True)
class MeasuredRegion:
    """The spherical convex hull of the measured set, triangulated.

    Attributes
    ----------
    vertices : ndarray, shape (N, 3), float64
        The measured directions (unit vectors).
    triangles : ndarray, shape (F, 3), int64
        Vertex indices of each triangle.
    inverse : ndarray, shape (F, 3, 3), float64
        The inverse of the matrix whose columns are a triangle's vertices (its barycentric
        coordinates of q are inverse @ q, up to scale).
    neighbours : ndarray, shape (F, 3), int64
        The triangle across the edge opposite each vertex, or -1 on the boundary.
    planes : ndarray, shape (C, 3), float64
        Outward normals of the bounding planes through the origin (q is outside when any
        n . q > 0).
    edges : ndarray, shape (E, 2), int64
        The boundary arcs.
    corners : ndarray, int64
        The vertices a clamped query may land on.
    """

    vertices: FloatArray
    triangles: IntArray
    inverse: FloatArray
    neighbours: IntArray
    planes: FloatArray
    edges: IntArray
    corners: IntArray

    @property
    def solid(self) -> bool:
        """Whether the region has triangles (False for a set on one great circle)."""
        return self.triangles.shape[0] > 0

    @staticmethod
    def build(points: FloatArray) -> MeasuredRegion:
        """Triangulate the region of measured directions.

        The same directions give the same region, kept (read-only) for the next call: the
        relighting asks for the region of one light set once per predicted light.

        Parameters
        ----------
        points : ndarray, shape (N, 3), float64
            Measured unit directions, N >= 1, no duplicates.

        Returns
        -------
        MeasuredRegion
            Triangulated, or for sets on one great circle (or of one or two directions) its
            arcs and points only.
        """
        data = np.ascontiguousarray(points, dtype=np.float64)
        return _built(data.tobytes(), len(data))

    @staticmethod
    def _triangulate(points: FloatArray) -> MeasuredRegion:
        count = len(points)
        if count >= 3:
            s = np.linalg.svd(points, compute_uv=False)
            if s[2] > 1e-9 * s[0]:
                try:
                    hull = ConvexHull(np.vstack([points, np.zeros((1, 3))]))
                except QhullError:
                    hull = None
                if hull is not None:
                    region = MeasuredRegion._from_hull(points, hull)
                    if region.solid:
                        return region
        return MeasuredRegion._arcs(points)

    @staticmethod
    def _from_hull(points: FloatArray, hull: Any) -> MeasuredRegion:
        count = len(points)
        simplices = hull.simplices.astype(np.int64)
        offset = -hull.equations[:, 3]  # distance of each face plane from the origin
        keep = (offset > _PLANE) & ~np.any(simplices == count, axis=1)
        triangles = simplices[keep]
        renumber = np.full(len(simplices), -1, dtype=np.int64)
        renumber[keep] = np.arange(len(triangles))
        neighbours = renumber[hull.neighbors[keep]]
        inverse = np.linalg.inv(points[triangles].transpose(0, 2, 1))
        t, i = np.nonzero(neighbours < 0)
        edges = np.stack([triangles[t, (i + 1) % 3], triangles[t, (i + 2) % 3]], axis=1)
        return MeasuredRegion(
            vertices=points,
            triangles=triangles,
            inverse=np.ascontiguousarray(inverse),
            neighbours=np.ascontiguousarray(neighbours),
            planes=np.ascontiguousarray(hull.equations[~keep, :3]),
            edges=edges.astype(np.int64).reshape(-1, 2),
            corners=np.unique(edges).astype(np.int64),
        )

    @staticmethod
    def _arcs(points: FloatArray) -> MeasuredRegion:
        # One, two or more directions on a single great circle: the region is the shortest arc
        # system through them (consecutive directions along the circle, the largest gap left out
        # when it exceeds a half turn) or, for one direction or an antipodal pair, the points.
        edges = np.zeros((0, 2), dtype=np.int64)
        if len(points) >= 2:
            _, s, vt = np.linalg.svd(points)
            if s[1] > 1e-9 * s[0]:
                normal = vt[2]
                u = points[0]
                v = np.cross(normal, u)
                angle = np.arctan2(points @ v, points @ u)
                order = np.argsort(angle)
                gaps = np.diff(np.append(angle[order], angle[order[0]] + 2.0 * np.pi))
                pairs = np.stack([order, np.roll(order, -1)], axis=1)
                use = gaps < np.pi - 1e-9
                if gaps.max() >= np.pi - 1e-9:
                    use[np.argmax(gaps)] = False
                edges = pairs[use].astype(np.int64).reshape(-1, 2)
        corners = np.arange(len(points), dtype=np.int64)
        return MeasuredRegion(
            vertices=points,
            triangles=np.zeros((0, 3), dtype=np.int64),
            inverse=np.zeros((0, 3, 3)),
            neighbours=np.zeros((0, 3), dtype=np.int64),
            planes=np.zeros((0, 3)),
            edges=edges,
            corners=corners,
        )

    def outside(self, queries: FloatArray) -> NDArray[np.bool_]:
        """Which queries lie outside the region.

        Parameters
        ----------
        queries : ndarray, shape (Q, 3), float64
            Unit query directions.

        Returns
        -------
        ndarray, shape (Q,), bool
        """
        if self.solid:
            out = np.zeros(len(queries), dtype=bool)
            _outside_kernel(queries, self.planes, out)
            return out
        _, _, gap = self._clamp(queries, np.arange(len(queries), dtype=np.int64))
        return gap > DUPLICATE_CHORD

    def _clamp(
        self, queries: FloatArray, rows: IntArray
    ) -> tuple[IntArray, FloatArray, FloatArray]:
        index = np.zeros((len(queries), 3), dtype=np.int64)
        weights = np.zeros((len(queries), 3))
        gap = np.zeros(len(queries))
        cross = np.cross(self.vertices[self.edges[:, 0]], self.vertices[self.edges[:, 1]])
        normal = cross / np.linalg.norm(cross, axis=1, keepdims=True)
        _clamp_kernel(
            queries,
            rows,
            self.vertices,
            self.edges,
            np.ascontiguousarray(normal),
            self.corners,
            index,
            weights,
            gap,
        )
        return index, weights, gap

    def barycentric(
        self, queries: FloatArray, *, clamp: bool
    ) -> tuple[IntArray, FloatArray, NDArray[np.bool_]]:
        """Barycentric weights of each query over the vertices of its triangle.

        Parameters
        ----------
        queries : ndarray, shape (Q, 3), float64
            Unit query directions.
        clamp : bool
            Outside queries take the weights of the region's nearest point (True) or all-zero
            weights (False).

        Returns
        -------
        indices : ndarray, shape (Q, 3), int64
            Vertices each query uses (always valid indices).
        weights : ndarray, shape (Q, 3), float64
            Their weights, >= 0, each row summing to 1 except zeroed outside rows.
        outside : ndarray, shape (Q,), bool
            Queries outside the region.
        """
        q_count = len(queries)
        if self.solid:
            index = np.zeros((q_count, 3), dtype=np.int64)
            weights = np.zeros((q_count, 3))
            outside = np.zeros(q_count, dtype=bool)
            _locate_kernel(
                queries,
                self.planes,
                self.triangles,
                self.inverse,
                self.neighbours,
                outside,
                index,
                weights,
            )
            rows = np.flatnonzero(outside).astype(np.int64)
            if clamp and rows.size:
                near, w, _ = self._clamp(queries, rows)
                index[rows], weights[rows] = near[rows], w[rows]
            elif rows.size:
                index[rows] = self.edges[0, 0] if len(self.edges) else 0
        else:
            index, weights, gap = self._clamp(queries, np.arange(q_count, dtype=np.int64))
            outside = gap > DUPLICATE_CHORD
        if not clamp:
            weights[outside] = 0.0
        return index, weights, outside


@numba.njit(cache=True, parallel=True)
def _outside_kernel(queries: FloatArray, planes: FloatArray, outside: NDArray[np.bool_]) -> None:
    for row in numba.prange(queries.shape[0]):
        x, y, z = queries[row, 0], queries[row, 1], queries[row, 2]
        for c in range(planes.shape[0]):
            if planes[c, 0] * x + planes[c, 1] * y + planes[c, 2] * z > _PLANE:
                outside[row] = True
                break


@numba.njit(cache=True, parallel=True)
def _locate_kernel(
    queries: FloatArray,
    planes: FloatArray,
    triangles: IntArray,
    inverse: FloatArray,
    neighbours: IntArray,
    outside: NDArray[np.bool_],
    index: IntArray,
    weights: FloatArray,
) -> None:
    # Point location by a visibility walk: from the last triangle of the block (the first query
    # of a block searches them all), cross the edge of the most negative coordinate until none
    # is negative; a walk that leaves the triangulation or runs too long falls back to a search
    # of every triangle for the one the query is least outside of.
    q_count = queries.shape[0]
    f_count = triangles.shape[0]
    for block in numba.prange((q_count + _BLOCK - 1) // _BLOCK):
        current = -1
        for row in range(block * _BLOCK, min((block + 1) * _BLOCK, q_count)):
            x, y, z = queries[row, 0], queries[row, 1], queries[row, 2]
            out = False
            for c in range(planes.shape[0]):
                if planes[c, 0] * x + planes[c, 1] * y + planes[c, 2] * z > _PLANE:
                    out = True
                    break
            if out:
                outside[row] = True
                continue
            t = current
            found = False
            if t >= 0:
                for _ in range(f_count + 3):
                    worst = 0
                    low = np.inf
                    size = 0.0
                    for i in range(3):
                        lam = inverse[t, i, 0] * x + inverse[t, i, 1] * y + inverse[t, i, 2] * z
                        size += abs(lam)
                        if lam < low:
                            low = lam
                            worst = i
                    if low >= -_LAMBDA * size:
                        found = True
                        break
                    t = neighbours[t, worst]
                    if t < 0:
                        break
            if not found:
                best = -np.inf
                t = 0
                for f in range(f_count):
                    low = np.inf
                    size = 0.0
                    for i in range(3):
                        lam = inverse[f, i, 0] * x + inverse[f, i, 1] * y + inverse[f, i, 2] * z
                        size += abs(lam)
                        low = min(low, lam)
                    score = low / size if size > 0.0 else -np.inf
                    if score > best:
                        best = score
                        t = f
            total = 0.0
            for i in range(3):
                lam = inverse[t, i, 0] * x + inverse[t, i, 1] * y + inverse[t, i, 2] * z
                lam = max(lam, 0.0)
                weights[row, i] = lam
                total += lam
            for i in range(3):
                index[row, i] = triangles[t, i]
                weights[row, i] = weights[row, i] / total if total > 0.0 else 1.0 / 3.0
            current = t


@numba.njit(cache=True, parallel=True)
def _clamp_kernel(
    queries: FloatArray,
    rows: IntArray,
    vertices: FloatArray,
    edges: IntArray,
    normals: FloatArray,
    corners: IntArray,
    index: IntArray,
    weights: FloatArray,
    gap: FloatArray,
) -> None:
    # Nearest point of the boundary arcs and corners to each query. On the great circle of arc
    # (a, b) with unit normal n the nearest point is p = normalize(q - (q . n) n); it lies on the
    # arc when (a x p) . n and (p x b) . n are both >= 0, and those are its coordinates in a and b
    # times |a x b|: the planar barycentric coordinates on the chord, as inside the triangles.
    for r in numba.prange(rows.shape[0]):
        row = rows[r]
        x, y, z = queries[row, 0], queries[row, 1], queries[row, 2]
        best = -np.inf
        first = corners[0]
        second = corners[0]
        wa = 1.0
        px, py, pz = vertices[first, 0], vertices[first, 1], vertices[first, 2]
        for c in range(corners.shape[0]):
            v = corners[c]
            dot = x * vertices[v, 0] + y * vertices[v, 1] + z * vertices[v, 2]
            if dot > best:
                best = dot
                first = v
                second = v
                wa = 1.0
                px, py, pz = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        for e in range(edges.shape[0]):
            nx, ny, nz = normals[e, 0], normals[e, 1], normals[e, 2]
            h = x * nx + y * ny + z * nz
            sx, sy, sz = x - h * nx, y - h * ny, z - h * nz
            norm = math.sqrt(sx * sx + sy * sy + sz * sz)
            if norm <= best or norm < 1e-12:  # q . p = norm: not nearer than the best so far
                continue
            sx, sy, sz = sx / norm, sy / norm, sz / norm
            a, b = edges[e, 0], edges[e, 1]
            ax, ay, az = vertices[a, 0], vertices[a, 1], vertices[a, 2]
            bx, by, bz = vertices[b, 0], vertices[b, 1], vertices[b, 2]
            beta = (ay * sz - az * sy) * nx + (az * sx - ax * sz) * ny + (ax * sy - ay * sx) * nz
            alpha = (sy * bz - sz * by) * nx + (sz * bx - sx * bz) * ny + (sx * by - sy * bx) * nz
            if alpha < 0.0 or beta < 0.0 or alpha + beta <= 0.0:
                continue
            best = norm
            first = a
            second = b
            wa = alpha / (alpha + beta)
            px, py, pz = sx, sy, sz
        index[row, 0] = first
        index[row, 1] = second
        index[row, 2] = first
        weights[row, 0] = wa
        weights[row, 1] = 1.0 - wa
        weights[row, 2] = 0.0
        gap[row] = math.sqrt((x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2)


@functools.lru_cache(maxsize=64)
def _built(data: bytes, count: int) -> MeasuredRegion:
    """:meth:`MeasuredRegion.build` of the directions held in ``data``, its arrays read-only."""
    region = MeasuredRegion._triangulate(np.frombuffer(data, dtype=np.float64).reshape(count, 3))
    for value in vars(region).values():
        value.setflags(write=False)
    return region
