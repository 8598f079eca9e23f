"""An independent check of the ground truth: the same scene rendered by Mitsuba 3.

:func:`render_reference` rebuilds a sphere scene of :mod:`sim.scenes` in Mitsuba 3 and renders
it under an equirectangular panorama, seen by a :class:`core.camera_model.PinholeCamera`, on the
same pixel grid as :func:`sim.ground_truth.render_environment` (row 0 at the top, not
mirrored). Mitsuba is an optional extra (``pip install -e '.[reference]'``) imported only when a
function here runs.

How the conventions map (derived from ``docs/conventions.md`` and the Mitsuba 3.9 sources)
------------------------------------------------------------------------------------------

World frame
    Mitsuba has no preferred up axis except in the ``envmap`` emitter, so its world frame *is*
    the rig frame (``+z`` up): geometry and camera need no transform.

Environment
    ``envmap`` maps a direction d of its local frame to texture coordinates
    u = atan2(d_x, -d_z) / 2 pi (wrapped into [0, 1)), v = acos(d_y) / pi. Our column centres
    are at (j + 0.5) / W = (pi - phi) / 2 pi and our rows at theta / pi. With
    atan2(d_x, -d_z) = pi - phi and acos(d_y) = theta, the local direction is
    d = (sin theta sin phi, cos theta, sin theta cos phi) = (y, z, x) in the rig frame, so
    ``to_world`` is the cyclic permutation local (x, y, z) -> rig (z, x, y) (a rotation,
    :data:`ENVMAP_TO_RIG`); no flip of the bitmap is needed.

    The texel grid is not ours, though. ``envmap`` appends a copy of the first column (the seam),
    interpolates bilinearly and shifts u by half a texel, so texel column m sits at u =
    (m + 0.5) / W as ours do; but rows are vertices, not cells: texel row k sits at theta =
    pi k / (H - 1), the first and last rows on the poles. Handed our panorama unchanged it
    stretches every row by up to half a pixel toward the poles: on the 64 x 128 courtyard that
    alone makes the spheres 1.2 % brighter than our model. :func:`envmap_texels` therefore
    resamples our piecewise-constant map onto ``upsample`` times finer texels (rows at theta =
    pi k / (upsample H), columns at the centres of ``upsample`` W cells), each texel taking the
    value of the pixel it lies in (the mean of the two when it lies on a row boundary). The
    bilinear reconstruction then departs from our pixels only within half a fine texel of a
    pixel boundary, symmetrically: measured on the same scenes, the mean radiance moves by
    0.08 % with ``upsample = 1`` and by 0.005 % with the default 4 (against 8). Mitsuba receives
    the texels as an in-memory float32 ``Bitmap`` with ``srgb_gamma`` off, so no transfer curve
    is applied (``envmap`` converts to linear float RGB, a no-op for such a bitmap).

Camera
    ``perspective`` with ``to_world = look_at(position, position + forward, up)``, taking
    position, forward and up from :meth:`PinholeCamera.axes`, ``fov_axis = 'x'`` and
    ``fov = fov_deg``. Mitsuba's ``look_at`` puts camera ``+x`` along up x forward (the image's
    left) and its film maps growing column index to ``-x``, so image right is forward x up, as
    in our camera: no horizontal flip (the tests check it with a light from one side). Film rows
    grow downward as ours. ``hdrfilm`` with a ``box`` filter of radius 0.5 averages each pixel
    over its own square, as our splats approximate it; ``hide_emitters`` keeps the background
    black and the alpha channel gives the fraction of each pixel the object covers.

Material
    Our model is f = rho_d / pi + F0 D G / (4 cos_i cos_o) (:mod:`sim.materials`). Checked in
    the Mitsuba 3 sources:

    - ``blendbsdf`` evaluates (1 - w) bsdf_0 + w bsdf_1 (weight clamped to [0, 1]); w = 0.5
      halves both, hence the factors 2 below.
    - ``diffuse`` evaluates reflectance / pi cos_o.
    - ``roughconductor`` evaluates F D G / (4 cos_i) times ``specular_reflectance`` (its
      cos_o included). ``material = 'none'`` sets eta = 0, k = 1, for which Mitsuba's
      ``fresnel_conductor`` gives r_s = r_p = 1 exactly (a = 0 in its formula): F = 1.
    - GGX ``D`` = 1 / (pi alpha^2 ((m_x^2 + m_y^2) / alpha^2 + m_z^2)^2), equal for a unit m to
      alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2); ``G`` = G1(wi) G1(wo) (separable Smith) with
      G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2 theta)) = 2 cos / (cos + sqrt(alpha^2 +
      (1 - alpha^2) cos^2)): our D and G1. Mitsuba also zeroes G1 where v . h and n . v
      differ in sign, which never happens for a reflection with both directions above.

    So ``blendbsdf(0.5, diffuse(2 rho_d), roughconductor(ggx, alpha, none, 2 F0))`` is our f
    exactly. One catch: Mitsuba refuses a plain RGB reflectance above 1 and 2 rho_d exceeds it
    (0.75 -> 1.5), so both reflectances are ``srgb`` textures with ``unbounded = True`` (in the
    RGB variants that stores the value unchanged). A material without specular (F0 = 0) is a
    plain ``diffuse`` of reflectance rho_d.

Integrator
    ``direct``: emitter and BSDF sampling combined by MIS, direct light only, as our model.
    Environment sampling converges fastest for these materials, hence the default of 8 emitter
    samples and 1 BSDF sample per camera sample; the ``multijitter`` sampler stratifies them
    (under the courtyard panorama at 256 samples per pixel its noise was 4.4 (diffuse) and 2.7
    (glossy) times lower than the ``independent`` sampler's). Variant ``scalar_rgb``: on the
    development machine the ``llvm_ad_rgb`` variant aborts the whole process inside LLVM
    (``Cannot select: fminimum``), which no ``try`` can catch, so the variant is a parameter
    rather than a fallback.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError, RigError
from sim.scenes import SceneSpec, get_scene

__all__ = [
    "ENVMAP_TO_RIG",
    "MitsubaUnavailableError",
    "ReferenceImage",
    "camera_to_world",
    "envmap_texels",
    "load_mitsuba",
    "mitsuba_scene_dict",
    "perspective_sensor",
    "render_reference",
]

#: Rotation (rows: rig x, y, z) taking a direction of the ``envmap``'s local frame to the rig
#: frame: local (x, y, z) = rig (y, z, x), see the module docstring.
ENVMAP_TO_RIG = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

DEFAULT_VARIANT = "scalar_rgb"


class MitsubaUnavailableError(RigError, ImportError):
    """Mitsuba 3 (the ``reference`` extra) is not installed or the variant cannot be used."""


@dataclass(frozen=True)
class ReferenceImage:
    """A Mitsuba rendering on our pixel grid.

    Attributes
    ----------
    rgb : ndarray, shape (H, W, 3), float32, linear radiance (0 where nothing is hit)
    coverage : ndarray, shape (H, W), float32, fraction of each pixel the object covers
    """

    rgb: NDArray[np.float32]
    coverage: NDArray[np.float32]


def load_mitsuba(variant: str = DEFAULT_VARIANT) -> Any:
    """Import Mitsuba 3 and select ``variant``; returns the ``mitsuba`` module.

    Mitsuba's variant is process-wide: this switches it for every user in the process.

    Raises
    ------
    MitsubaUnavailableError
        Mitsuba is not installed, or it was built without ``variant``.
    """
    try:
        # importlib keeps the import lazy and the handle untyped: Mitsuba's stubs describe one
        # variant at a time, which a static checker cannot follow.
        mi: Any = importlib.import_module("mitsuba")
    except ImportError as error:
        raise MitsubaUnavailableError(
            "Mitsuba 3 is not installed: pip install -e '.[reference]'"
        ) from error
    if mi.variant() != variant:
        if variant not in mi.variants():
            raise MitsubaUnavailableError(
                f"this Mitsuba build has no variant {variant!r}; available: {mi.variants()}"
            )
        mi.set_variant(variant)
    return mi


def camera_to_world(mi: Any, camera: PinholeCamera) -> Any:
    """Mitsuba's ``to_world`` of ``camera``: ``look_at`` from its position along its axes."""
    _, up, forward = camera.axes()
    return mi.ScalarTransform4f().look_at(
        origin=[float(c) for c in camera.position],
        target=[float(c) for c in camera.position + forward],
        up=[float(c) for c in up],
    )


