"""Relighting a reflectance field: the paper's eq. 3, camera blending, and the sum over slabs.

A field F (S, T, P, 3) holds the radiance of every sample p seen from camera s under a
directional light t of unit irradiance. Light is linear, so under lights of irradiance E_k
from directions l_k (a :class:`processing.lights.LightSet`) and for a view e

    L_p = sum_s w(e, s, p) sum_t W_t F[s, t, p],    W_t = sum_k E_k w(l_k, t)        (eq. 3)

with w(l, t) the interpolation weights of direction l over the measured lights and w(e, s, p)
those of the view direction from p over the measured cameras, restricted to the cameras that see
p and renormalised. A sample no camera sees is a hole: reported, never silently black.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from core.brdf import cosine, toward_eye
from core.camera_model import PinholeCamera
from core.directions import panorama_directions, panorama_solid_angles
from core.errors import InputError
from core.field_store import ReflectanceField
from processing.interpolation import InterpolationMethod, OutsidePolicy, interpolation_weights
from processing.panorama import downsample_panorama
from render.light_weights import LightWeights

__all__ = [
    "ViewBlend",
    "ViewField",
    "blend_cameras",
    "blend_field",
    "relight",
    "relight_camera",
    "relight_pixels_literal",
    "relight_view",
]

#: float16 bit pattern -> float32, so the numba kernels read half-precision fields directly.
_HALF_TO_FLOAT = (
    np.arange(65536, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(np.float32)
)
#: Samples per block of the relighting kernel (one block's rows of every light stay in cache).
BLOCK = 1024


@dataclass(frozen=True)
class ViewBlend:
    """Per-sample camera weights of one view.

    Attributes
    ----------
    cameras : ndarray, shape (C,), int64, the measured cameras the view uses
    weights : ndarray, shape (C, P), float32, weight of each used camera for each sample
        (rows of a sample sum to 1, or 0 for holes and for samples not needed)
    holes : ndarray, shape (P,), bool, needed samples that no chosen camera sees
    """

    cameras: NDArray[np.int64]
    weights: NDArray[np.float32]
    holes: NDArray[np.bool_]


def blend_cameras(
    field: ReflectanceField,
    camera: PinholeCamera,
    method: InterpolationMethod = "paper",
    *,
    n: int = 3,
    needed: NDArray[np.bool_] | None = None,
) -> ViewBlend:
    """Camera weights of every needed sample for the view of ``camera``.

    Each sample's ray toward the eye is followed to the sphere the measured cameras sit on, and
    the cameras are interpolated at that point (so a captured view uses exactly its camera for
    every sample, and parallax between cameras is respected). Cameras that do
    not see a sample are dropped and the rest renormalised; a sample none of the chosen cameras
    sees takes the nearest camera that does, and one that no camera sees is a hole.

    Parameters
    ----------
    field : ReflectanceField
    camera : PinholeCamera, the wanted view
    method, n : interpolation over the measured cameras (n nearest for ``paper``)
    needed : ndarray, shape (P,), bool, optional; samples to relight (default all)
    """
    _, _, p_count = field.shape
    if field.sample_kind == "pixels":
        # One fixed view: nothing to blend; the wanted view must be that one.
        if not np.allclose(camera.direction, field.camera_directions[0], atol=1e-6):
            raise InputError(
                f"{field.path} holds the pixels of one view "
                f"({field.cameras[0].azimuth_deg:g}, {field.cameras[0].inclination_deg:g}); it "
                "cannot be seen from another"
            )
        keep = np.ones(p_count, dtype=bool) if needed is None else needed
        return ViewBlend(
            np.zeros(1, dtype=np.int64),
            keep.astype(np.float32)[None, :],
            keep & ~field.visibility[0],
        )
    assert field.points is not None
    mask = np.ones(p_count, dtype=bool) if needed is None else np.asarray(needed, dtype=bool)
    index = np.flatnonzero(mask)
    towards = np.empty((len(index), 3))
    radius = float(np.mean([c.distance for c in field.cameras]))
    _sphere_crossings(np.asarray(field.points), index, camera.position, radius, towards)
    chosen = interpolation_weights(field.camera_directions, towards, method, m=n, policy="clamp")
    # The cameras that see each sample keep their weights, renormalised; numba, because in
    # numpy these steps took 30 of the 40 ms of a view's blend at 250k points.
    indices, weights = chosen.indices.copy(), chosen.weights.copy()
    holes = np.zeros(p_count, dtype=bool)
    _keep_seen(indices, weights, index, towards, field.camera_directions, field.visibility, holes)
    used = np.flatnonzero(np.bincount(indices[weights > 0], minlength=len(field.cameras)))
    per_camera = np.zeros((len(used), p_count), dtype=np.float32)
    row_of = np.full(len(field.cameras), -1, dtype=np.int64)
    row_of[used] = np.arange(len(used))
    _scatter_weights(indices, weights, index, row_of, per_camera)
    return ViewBlend(used.astype(np.int64), per_camera, holes)


@numba.njit(cache=True, parallel=True)
def _sphere_crossings(
    points: NDArray[np.floating],
    index: NDArray[np.int64],
    eye: NDArray[np.float64],
    radius: float,
    out: NDArray[np.float64],
) -> None:
    """Unit directions of where the rays from ``points[index]`` to ``eye`` cross a sphere.

    The sphere has ``radius`` (the measured cameras' distance); where a ray cannot reach it,
    the direction is the eye's.
    """
    for q in numba.prange(index.shape[0]):
        p = index[q]
        x, y, z = float(points[p, 0]), float(points[p, 1]), float(points[p, 2])
        rx, ry, rz = toward_eye(points, p, eye, False)
        along = x * rx + y * ry + z * rz
        reach = along * along - (x * x + y * y + z * z) + radius * radius
        if reach < 0.0:
            cx, cy, cz = eye[0], eye[1], eye[2]
        else:
            t = -along + math.sqrt(reach)
            cx, cy, cz = x + t * rx, y + t * ry, z + t * rz
        norm = math.sqrt(cx * cx + cy * cy + cz * cz)
        out[q, 0], out[q, 1], out[q, 2] = cx / norm, cy / norm, cz / norm


# Arrays one by one on purpose: numba kernels take arrays, not the field and the weights.
@numba.njit(cache=True, parallel=True)
def _keep_seen(
    indices: NDArray[np.int64],
    weights: NDArray[np.float64],
    index: NDArray[np.int64],
    towards: NDArray[np.float64],
    cameras: NDArray[np.float64],
    visibility: NDArray[np.bool_],
    holes: NDArray[np.bool_],
) -> None:
    """Drop the chosen cameras that do not see each sample and renormalise, in place.

    A sample none of its chosen cameras sees takes the nearest camera (by angle) that does; one
    that no camera sees is a hole (all weights 0).
    """
    for q in numba.prange(index.shape[0]):
        p = index[q]
        total = 0.0
        for j in range(indices.shape[1]):
            if not visibility[indices[q, j], p]:
                weights[q, j] = 0.0
            total += weights[q, j]
        if total <= 0.0:
            best, nearest = -np.inf, -1
            toward = (towards[q, 0], towards[q, 1], towards[q, 2])
            for c in range(cameras.shape[0]):
                if visibility[c, p]:
                    cos = cosine(toward, (cameras[c, 0], cameras[c, 1], cameras[c, 2]))
                    if cos > best:
                        best, nearest = cos, c
            if nearest < 0:
                holes[p] = True
                continue
            indices[q, 0], weights[q, 0], total = nearest, 1.0, 1.0
        for j in range(indices.shape[1]):
            weights[q, j] /= total


@numba.njit(cache=True, parallel=True)
def _scatter_weights(
    indices: NDArray[np.int64],
    weights: NDArray[np.float64],
    index: NDArray[np.int64],
    row_of: NDArray[np.int64],
    per_camera: NDArray[np.float32],
) -> None:
    # A camera chosen twice for one sample (unused slots repeat one) adds up.
    for q in numba.prange(index.shape[0]):
        for j in range(indices.shape[1]):
            if weights[q, j] > 0.0:
                per_camera[row_of[indices[q, j]], index[q]] += np.float32(weights[q, j])


@dataclass(frozen=True)
class ViewField:
    """The field as one view sees it, blended once for every new lighting.

    The camera blend is applied once and the result compacted to the samples the view needs,
    so every new lighting costs a single pass over (T, Pn, 3).

    Attributes
    ----------
    samples : ndarray, shape (Pn,), int64, the needed samples (those with camera weight)
    radiance : ndarray, shape (T, Pn, 3), float32, sum_s w(e, s, p) F[s, t, p]
    sample_count : int, P of the field
    """

    samples: NDArray[np.int64]
    radiance: NDArray[np.float32]
    sample_count: int


def blend_field(field: ReflectanceField, blend: ViewBlend) -> ViewField:
    """Apply a view's camera weights to the field's slabs (one pass over each used camera)."""
    _, t_count, p_count = field.shape
    samples = np.flatnonzero(blend.weights.sum(axis=0) > 0).astype(np.int64)
    radiance = np.zeros((t_count, len(samples), 3), dtype=np.float32)
    for row, camera in enumerate(blend.cameras):
        _blend(field.camera_slab(int(camera)), samples, blend.weights[row], radiance)
    return ViewField(samples, radiance, p_count)


def relight_view(view: ViewField, lighting: LightWeights) -> NDArray[np.float32]:
    """Radiance (P, 3), float32, of every sample under ``lighting``: sum_t W_t G[t, p].

    Samples outside the view (holes, samples not needed) are 0.
    """
    t_count = view.radiance.shape[0]
    if lighting.rgb.shape[1:] != (t_count, 3):
        raise InputError(
            f"light weights are for {lighting.rgb.shape[1]} lights, the field has {t_count}"
        )
    if lighting.sample_rows is None:
        rows = np.zeros(1, dtype=np.int64)  # one light row for all: the kernel never reads it
    elif lighting.sample_rows.shape == (view.sample_count,):
        rows = lighting.sample_rows[view.samples]
    else:
        raise InputError(
            f"light weights are for {lighting.sample_rows.shape[0]} samples, the field has "
            f"{view.sample_count}"
        )
    compact = np.zeros((len(view.samples), 3), dtype=np.float32)
    _relight(view.radiance, lighting.rgb, rows, lighting.sample_rows is None, compact)
    out = np.zeros((view.sample_count, 3), dtype=np.float32)
    out[view.samples] = compact
    return out


def relight_camera(
    field: ReflectanceField, camera: int, lighting: LightWeights
) -> NDArray[np.float32]:
    """Radiance (P, 3), float32, of every sample as measured camera ``camera`` sees it.

    Cached per lighting by the :class:`render.engines.interpolated.Relighter`, these make a new view
    under an unchanged lighting a blend of a few (P, 3) arrays.
    """
    slab = field.camera_slab(camera)
    t_count, p_count = slab.shape[:2]
    if lighting.rgb.shape[1:] != (t_count, 3):
        raise InputError(
            f"light weights are for {lighting.rgb.shape[1]} lights, the field has {t_count}"
        )
    rows = lighting.sample_rows
    if rows is None:
        rows = np.zeros(1, dtype=np.int64)
    out = np.zeros((p_count, 3), dtype=np.float32)
    _relight(slab, lighting.rgb, rows, lighting.sample_rows is None, out)
    return out


def relight(
    field: ReflectanceField, lighting: LightWeights, blend: ViewBlend
) -> NDArray[np.float32]:
    """Radiance (P, 3), float32, of every sample for one lighting and view (eq. 3's sums).

    Samples with no weight (holes, samples not needed) are 0; see ``blend.holes``.
    """
    return relight_view(blend_field(field, blend), lighting)


def relight_pixels_literal(
    field: ReflectanceField,
    rgb: NDArray[np.floating],
    blend: ViewBlend,
    method: InterpolationMethod = "paper",
    *,
    m: int = 3,
    policy: OutsidePolicy = "clamp",
    grid_height: int | None = None,
) -> NDArray[np.float32]:
    """Paper eq. 2 as written: radiance (P, 3) of every sample by a sum over panorama pixels.

    For each sample, the sum over every panorama pixel in the hemisphere of its normal of L dw
    times the interpolated field. The slow reference (P x pixels x m operations) that
    :func:`render.light_weights.pixel_light_weights` rearranges; use small P or
    ``grid_height``.

    Returns
    -------
    ndarray, shape (P, 3), float32 (0 where the blend gives no weight)
    """
    if field.normals is None:
        raise InputError(f"{field.path} has no normals: eq. 2 needs each sample's hemisphere")
    image = np.asarray(rgb, dtype=np.float32)
    if grid_height is not None and grid_height < image.shape[0]:
        image = downsample_panorama(image, grid_height)
    height, width = image.shape[:2]
    directions = panorama_directions(height, width).reshape(-1, 3)
    energy = (image * panorama_solid_angles(height, width)[:, :, None]).reshape(-1, 3)
    weights = interpolation_weights(field.light_directions, directions, method, m=m, policy=policy)
    view = blend_field(field, blend)
    needed, p_count = view.samples, view.sample_count
    blended = np.ascontiguousarray(view.radiance.transpose(1, 0, 2), dtype=np.float64)
    out = np.zeros((p_count, 3), dtype=np.float32)
    result = np.zeros((len(needed), 3))
    _literal_eq2(
        field.normals[needed].astype(np.float64),
        directions,
        energy.astype(np.float64),
        weights.indices,
        weights.weights,
        blended,
        result,
    )
    out[needed] = result
    return out


# Arrays one by one on purpose: numba kernels take arrays, not the field and the weights.
@numba.njit(cache=True, parallel=True)
def _literal_eq2(
    normals: NDArray[np.float64],
    directions: NDArray[np.float64],
    energy: NDArray[np.float64],
    indices: NDArray[np.int64],
    weights: NDArray[np.float64],
    blended: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    for p in numba.prange(normals.shape[0]):
        normal = (normals[p, 0], normals[p, 1], normals[p, 2])
        for q in range(directions.shape[0]):
            if cosine(normal, (directions[q, 0], directions[q, 1], directions[q, 2])) <= 0.0:
                continue
            for j in range(indices.shape[1]):
                w = weights[q, j]
                if w != 0.0:
                    t = indices[q, j]
                    for c in range(3):
                        out[p, c] += energy[q, c] * w * blended[p, t, c]


@numba.njit(cache=True, parallel=True)
def _blend(
    slab: NDArray[np.float32],
    samples: NDArray[np.int64],
    weight: NDArray[np.float32],
    out: NDArray[np.float32],
) -> None:
    for t in numba.prange(slab.shape[0]):
        for j in range(samples.shape[0]):
            p = samples[j]
            w = weight[p]
            if w != 0.0:
                for c in range(3):
                    out[t, j, c] += w * slab[t, p, c]


@numba.njit(cache=True, parallel=True, fastmath=True)
def _relight(
    radiance: NDArray[np.float32],
    light: NDArray[np.float32],
    rows: NDArray[np.int64],
    uniform: bool,
    out: NDArray[np.float32],
) -> None:
    # Blocks of samples in parallel, lights outer: each block's rows stream once from memory
    # while its outputs stay in cache. One light row for all samples is the common case
    # (sampled lights, projection); hoisting it lets the inner loop vectorise.
    t_count, count = radiance.shape[0], radiance.shape[1]
    for block in numba.prange((count + BLOCK - 1) // BLOCK):
        start, stop = block * BLOCK, min((block + 1) * BLOCK, count)
        for t in range(t_count):
            if uniform:
                r, g, b = light[0, t, 0], light[0, t, 1], light[0, t, 2]
                for j in range(start, stop):
                    out[j, 0] += r * radiance[t, j, 0]
                    out[j, 1] += g * radiance[t, j, 1]
                    out[j, 2] += b * radiance[t, j, 2]
            else:
                for j in range(start, stop):
                    row = rows[j]
                    out[j, 0] += light[row, t, 0] * radiance[t, j, 0]
                    out[j, 1] += light[row, t, 1] * radiance[t, j, 1]
                    out[j, 2] += light[row, t, 2] * radiance[t, j, 2]
