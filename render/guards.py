"""Over 500 lines because each guard keeps its own thresholds and plain-language advice.

Plain-language warnings for the cases where relighting is known to go wrong.

Each guard looks at the inputs only (the field's light and camera layout, its fitted lobes, the
view, the panorama) and says what to expect and what fixes it. Where the fix might be to relight
through the per-sample models, the advice follows the field's own held-out comparison
(:class:`render.engines.modes.HeldOutComparison`): the models are advised only where they predicted
lights they never saw better than interpolation did, and the figures are quoted. On a world no
model contains, the old unconditional advice made results worse where it fired (``python -m
bench.guard_advice``, docs/evaluation.md). The thresholds come from the
accuracy study (docs/models.md, ``python -m bench.relight``): interpolating a GGX lobe of
roughness 0.2 (full width about 30 degrees in light direction) from 30 lights (spacing about
26 degrees) misses it by 24-41 %; from 400 lights (about 7 degrees) by 2 % under light from
above.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.colour import luminance
from core.directions import angle_between, panorama_directions, panorama_solid_angles
from core.errors import InputError
from core.field_store import ReflectanceField
from processing.interpolation import mean_spacing_deg
from processing.measured_region import MeasuredRegion
from processing.panorama import downsample_panorama
from processing.sample_models import ParametricFit, SampleModels, choose_model
from render.engines.modes import HeldOutComparison, RelightMode

__all__ = [
    "RelightWarning",
    "clipped_observation_share",
    "clipped_panorama_warning",
    "empty_camera_warning",
    "empty_cameras",
    "fitted_lobe_alpha",
    "ghosting_warning",
    "grazing_view_warning",
    "lobe_width_deg",
    "model_advice",
    "noisy_capture_warning",
    "outside_light_share",
    "outside_light_warning",
    "relight_warnings",
    "saturated_capture_warning",
    "sun_share",
    "sun_warning",
    "view_warning",
]

#: A lobe is ghosted when the light spacing exceeds this share of its full width at half max.
GHOST_SPACING = 0.5
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
#: Views this close to the horizon or lower, and below every captured camera, are grazing
#: (inclination, degrees).
GRAZING_INCLINATION_DEG = 80.0
#: Observations within this relative distance of their image's brightest value sit at its
#: ceiling (a saturated sensor reads one value; the dark frame adds about 1e-4 of noise).
CEILING_TOLERANCE = 1e-3
#: Share of the lit observations at their image's ceiling that marks a saturated capture
#: (clean or well-exposed simulated fields: 0.10-0.14 %, a sun-lit cap; exposed 3x too long:
#: 3.0 % on the glossy sphere, 49 % on the diffuse one).
CLIPPED_OBSERVATIONS = 0.01
#: Share of the panorama's luminous energy outside the measured lights' region above which
#: interpolating it is warned of (path-traced worlds, S = T = 30, 30 lights: the courtyard puts
#: 54 % there, the studio 73 %; see :func:`outside_light_warning`).
OUTSIDE_SHARE = 0.5
#: Rows of the panorama :func:`outside_light_share` reads.
OUTSIDE_ROWS = 64
#: Leave-one-light-out error of the best model above which the capture is called noisy
#: (clean simulated fields 0-11 % (the torus: its shadows), well exposed 1-5 %; the brightest
#: values at 0.2 % of the well: 27-57 %).
NOISY_LOO = 0.2


@dataclass(frozen=True)
class RelightWarning:
    """One warning: a short code for programs and the sentence for people."""

    code: str
    message: str

    def __str__(self) -> str:
        return f"warning ({self.code}): {self.message}"


def lobe_width_deg(alpha: float) -> float:
    """Full width at half maximum of a GGX lobe of roughness ``alpha``, in light direction, deg.

    D(h) falls to half its peak at a half-vector angle t with cos^2 t = (alpha^2 sqrt 2 - 1) /
    (alpha^2 - 1); the reflected light direction turns twice as fast as the half vector, and the
    full width is twice the half width: 4 t.

    A closed form solved from D as :func:`core.brdf.ggx_distribution` defines it (tests hold
    D at t to half its peak), not a shading: there is no part of the shading sum to call here.
    """
    a2 = alpha * alpha
    if a2 >= 1.0 / math.sqrt(2.0):
        return 180.0  # no half maximum above the horizon: a broad lobe
    cos2 = (a2 * math.sqrt(2.0) - 1.0) / (a2 - 1.0)
    return 4.0 * math.degrees(math.acos(math.sqrt(cos2)))


def model_advice(comparison: HeldOutComparison | None, fix: str) -> str:
    """The advice of a guard that the per-sample models might cure, as the field measured it.

    Parameters
    ----------
    comparison : HeldOutComparison or None, the field's models against interpolation on
        held-out lights (None: not measured)
    fix : str, the cure that does not depend on the models (a denser capture, say)
    """
    if comparison is None:
        return (
            f"{fix}; the per-sample models (--scheme model) may do better: rig evaluate FIELD "
            "--split every-other measures whether they do"
        )
    if comparison.models_win:
        return f"relight through the per-sample models (--scheme model; {comparison}), or {fix}"
    return f"the per-sample models do not help here ({comparison}): {fix}"


def ghosting_warning(
    light_directions: NDArray[np.floating],
    alpha: float,
    comparison: HeldOutComparison | None = None,
) -> RelightWarning | None:
    """Warn when interpolating between the measured lights cannot follow a lobe of ``alpha``.

    Parameters
    ----------
    light_directions : ndarray, shape (T, 3), the measured lights
    alpha : float, the typical fitted GGX roughness of the object's samples
    comparison : HeldOutComparison, optional, whether the models beat interpolation
    """
    spacing = mean_spacing_deg(light_directions)
    width = lobe_width_deg(alpha)
    if spacing <= GHOST_SPACING * width:
        return None
    needed = math.ceil(len(light_directions) * (spacing / (GHOST_SPACING * width)) ** 2)
    return RelightWarning(
        "ghosting",
        f"specular lobe (about {width:.0f} deg wide, GGX roughness {alpha:.2f}) narrower than "
        f"twice the light spacing ({spacing:.0f} deg): interpolating the measured lights will "
        f"ghost the highlights; "
        + model_advice(comparison, f"capture about {needed} light positions"),
    )


def fitted_lobe_alpha(models: SampleModels) -> float | None:
    """Median roughness of the samples whose chosen model has a lobe, or None without lobes."""
    choice = choose_model(models)
    fit = models.fits.get("lambert+ggx")
    if choice.chosen != "lambert+ggx" or not isinstance(fit, ParametricFit):
        return None
    has_lobe = fit.fitted & np.any(fit.f0 > 0, axis=1)
    if not has_lobe.any():
        return None
    return float(np.median(fit.alpha[has_lobe]))


def view_warning(
    camera_directions: NDArray[np.floating],
    camera: PinholeCamera,
    comparison: HeldOutComparison | None = None,
) -> RelightWarning | None:
    """Warn when the view is farther from every captured camera than their spacing.

    Blending captured views then extrapolates (a view below the lowest ring, say); the
    per-sample models evaluate the fitted BRDF at the view instead, where they generalise
    (``comparison``).
    """
    directions = np.asarray(camera_directions, dtype=np.float64)
    if len(directions) < 2:
        return None
    nearest = float(np.degrees(np.min(angle_between(directions, camera.direction[None, :]))))
    spacing = mean_spacing_deg(directions)
    if nearest <= spacing:
        return None
    return RelightWarning(
        "view-outside",
        f"the view is {nearest:.0f} deg from the nearest captured camera (cameras are "
        f"{spacing:.0f} deg apart): blending the captured views extrapolates here; "
        + model_advice(comparison, "capture cameras nearer this view"),
    )


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


def grazing_view_warning(
    camera_directions: NDArray[np.floating],
    camera: PinholeCamera,
    comparison: HeldOutComparison | None = None,
) -> RelightWarning | None:
    """Warn when the view skims the horizon below every captured camera.

    The object's lower rim is then seen at grazing angles that no camera measured, and the
    view blend clamps to the lowest ring. Measured by ``python -m bench.stability`` (S = 12,
    lowest ring at 67.5 degrees, T = 30, sky without sun; best interpolation): inclination
    50 degrees 3.8 % (diffuse sphere), 7.5 % (glossy), 6.8 % (torus); 85 degrees 8.7 %, 16 %,
    10 %; the models 0.1-6 % at both. Threshold: :data:`GRAZING_INCLINATION_DEG` (80), up to
    as far below the horizon.

    Parameters
    ----------
    camera_directions : ndarray, shape (S, 3), the captured cameras
    camera : PinholeCamera, the wanted view
    comparison : HeldOutComparison, optional, whether the models beat interpolation
    """
    directions = np.asarray(camera_directions, dtype=np.float64)
    # From under the object (past 180 - 80 degrees) is no longer grazing: view_warning's case.
    if not GRAZING_INCLINATION_DEG <= camera.inclination_deg <= 180.0 - GRAZING_INCLINATION_DEG:
        return None
    if not len(directions):
        return None
    lowest = float(np.degrees(np.arccos(np.clip(directions[:, 2].min(), -1.0, 1.0))))
    if camera.inclination_deg <= lowest:
        return None
    return RelightWarning(
        "grazing-view",
        f"the view is {90.0 - camera.inclination_deg:.0f} deg above the horizon, below the "
        f"lowest captured camera ({90.0 - lowest:.0f} deg): the object is seen at grazing "
        "angles no camera measured, expect about twice the error of a higher view; "
        + model_advice(comparison, "capture a lower ring of cameras"),
    )


def clipped_observation_share(
    field: ReflectanceField, cameras: Sequence[int] | None = None
) -> float:
    """Share of the lit, visible observations that sit at their image's brightest value.

    A saturated pixel reads the sensor's ceiling, so a clipped image has many samples at one
    value; an unclipped one has a single brightest sample and the few beside it.

    Parameters
    ----------
    field : ReflectanceField
    cameras : sequence of int, optional; the camera slabs to read (default all)

    Returns
    -------
    float in [0, 1]
    """
    chosen = range(field.shape[0]) if cameras is None else cameras
    at_ceiling, lit = 0, 0
    for s in chosen:
        seen = field.visibility[s]
        brightest = field.camera_slab(int(s))[:, seen].max(axis=2)  # (T, visible)
        if brightest.size == 0:
            continue
        ceiling = brightest.max(axis=1, keepdims=True)
        on = brightest > 0.0
        at_ceiling += int(np.sum(on & (brightest >= ceiling * (1.0 - CEILING_TOLERANCE))))
        lit += int(on.sum())
    return at_ceiling / lit if lit else 0.0


def saturated_capture_warning(
    field: ReflectanceField, cameras: Sequence[int] | None = None
) -> RelightWarning | None:
    """Warn when many observations sit at their image's ceiling: the capture saturated.

    Threshold :data:`CLIPPED_OBSERVATIONS` (1 %), measured by ``python -m bench.stability``:
    clean and well-exposed simulated fields 0.10-0.14 %; exposed so the 99.9th percentile is 3
    times the full well: 3 % (glossy sphere; models 2.4 -> 30 % error under a sunny sky) and
    49 % (diffuse sphere; 0.1 -> 48 %).

    Parameters
    ----------
    field : ReflectanceField
    cameras : sequence of int, optional; the camera slabs to check (default all)
    """
    share = clipped_observation_share(field, cameras)
    if share <= CLIPPED_OBSERVATIONS:
        return None
    return RelightWarning(
        "saturated-capture",
        f"{share:.1%} of the lit observations sit at their image's ceiling: the capture "
        "saturated, so highlights and bright surfaces are too dim and the models fit to them "
        "are biased; capture an exposure bracket (or shorter exposures) and process again",
    )


def noisy_capture_warning(
    models: SampleModels, comparison: HeldOutComparison | None = None
) -> RelightWarning | None:
    """Warn when even the best model misses left-out lights by much.

    The cause is noise, clipping, or a material beyond the models.
    Threshold :data:`NOISY_LOO` (20 %) on the chosen model's leave-one-light-out error,
    measured by ``python -m bench.stability``: clean simulated fields 0-11 % (the torus's
    cast shadows), well exposed 1-5 %; brightest values at 0.2 % of the well 27 % (diffuse
    sphere; best interpolation 2.1 -> 11 % under a sunny sky) and 57 % (glossy). There the
    models average the noise over every observation (1.3-5 %) and interpolation passes it
    through; but the same error comes from a noise-free material the models do not contain
    (a glossy path-traced world), where the models do worse than interpolation. So the
    advice follows ``comparison``, the field's own held-out measurement.
    """
    choice = choose_model(models)
    loo = models.fits[choice.chosen].loo.relative_rmse
    if loo <= NOISY_LOO:
        return None
    return RelightWarning(
        "noisy-capture",
        f"the best per-sample model ({choice.chosen}) misses left-out lights by {loo:.0%}: "
        "the capture is noisy or clipped, or its material is beyond the models; "
        + model_advice(comparison, "capture longer exposures (or an exposure bracket)"),
    )


def empty_cameras(field: ReflectanceField, cameras: Sequence[int] | None = None) -> list[int]:
    """Cameras (of ``cameras``, default all) whose visible samples are black under every light.

    A camera whose images recorded nothing (a lens cap, a dead cable) or whose pose pointed
    away from the object. The store's writer records them (``dark_cameras``); only stores
    without that record (older ones, in-memory subsets) are read.
    """
    chosen = list(range(field.shape[0]) if cameras is None else cameras)
    if field.dark_cameras is not None:
        return [int(s) for s in chosen if int(s) in field.dark_cameras]
    empty = []
    for s in chosen:
        seen = field.visibility[s]
        if not seen.any() or not np.any(field.camera_slab(int(s))[:, seen]):
            empty.append(int(s))
    return empty


def empty_camera_warning(
    field: ReflectanceField, cameras: Sequence[int] | None = None
) -> RelightWarning | None:
    """Warn when camera slabs are empty: a missing camera pose or an unfinished field.

    Measured by ``python -m bench.stability`` (glossy sphere, S = 12, T = 30, courtyard, one
    camera's slabs left at 0): at that camera best interpolation 17 -> 100 %, the models
    0.2 -> 37 % (the fit takes the zeros as measured, so every view suffers: 0.1 -> 11 %).
    Any empty camera is reported.
    """
    empty = empty_cameras(field, cameras)
    if not empty:
        return None
    listed = ", ".join(str(s) for s in empty[:5]) + (", ..." if len(empty) > 5 else "")
    return RelightWarning(
        "empty-camera",
        f"camera{'s' if len(empty) > 1 else ''} {listed} of {field.path} recorded nothing "
        "(every visible sample black under every light): a missing camera pose or an "
        "interrupted processing run; views near it come out black and the models are biased. "
        "Process the dataset again (rig process), re-taking that pose if its images are missing",
    )


#: Cameras nearest the view whose slabs :func:`relight_warnings` reads for the saturation check
#: (the ones a barycentric view blend reads anyway; a whole large field would take minutes).
CHECKED_CAMERAS = 3


def relight_warnings(
    field: ReflectanceField,
    camera: PinholeCamera,
    rgb: NDArray[np.floating],
    mode: RelightMode,
    models: SampleModels | None,
    comparison: HeldOutComparison | None = None,
) -> list[RelightWarning]:
    """Every warning that applies to relighting ``field`` under ``rgb`` at ``camera``.

    The panorama and capture guards apply to every mode; the ones about interpolating the
    measured lights and cameras (sun, ghosting, views outside or grazing, noise, light from
    outside the measured lights) only to the modes that interpolate (``not mode.uses_models``),
    since the per-sample models evaluate the fitted BRDF at any light and view and average the
    noise (bench.stability).

    Parameters
    ----------
    field : ReflectanceField
    camera : PinholeCamera, the wanted view
    rgb : ndarray, shape (H, 2H, 3), the panorama as relit (after yaw and exposure)
    mode : RelightMode
    models : SampleModels or None, the field's fit (its lobe and LOO error inform the guards)
    comparison : HeldOutComparison, optional, the models against interpolation on held-out
        lights (:class:`render.engines.modes.ModeChoice`): the advice to relight through the
        models is given only where they won
    """
    found = [clipped_panorama_warning(rgb), empty_camera_warning(field)]
    nearest = np.argsort(angle_between(field.camera_directions, camera.direction[None, :]))
    found.append(saturated_capture_warning(field, [int(s) for s in nearest[:CHECKED_CAMERAS]]))
    if not mode.uses_models:
        alpha = None if models is None else fitted_lobe_alpha(models)
        points = field.sample_kind == "points"
        if points:
            found += [
                view_warning(field.camera_directions, camera, comparison),
                grazing_view_warning(field.camera_directions, camera, comparison),
            ]
        if models is not None:
            found.append(noisy_capture_warning(models, comparison))
        if alpha is not None:
            found.append(ghosting_warning(field.light_directions, alpha, comparison))
        found.append(outside_light_warning(rgb, field.light_directions))
        # A pixel field has one fixed view: nothing to interpolate between cameras.
        views = (field.camera_directions, camera) if points else (None, None)
        found.append(
            sun_warning(
                rgb,
                field.light_directions,
                alpha,
                interpolation=mode.predictors()[0][1],
                camera_directions=views[0],
                camera=views[1],
                comparison=comparison,
            )
        )
    return [w for w in found if w is not None]