def perspective_sensor(mi: Any, camera: PinholeCamera, sampler: dict[str, Any]) -> dict[str, Any]:
    """The ``perspective`` sensor of ``camera`` on the project's pixel grid (see the module).

    RGBA float film with a box filter (each pixel its own square, as the splats approximate
    it), ``sampler`` the sampler's dictionary.
    """
    return {
        "type": "perspective",
        "fov": float(camera.fov_deg),
        "fov_axis": "x",
        "to_world": camera_to_world(mi, camera),
        "film": {
            "type": "hdrfilm",
            "width": camera.width,
            "height": camera.height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgba",
            "component_format": "float32",
        },
        "sampler": sampler,
    }


def envmap_texels(rgb: NDArray[np.floating], upsample: int = 4) -> NDArray[np.float32]:
    """Resample our panorama onto the texel grid of Mitsuba's ``envmap``.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), linear radiance in our convention (``docs/conventions.md``)
    upsample : int, >= 1, texels per pixel along each axis

    Returns
    -------
    ndarray, shape (upsample H + 1, upsample W, 3), float32
        Texel (k, m) holds our radiance at inclination pi k / (upsample H) and column centre
        (m + 0.5) / (upsample W) (the pixel's value; the mean of two pixels on a row boundary).
    """
    image = np.asarray(rgb, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[1] != 2 * image.shape[0]:
        raise InputError(f"expected an (H, 2H, 3) panorama, got shape {image.shape}")
    if upsample < 1:
        raise InputError(f"upsample must be at least 1, got {upsample}")
    height = image.shape[0]
    k = np.arange(upsample * height + 1)
    # Row boundaries fall on texels (k a multiple of upsample); averaging the two rows there
    # keeps the bilinear ramp centred on the boundary, so no light moves up or down.
    below = np.clip(k // upsample, 0, height - 1)
    above = np.clip(-(-k // upsample) - 1, 0, height - 1)
    rows = 0.5 * (image[below] + image[above])
    return np.ascontiguousarray(np.repeat(rows, upsample, axis=1), dtype=np.float32)


def _colour(mi: Any, value: NDArray[np.floating]) -> dict[str, Any]:
    # ``unbounded`` lets 2 rho_d exceed 1 (a plain RGB reflectance is refused above 1).
    return {
        "type": "srgb",
        "color": mi.ScalarColor3f(*(float(c) for c in value)),
        "unbounded": True,
    }


def _material(mi: Any, spec: SceneSpec) -> dict[str, Any]:
    rho_d = np.asarray(spec.material.rho_d, dtype=np.float64)
    f0 = np.asarray(spec.material.f0, dtype=np.float64)
    if not f0.any():
        return {"type": "diffuse", "reflectance": _colour(mi, rho_d)}
    return {
        "type": "blendbsdf",
        "weight": 0.5,
        "bsdf_0": {"type": "diffuse", "reflectance": _colour(mi, 2.0 * rho_d)},
        "bsdf_1": {
            "type": "roughconductor",
            "material": "none",
            "distribution": "ggx",
            "alpha": float(spec.material.alpha),
            "specular_reflectance": _colour(mi, 2.0 * f0),
        },
    }


def mitsuba_scene_dict(
    spec: SceneSpec,
    rgb: NDArray[np.floating],
    camera: PinholeCamera,
    *,
    spp: int = 256,
    emitter_samples: int = 8,
    bsdf_samples: int = 1,
    seed: int = 0,
    upsample: int = 4,
    variant: str = DEFAULT_VARIANT,
) -> dict[str, Any]:
    """The Mitsuba scene of :func:`render_reference`, for inspection or to adjust.

    Parameters are those of :func:`render_reference` (with the scene as a ``SceneSpec``).

    Returns
    -------
    dict
        For ``mitsuba.load_dict``: ``integrator``, ``sensor`` (film ``camera.width`` x
        ``camera.height``, RGBA float32), ``environment`` (the panorama) and ``object``.
    """
    mi = load_mitsuba(variant)
    if spec.geometry.get("type") != "sphere" or spec.texture is not None:
        raise InputError(
            f"scene {spec.name!r} cannot be rebuilt in Mitsuba yet; only untextured spheres can"
        )
    if spp < 1 or emitter_samples < 0 or bsdf_samples < 0 or emitter_samples + bsdf_samples < 1:
        raise InputError(
            f"need spp >= 1 and at least one emitter or BSDF sample, got spp={spp}, "
            f"emitter_samples={emitter_samples}, bsdf_samples={bsdf_samples}"
        )
    bitmap = mi.Bitmap(envmap_texels(rgb, upsample))
    to_rig = np.eye(4)
    to_rig[:3, :3] = ENVMAP_TO_RIG
    return {
        "type": "scene",
        "integrator": {
            "type": "direct",
            "emitter_samples": emitter_samples,
            "bsdf_samples": bsdf_samples,
            "hide_emitters": True,
        },
        "sensor": perspective_sensor(
            mi, camera, {"type": "multijitter", "sample_count": spp, "seed": seed}
        ),
        "environment": {
            "type": "envmap",
            "bitmap": bitmap,
            "to_world": mi.ScalarTransform4f(to_rig.tolist()),
        },
        "object": {
            "type": "sphere",
            "center": [float(c) for c in spec.geometry["center"]],
            "radius": float(spec.geometry["radius"]),
            "bsdf": _material(mi, spec),
        },
    }


def render_reference(
    scene: str | SceneSpec,
    rgb: NDArray[np.floating],
    camera: PinholeCamera,
    *,
    spp: int = 256,
    emitter_samples: int = 8,
    bsdf_samples: int = 1,
    seed: int = 0,
    upsample: int = 4,
    variant: str = DEFAULT_VARIANT,
) -> ReferenceImage:
    """Render a scene of :mod:`sim.scenes` under a panorama with Mitsuba 3.

    Parameters
    ----------
    scene : str or SceneSpec
        A sphere scene (``diffuse-sphere``, ``glossy-sphere``).
    rgb : ndarray, shape (H, W, 3), W = 2H, linear radiance in our panorama convention
    camera : PinholeCamera
    spp : int
        Camera samples per pixel (``multijitter`` rounds it up to a product of two near-equal
        integers; a square avoids the rounding and its log message).
    emitter_samples, bsdf_samples : int
        Light and BSDF samples of the ``direct`` integrator per camera sample, combined by MIS.
        Environment sampling converges fastest here (see the module docstring).
    seed : int, seed of Mitsuba's sampler
    upsample : int, envmap texels per panorama pixel along each axis (see the module docstring)
    variant : str, Mitsuba variant (an RGB one)

    Returns
    -------
    ReferenceImage
        ``rgb`` (H, W, 3) float32 and ``coverage`` (H, W) float32 on the grid of
        :func:`sim.ground_truth.render_environment` for the same camera.

    Raises
    ------
    MitsubaUnavailableError
        Mitsuba 3 is not installed.
    InputError
        The scene is not a sphere, or an argument is out of range.
    """
    spec = get_scene(scene) if isinstance(scene, str) else scene
    mi = load_mitsuba(variant)
    scene_dict = mitsuba_scene_dict(
        spec,
        rgb,
        camera,
        spp=spp,
        emitter_samples=emitter_samples,
        bsdf_samples=bsdf_samples,
        seed=seed,
        upsample=upsample,
        variant=variant,
    )
    image = np.array(mi.render(mi.load_dict(scene_dict), seed=seed), dtype=np.float32)
    return ReferenceImage(
        rgb=np.ascontiguousarray(image[:, :, :3]), coverage=np.ascontiguousarray(image[:, :, 3])
    )
