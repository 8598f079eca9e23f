"""The synthetic camera: one reflectance-field image of a point-sampled object under ONE light.

Radiance of a surface point p seen from the camera at C, lit by a light of direction l(p):

    L(p) = f(l, v) max(0, n . l) E(p) V(p),    v = normalize(C - p)

with f the model of :mod:`sim.materials`, E the irradiance the light delivers (directional: its
irradiance, 1 by default; point light: I / r^2, as on a real gantry) and V the light's
visibility: a shadow map (a z-buffer of the object's splats seen from the light: orthographic for
a directional light, perspective for a point light), so cast shadows and self-shadowing appear
where the geometry says. Direct light only. The image is the depth-tested blend of the visible
points' splats (disks one point spacing wide, so no holes), plus a coverage mask.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.brdf import cosine, shade_light, toward_eye
from core.camera_model import PinholeCamera
from core.errors import InputError
from core.splat import (
    SPLAT_RADIUS,
    blend_splats,
    camera_splats,
    depth_at_points,
    shown_points,
    zbuffer,
)
from sim.scenes import SurfaceSamples

__all__ = [
    "DirectionalLight",
    "PointLight",
    "SyntheticImage",
    "camera_visibility",
    "image_of_points",
    "light_visibility",
    "render_under_light",
    "shade_points",
]

#: Shadow-map depth bias, in point spacings.
SHADOW_BIAS = 2.0
MAX_SHADOW_MAP = 4096


@dataclass(frozen=True)
class DirectionalLight:
    """A distant light from ``direction`` (toward the light) delivering ``irradiance``."""

    direction: tuple[float, float, float]
    irradiance: float = 1.0


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light at ``position`` of radiant ``intensity`` (irradiance I / r^2)."""

    position: tuple[float, float, float]
    intensity: float = 1.0


Light = DirectionalLight | PointLight


@dataclass(frozen=True)
class SyntheticImage:
    """One rendered image.

    Attributes
    ----------
    rgb : ndarray, shape (H, W, 3), float32, linear radiance
    coverage : ndarray, shape (H, W), bool, pixels the object covers
    point_radiance : ndarray, shape (P, 3), float32, radiance of every point toward the camera
    visible : ndarray, shape (P,), bool, points the camera sees
    """

    rgb: NDArray[np.float32]
    coverage: NDArray[np.bool_]
    point_radiance: NDArray[np.float32]
    visible: NDArray[np.bool_]


