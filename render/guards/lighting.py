"""The guards of the panorama: clipped, lit by a sun, or lit from outside the measured lights."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.colour import luminance
from core.directions import angle_between, panorama_directions, panorama_solid_angles
from core.errors import InputError
from processing.interpolation import mean_spacing_deg
from processing.measured_region import MeasuredRegion
from processing.panorama import downsample_panorama
from render.engines.modes import HeldOutComparison
from render.guards.warning import RelightWarning, lobe_width_deg, model_advice

__all__ = [
    "CLIPPED_SHARE",
    "LDR_CEILING",
    "OUTSIDE_ROWS",
    "OUTSIDE_SHARE",
    "SUN_CAP_DEG",
    "SUN_DIFFUSE_SPACING_DEG",
    "SUN_GHOST_SPACING",
    "SUN_SHARE",
    "SUN_VIEW_OFFSET",
    "clipped_panorama_warning",
    "outside_light_share",
    "outside_light_warning",
    "sun_share",
    "sun_warning",
]

#: A panorama whose brightest value is at most this, on many pixels, was clipped (8-bit photo).
LDR_CEILING = 1.0
#: Share of pixels at the ceiling that marks a clipped panorama.
CLIPPED_SHARE = 1e-3
#: Radius of the cap around the panorama's brightest pixel counted as its sun, degrees (the
#: sun is 0.53 degrees wide; a 64-row panorama's pixels are 2.8 degrees).
SUN_CAP_DEG = 3.0
#: Share of the panorama's luminous energy in that cap above which it is lit by a sun.
SUN_SHARE = 0.5
#: Without a lobe, a sun is interpolated badly from lights farther apart than this, degrees
#: (bench.stability, diffuse sphere, 12 cameras, sky with 90 % in its sun: 44 degrees apart
#: 13 %, 24 degrees 2.5 %, 13 degrees 1.6 %).
SUN_DIFFUSE_SPACING_DEG = 30.0
#: With a lobe, a sun's highlight ghosts when the light spacing exceeds this share of the
#: lobe's width (glossy sphere, alpha 0.2 (30 degrees), captured view: spacing 0.79 of the
#: width 16 %, 0.44: 6.8 %, 0.32: 4.4 %, 0.22: 2.4 %; no sun 4-9 %).
SUN_GHOST_SPACING = 0.4
#: ... or when the view is farther than this share of the lobe's width from every captured
#: camera (same field, 100 lights: 0 degrees off 6.8 %, 2.8 degrees (0.09 width) 13 %, 5.6
#: degrees 21 %, 9.3 degrees 30 %).
SUN_VIEW_OFFSET = 0.05
#: Share of the panorama's luminous energy outside the measured lights' region above which
#: interpolating it is warned of (path-traced worlds, S = T = 30, 30 lights: the courtyard puts
#: 54 % there, the studio 73 %; see :func:`outside_light_warning`).
OUTSIDE_SHARE = 0.5
#: Rows of the panorama :func:`outside_light_share` reads.
OUTSIDE_ROWS = 64


def clipped_panorama_warning(rgb: NDArray[np.floating]) -> RelightWarning | None:
    """Warn when a panorama looks like a clipped 8-bit photo (its sun is not measured).

    Clipping leaves a plateau: many white pixels at exactly the brightest value. That is so at any
    scale (an LDR photo decoded and divided by its exposure, or scaled to a known total), so
    a plateau of :data:`CLIPPED_SHARE` to half the pixels counts; a panorama whose peak is at
    most :data:`LDR_CEILING` on that share counts too. Measured by ``python -m
    bench.stability``: the sky with 90 % in its sun as an 8-bit photo, scaled to the right
    total light, misses the diffuse sphere by 60-64 % against 0.3-15 % from the HDR sky.
    """
    image = np.asarray(rgb)
    peak = float(np.max(image))
    if peak <= 0.0:
        return None
    top = np.max(image, axis=2)
    on = top >= peak * (1.0 - 1e-6)
    at_peak = float(np.mean(on))
    # A clipped photo's plateau holds white pixels (every channel clipped) or pixels of many
    # colours (one channel clipped); one non-white colour is a synthetic sky's brightest
    # ring, and a panorama mostly at one value a uniform test environment.
    least = image[on].min(axis=1)
    white = bool(np.all(least >= peak * (1.0 - 1e-6)))
    varied = float(np.ptp(least)) > 1e-3 * peak
    plateau = CLIPPED_SHARE <= at_peak <= 0.5 and (white or varied)
    if not (plateau or (peak <= LDR_CEILING and at_peak >= CLIPPED_SHARE)):
        return None
    return RelightWarning(
        "clipped-panorama",
        f"the panorama's brightest value is {peak:.3g} on {at_peak:.1%} of its pixels: an LDR "
        "photo that clips its sun and sky, so the lighting is too dim and too soft; use an HDR "
        "panorama (EXR or Radiance .hdr)",
    )


def sun_share(rgb: NDArray[np.floating]) -> float:
    """Share of a panorama's luminous energy within :data:`SUN_CAP_DEG` of its brightest pixel.

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), linear radiance

    Returns
    -------
    float in [0, 1] (0 for a black panorama)
    """
    image = np.asarray(rgb, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"a panorama must be (H, W, 3), got shape {image.shape}")
    height, width = image.shape[:2]
    energy = luminance(image).astype(np.float64) * panorama_solid_angles(height, width)
    total = float(energy.sum())
    if total <= 0.0:
        return 0.0
    directions = panorama_directions(height, width)
    peak = directions[np.unravel_index(np.argmax(luminance(image)), (height, width))]
    cap = directions @ peak >= math.cos(math.radians(SUN_CAP_DEG))
    return float(energy[cap].sum() / total)


def sun_warning(
    rgb: NDArray[np.floating],
    light_directions: NDArray[np.floating],
    alpha: float | None,
    *,
    interpolation: str = "barycentric",
    camera_directions: NDArray[np.floating] | None = None,
    camera: PinholeCamera | None = None,
    comparison: HeldOutComparison | None = None,
) -> RelightWarning | None:
    """Warn when a sun dominates the panorama and interpolation cannot place its light.

    A sun is one direction carrying most of the light: interpolation spreads it over the
    neighbouring measured lights (and a view over the neighbouring cameras), so a glossy
    object shows several displaced highlights and a matte one a blurred terminator. Measured
    by ``python -m bench.stability`` (relative RMSE, S = 12, a sky with 90 % in its sun):

    - matte (``alpha`` None): lights 44 degrees apart 13 %, 24 degrees 2.5 % ->
      :data:`SUN_DIFFUSE_SPACING_DEG` 30;
    - glossy (GGX alpha 0.2, lobe 30 degrees): light spacing over :data:`SUN_GHOST_SPACING`
      (0.4) of the lobe width, the paper's m-nearest cosine interpolation at any density
      (28-41 % from 30 to 400 lights), or a view more than :data:`SUN_VIEW_OFFSET` (0.05) of
      the width from every camera (2.8 degrees off: 13 %, halfway between cameras 41-46 %).

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), the panorama
    light_directions : ndarray, shape (T, 3), the measured lights
    alpha : float or None, the fitted lobe's roughness (:func:`fitted_lobe_alpha`)
    interpolation : str, the light interpolation of the relighting ("paper" blends the m
        nearest lights whatever their spacing)
    camera_directions : ndarray, shape (S, 3), optional; with ``camera``, checks the view
    camera : PinholeCamera, optional, the wanted view
    comparison : HeldOutComparison, optional, whether the models beat interpolation (a
        held-out light is a sun: the comparison measures this very case)
    """
    share = sun_share(rgb)
    if share < SUN_SHARE:
        return None
    spacing = mean_spacing_deg(light_directions)
    count = len(light_directions)
    intro = f"the panorama puts {share:.0%} of its light in a sun"
    if alpha is None:
        if spacing <= SUN_DIFFUSE_SPACING_DEG:
            return None
        needed = math.ceil(count * (spacing / SUN_DIFFUSE_SPACING_DEG) ** 2)
        return RelightWarning(
            "sun-sparse-lights",
            f"{intro} and the measured lights are {spacing:.0f} deg apart: interpolating them "
            f"blurs its shading and shadows (expect 10 % error or more); "
            + model_advice(comparison, f"capture about {needed} light positions"),
        )
    width = lobe_width_deg(alpha)
    reasons = []
    fix = "capture more light positions"
    if interpolation == "paper":
        reasons.append("the paper's interpolation blends the 3 nearest lights at any spacing")
    elif spacing > SUN_GHOST_SPACING * width:
        needed = math.ceil(count * (spacing / (SUN_GHOST_SPACING * width)) ** 2)
        fix = f"capture about {needed} light positions"
        reasons.append(
            f"the lights are {spacing:.0f} deg apart against a {width:.0f} deg lobe "
            f"(about {needed} light positions would follow it)"
        )
    if camera_directions is not None and camera is not None and len(camera_directions):
        nearest = float(
            np.degrees(np.min(angle_between(camera_directions, camera.direction[None, :])))
        )
        if nearest > SUN_VIEW_OFFSET * width:
            reasons.append(f"the view is {nearest:.1f} deg from the nearest captured camera")
            fix += " and view from a captured camera"
    if not reasons:
        return None
    return RelightWarning(
        "sun-ghosting",
        f"{intro}, and {'; '.join(reasons)}: its highlight will show as several ghosted copies "
        "(expect 10-45 % error); " + model_advice(comparison, fix),
    )


def outside_light_share(rgb: NDArray[np.floating], light_directions: NDArray[np.floating]) -> float:
    """Share of a panorama's luminous energy outside the region of the measured lights.

    Outside is below the lowest measured lights or below the horizon
    (:class:`processing.measured_region.MeasuredRegion`); the panorama is read at 64 rows.

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), linear radiance
    light_directions : ndarray, shape (T, 3), the measured lights, rig frame

    Returns
    -------
    float in [0, 1] (0 for a black panorama)
    """
    image = np.asarray(rgb, dtype=np.float32)
    if image.shape[0] > OUTSIDE_ROWS:
        image = downsample_panorama(image, OUTSIDE_ROWS)
    height, width = image.shape[:2]
    energy = luminance(image).astype(np.float64) * panorama_solid_angles(height, width)
    total = float(energy.sum())
    if total <= 0.0:
        return 0.0
    region = MeasuredRegion.build(np.asarray(light_directions, dtype=np.float64))
    outside = region.outside(panorama_directions(height, width).reshape(-1, 3))
    return float(energy.reshape(-1)[outside].sum() / total)


def outside_light_warning(
    rgb: NDArray[np.floating], light_directions: NDArray[np.floating]
) -> RelightWarning | None:
    """Warn when most of the light comes from where no light was measured.

    Interpolation repeats the lowest measured lights for light from below them (and from below
    the horizon, which a rig's base blocks but an open scene does not); the per-sample models
    evaluate their BRDF there. Measured by ``python -m bench.advisor_world`` (path-traced worlds,
    S = T = 30, 30 lights, between view): under the studio (73 % outside) the models err 22.6 %
    against 29.7 % for the best interpolation (matte relief) and 43.8 % against 63.7 % (copper
    bowl); under the courtyard (54 %) 15.8 against 16.0 % and 35.7 against 38.2 %. Under a
    uniform white sphere interpolation errs 10-25 %, under the upper half alone 4-5 %.
    Threshold :data:`OUTSIDE_SHARE`.
    """
    share = outside_light_share(rgb, light_directions)
    if share <= OUTSIDE_SHARE:
        return None
    lowest = float(np.degrees(np.arccos(np.clip(np.min(light_directions[:, 2]), -1.0, 1.0))))
    return RelightWarning(
        "light-outside",
        f"{share:.0%} of the panorama's light comes from outside the measured lights (below "
        f"the lowest, at {lowest:.0f} deg inclination, or below the horizon): interpolation "
        "repeats the lowest lights there, while the per-sample models evaluate their BRDF "
        "(on path-traced worlds they did better here by 0.2-20 points); relight through the "
        "models (--scheme model), capture lights nearer the horizon, or darken the panorama "
        "below the horizon if the object stands on a base that blocks that light",
    )
