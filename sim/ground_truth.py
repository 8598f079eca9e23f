"""Ground truth: an object seen by a camera under a whole environment panorama.

    L(p, wo) = sum over directions w of f(w, wo) max(0, n . w) V(p, w) L_env(w) dw

Direct illumination only (no interreflection): that is the model every accuracy figure of this
project is measured against. The directions are either every panorama pixel (``grid_height =
None``: exact to the panorama's resolution) or a pre-filtered grid: the panorama summed exactly
(radiance x solid angle) into h x 2h blocks, each block a directional light at its
energy-weighted centroid (:func:`core.light_set.grid_lights`). The error the pre-filter adds is
measured against the exact mode (tests, and the closing notes). Visibility V comes from one
shadow map per direction (:func:`sim.synthetic_camera.light_visibility`); convex objects need
none (V = [n . w > 0]).

The panorama arrives as an array: reading files is the caller's job (``processing.panorama``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from core.brdf import cosine, shade_light, toward_eye
from core.camera_model import PinholeCamera
from core.light_set import LightSet, grid_lights
from core.progress import progress_bar
from sim.scenes import SurfaceSamples, build_scene, get_scene
from sim.synthetic_camera import DirectionalLight, SyntheticImage, image_of_points, light_visibility

__all__ = [
    "FieldTruth",
    "field_truth",
    "render_environment",
    "shade_environment",
    "shade_environment_views",
]

#: Directions shaded together (bounds the memory of the visibility matrix).
CHUNK = 64

#: The truth of a view under a panorama: linear RGB (H, W, 3) and coverage (H, W).
FieldTruth = Callable[
    [NDArray[np.float32], PinholeCamera], tuple[NDArray[np.float32], NDArray[np.bool_]]
]


def shade_environment(
    samples: SurfaceSamples,
    viewpoint: NDArray[np.floating],
    lights: LightSet,
    *,
    shadows: bool = True,
) -> NDArray[np.float64]:
    """Radiance (P, 3) of every point toward ``viewpoint`` under directional ``lights``."""
    return shade_environment_views(samples, [viewpoint], lights, shadows=shadows)[0]


def shade_environment_views(
    samples: SurfaceSamples,
    viewpoints: Sequence[NDArray[np.floating]],
    lights: LightSet,
    *,
    shadows: bool = True,
) -> list[NDArray[np.float64]]:
    """:func:`shade_environment` toward several viewpoints, each light's shadow map made once.

    Shadow maps depend on the light only and are most of the cost of a non-convex scene.
    """
    lit = lights.nonempty()
    directions, light = lit.directions, lit.rgb
    out = [np.zeros((samples.count, 3)) for _ in viewpoints]
    args = (
        samples.points.astype(np.float64),
        samples.normals.astype(np.float64),
        samples.rho_d.astype(np.float64),
        samples.f0.astype(np.float64),
        samples.alpha.astype(np.float64),
    )
    starts = range(0, len(directions), CHUNK)
    for start in progress_bar(starts, desc="shading", unit="chunk"):
        chunk = slice(start, start + CHUNK)
        if shadows:
            visible = np.stack(
                [light_visibility(samples, DirectionalLight(tuple(d))) for d in directions[chunk]]
            )
        else:
            visible = np.ones((0, 0), dtype=np.bool_)
        for viewpoint, radiance in zip(viewpoints, out, strict=True):
            eye = np.asarray(viewpoint, dtype=np.float64)
            _shade(*args, eye, directions[chunk], light[chunk], visible, shadows, radiance)
    return out


def render_environment(
    samples: SurfaceSamples,
    rgb: NDArray[np.floating],
    camera: PinholeCamera,
    *,
    grid_height: int | None = 32,
    shadows: bool = True,
) -> SyntheticImage:
    """The ground-truth image of ``samples`` under the panorama ``rgb`` seen by ``camera``."""
    lights = grid_lights(np.asarray(rgb), grid_height)
    radiance = shade_environment(samples, camera.position, lights, shadows=shadows)
    return image_of_points(samples, camera, radiance)


# The samples' arrays one by one on purpose, as sim.synthetic_camera's kernel takes them:
# numba kernels take arrays and scalars, not SurfaceSamples or a LightSet.
@numba.njit(cache=True, parallel=True)
def _shade(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    rho_d: NDArray[np.float64],
    f0: NDArray[np.float64],
    alpha: NDArray[np.float64],
    viewpoint: NDArray[np.float64],
    directions: NDArray[np.float64],
    light: NDArray[np.float64],
    visible: NDArray[np.bool_],
    use_visibility: bool,
    out: NDArray[np.float64],
) -> None:
    # The model of core.brdf.brdf times the cosine (core.brdf.shade_light), point by point
    # (tests hold the two equal).
    for p in numba.prange(points.shape[0]):
        view = toward_eye(points, p, viewpoint, False)
        normal = (normals[p, 0], normals[p, 1], normals[p, 2])
        if cosine(normal, view) <= 0.0:
            continue
        rho = (rho_d[p, 0], rho_d[p, 1], rho_d[p, 2])
        f = (f0[p, 0], f0[p, 1], f0[p, 2])
        a = alpha[p]
        r = g = b = 0.0
        for d in range(directions.shape[0]):
            if use_visibility and not visible[d, p]:
                continue
            towards = (directions[d, 0], directions[d, 1], directions[d, 2])
            if cosine(normal, towards) <= 0.0:
                continue  # behind the surface: skipped, not added as 0 (0 x inf light is NaN)
            shade = shade_light(normal, towards, view, rho, f, a, True)
            r += shade[0] * light[d, 0]
            g += shade[1] * light[d, 1]
            b += shade[2] * light[d, 2]
        out[p, 0] += r
        out[p, 1] += g
        out[p, 2] += b


def field_truth(provenance: Mapping[str, Any]) -> FieldTruth | None:
    """The ground truth of a simulated field's object under any panorama and view.

    A field written by :func:`sim.field.simulate_field` records its scene and point count; the
    scene's samples are rebuilt from them (the builders are deterministic), and each call
    renders them with :func:`render_environment`. Other fields (captured, imported, or
    path-traced, whose truth takes minutes) have none: None.

    Parameters
    ----------
    provenance : mapping, the field store's ``provenance`` attribute
    """
    if provenance.get("source") != "simulator":
        return None
    name = str(provenance["scene"]["name"])
    samples = build_scene(name, int(provenance["points"]))
    shadows = not get_scene(name).convex

    def truth(
        rgb: NDArray[np.float32], camera: PinholeCamera
    ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
        image = render_environment(samples, rgb, camera, shadows=shadows)
        return image.rgb, image.coverage

    return truth