def _light_geometry(
    samples: SurfaceSamples, light: Light
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit direction toward the light (P, 3) and irradiance (P,) at every point."""
    points = samples.points.astype(np.float64)
    if isinstance(light, DirectionalLight):
        direction = np.asarray(light.direction, dtype=np.float64)
        norm = np.linalg.norm(direction)
        if not (np.isfinite(norm) and norm > 0) or not light.irradiance >= 0:
            raise InputError(f"invalid directional light {light}")
        return np.broadcast_to(direction / norm, points.shape), np.full(
            len(points), light.irradiance
        )
    position = np.asarray(light.position, dtype=np.float64)
    if not light.intensity >= 0:
        raise InputError(f"point light intensity {light.intensity} must not be negative")
    distance_to_origin = float(np.linalg.norm(position))
    if distance_to_origin <= samples.bounding_radius:
        raise InputError(
            f"point light at distance {distance_to_origin:.3g} is inside the object (bounding "
            f"radius {samples.bounding_radius:.3g}); place the light further out"
        )
    offset = position - points
    distance = np.linalg.norm(offset, axis=1)
    return offset / distance[:, None], light.intensity / distance**2


def light_visibility(samples: SurfaceSamples, light: Light) -> NDArray[np.bool_]:
    """Which points the light reaches (facing it and not shadowed); shape (P,)."""
    points = samples.points.astype(np.float64)
    towards, _ = _light_geometry(samples, light)
    cosine = np.einsum("pk,pk->p", samples.normals.astype(np.float64), towards)
    facing = cosine > 0
    if isinstance(light, DirectionalLight):
        axis = towards[0]
        helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        a = np.cross(axis, helper)
        a /= np.linalg.norm(a)
        b = np.cross(axis, a)
        depth = -(points @ axis) + samples.bounding_radius + 1.0  # distance along the light
        scale = 1.0 / samples.spacing  # map cells per unit length
        u, w = points @ a, points @ b
        radius = np.full(len(points), SPLAT_RADIUS * 1.5)
        bias = SHADOW_BIAS * samples.spacing
    else:
        position = np.asarray(light.position, dtype=np.float64)
        forward = -position / np.linalg.norm(position)
        helper = np.array([0.0, 0.0, 1.0]) if abs(forward[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        a = np.cross(forward, helper)
        a /= np.linalg.norm(a)
        b = np.cross(a, forward)
        relative = points - position
        depth = relative @ forward
        scale = float(np.median(depth)) / samples.spacing
        u, w = (relative @ a) / depth, (relative @ b) / depth
        radius = SPLAT_RADIUS * 1.5 * samples.spacing * scale / depth
        depth = np.linalg.norm(relative, axis=1)
        bias = SHADOW_BIAS * samples.spacing
    cols = (u - u.min()) * scale * 1.5 + 2.0
    rows = (w - w.min()) * scale * 1.5 + 2.0
    width = int(np.ceil(cols.max())) + 3
    height = int(np.ceil(rows.max())) + 3
    if max(width, height) > MAX_SHADOW_MAP:
        shrink = MAX_SHADOW_MAP / max(width, height)
        cols, rows, radius = cols * shrink, rows * shrink, np.maximum(radius * shrink, 0.75)
        width, height = int(width * shrink) + 1, int(height * shrink) + 1
    front = depth_at_points(cols, rows, zbuffer(cols, rows, depth, radius, height, width))
    # Slope-scaled bias: a neighbour's splat one spacing away on the same tilted surface lies
    # spacing x tan(theta) nearer the light.
    clipped = np.clip(cosine, 0.05, 1.0)
    slope = np.sqrt(1.0 - clipped**2) / clipped
    return facing & (depth <= front + bias * (1.0 + slope))


def shade_points(
    samples: SurfaceSamples, viewpoint: ArrayLike, light: Light, *, shadows: bool = True
) -> NDArray[np.float64]:
    """Radiance (P, 3) of every point toward ``viewpoint`` under ``light`` (direct light only)."""
    towards, irradiance = _light_geometry(samples, light)
    if shadows:
        reached = light_visibility(samples, light)
    else:
        reached = np.ones(samples.count, dtype=np.bool_)
    out = np.zeros((samples.count, 3))
    _shade_one_light(
        samples.points.astype(np.float64),
        samples.normals.astype(np.float64),
        samples.rho_d.astype(np.float64),
        samples.f0.astype(np.float64),
        samples.alpha.astype(np.float64),
        np.asarray(viewpoint, dtype=np.float64),
        np.ascontiguousarray(towards),
        irradiance,
        reached,
        out,
    )
    return out


# The samples' arrays one by one on purpose, as sim.ground_truth's kernel takes them: numba
# kernels take arrays and scalars, not SurfaceSamples.
@numba.njit(cache=True, parallel=True)
def _shade_one_light(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    rho_d: NDArray[np.float64],
    f0: NDArray[np.float64],
    alpha: NDArray[np.float64],
    viewpoint: NDArray[np.float64],
    towards: NDArray[np.float64],
    irradiance: NDArray[np.float64],
    reached: NDArray[np.bool_],
    out: NDArray[np.float64],
) -> None:
    # core.brdf.brdf times cos(theta_i) (core.brdf.shade_light) point by point, times the
    # irradiance (tests hold the two equal); numpy's temporaries cost more than the arithmetic
    # at 250k points.
    for p in numba.prange(points.shape[0]):
        if not reached[p]:
            continue
        normal = (normals[p, 0], normals[p, 1], normals[p, 2])
        light = (towards[p, 0], towards[p, 1], towards[p, 2])
        view = toward_eye(points, p, viewpoint, False)
        if cosine(normal, light) <= 0.0 or cosine(normal, view) <= 0.0:
            continue  # unlit or unseen: left 0, not 0 x the irradiance (NaN if infinite)
        rho = (rho_d[p, 0], rho_d[p, 1], rho_d[p, 2])
        f = (f0[p, 0], f0[p, 1], f0[p, 2])
        shade = shade_light(normal, light, view, rho, f, alpha[p], True)
        for c in range(3):
            out[p, c] = shade[c] * irradiance[p]


def render_under_light(
    samples: SurfaceSamples, camera: PinholeCamera, light: Light, *, shadows: bool = True
) -> SyntheticImage:
    """Render one image of ``samples`` seen by ``camera`` under ``light``."""
    _check_camera(samples, camera)  # before the shading (camera_splats checks only after)
    return image_of_points(
        samples, camera, shade_points(samples, camera.position, light, shadows=shadows)
    )


def _check_camera(samples: SurfaceSamples, camera: PinholeCamera) -> None:
    if samples.count < 1:
        raise InputError("the object has no points")
    if camera.distance <= samples.bounding_radius:
        raise InputError(
            f"camera distance {camera.distance} is inside the object (bounding radius "
            f"{samples.bounding_radius:.3g}); move the camera further out"
        )


def camera_visibility(samples: SurfaceSamples, camera: PinholeCamera) -> NDArray[np.bool_]:
    """Which points (P,) the camera sees: facing it and blending into at least one pixel."""
    splats = camera_splats(samples.points, samples.normals, camera, samples.spacing)
    return shown_points(splats)


def image_of_points(
    samples: SurfaceSamples, camera: PinholeCamera, radiance: NDArray[np.floating]
) -> SyntheticImage:
    """Splat points of known radiance (P, 3) into the camera's image, with visibility."""
    s = camera_splats(samples.points, samples.normals, camera, samples.spacing)
    visible = shown_points(s)
    colours = np.asarray(radiance, dtype=np.float64)
    image, weight = blend_splats(s, colours)
    return SyntheticImage(
        rgb=image,
        coverage=weight > 0,
        point_radiance=colours.astype(np.float32),
        visible=visible,
    )
