"""Plain-language warnings for the cases where relighting is known to go wrong.

Each guard looks at the inputs only (the field's light and camera layout, its fitted lobes, the
view, the panorama) and says what to expect and what fixes it. The thresholds come from the
accuracy study (docs/models.md, ``python -m bench.relight``): interpolating a GGX lobe of
roughness 0.2 (full width about 30 degrees in light direction) from 30 lights (spacing about
26 degrees) misses it by 24-41 %; from 400 lights (about 7 degrees) by 2 % under light from
above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.interpolation import mean_spacing_deg
from processing.sample_models import ParametricFit, SampleModels, choose_model
from rig.camera_model import PinholeCamera
from rig.directions import angle_between

__all__ = [
    "RelightWarning",
    "clipped_panorama_warning",
    "fitted_lobe_alpha",
    "ghosting_warning",
    "lobe_width_deg",
    "view_warning",
]

#: A lobe is ghosted when the light spacing exceeds this share of its full width at half max.
GHOST_SPACING = 0.5
#: A panorama whose brightest value is at most this, on many pixels, was clipped (8-bit photo).
LDR_CEILING = 1.0
#: Share of pixels at the ceiling that marks a clipped panorama.
CLIPPED_SHARE = 1e-3


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
    """
    a2 = alpha * alpha
    if a2 >= 1.0 / math.sqrt(2.0):
        return 180.0  # no half maximum above the horizon: a broad lobe
    cos2 = (a2 * math.sqrt(2.0) - 1.0) / (a2 - 1.0)
    return 4.0 * math.degrees(math.acos(math.sqrt(cos2)))


def ghosting_warning(light_directions: NDArray[np.floating], alpha: float) -> RelightWarning | None:
    """Warn when interpolating between the measured lights cannot follow a lobe of ``alpha``.

    Parameters
    ----------
    light_directions : ndarray, shape (T, 3), the measured lights
    alpha : float, the typical fitted GGX roughness of the object's samples
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
        f"ghost the highlights; relight through the per-sample models (--scheme model), or "
        f"capture about {needed} light positions",
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
    camera_directions: NDArray[np.floating], camera: PinholeCamera
) -> RelightWarning | None:
    """Warn when the view is farther from every captured camera than their spacing.

    Blending captured views then extrapolates (a view below the lowest ring, say); the
    per-sample models evaluate the fitted BRDF at the view instead.
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
        f"{spacing:.0f} deg apart): blending the captured views extrapolates here; relight "
        "through the per-sample models (--scheme model) or capture cameras nearer this view",
    )


def clipped_panorama_warning(rgb: NDArray[np.floating]) -> RelightWarning | None:
    """Warn when a panorama looks like a clipped 8-bit photo (its sun is not measured)."""
    peak = float(np.max(rgb))
    if peak > LDR_CEILING:
        return None
    at_peak = float(np.mean(np.max(rgb, axis=2) >= peak * (1.0 - 1e-6)))
    if at_peak < CLIPPED_SHARE:
        return None
    return RelightWarning(
        "clipped-panorama",
        f"the panorama's brightest value is {peak:.3g} on {at_peak:.1%} of its pixels: an LDR "
        "photo that clips its sun and sky, so the lighting is too dim and too soft; use an HDR "
        "panorama (EXR or Radiance .hdr)",
    )
