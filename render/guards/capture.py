"""The guards of the capture and the view: ghosting, views off the cameras, bad captures."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.directions import angle_between
from core.field_store import ReflectanceField
from processing.interpolation import mean_spacing_deg
from processing.sample_models import ParametricFit, SampleModels, choose_model
from render.engines.modes import HeldOutComparison
from render.guards.warning import RelightWarning, lobe_width_deg, model_advice

__all__ = [
    "CEILING_TOLERANCE",
    "CLIPPED_OBSERVATIONS",
    "GHOST_SPACING",
    "GRAZING_INCLINATION_DEG",
    "NOISY_LOO",
    "clipped_observation_share",
    "empty_camera_warning",
    "empty_cameras",
    "fitted_lobe_alpha",
    "ghosting_warning",
    "grazing_view_warning",
    "noisy_capture_warning",
    "saturated_capture_warning",
    "view_warning",
]

#: A lobe is ghosted when the light spacing exceeds this share of its full width at half max.
GHOST_SPACING = 0.5
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
#: Leave-one-light-out error of the best model above which the capture is called noisy
#: (clean simulated fields 0-11 % (the torus: its shadows), well exposed 1-5 %; the brightest
#: values at 0.2 % of the well: 27-57 %).
NOISY_LOO = 0.2


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
