"""Environments the shared panoramas lack: a procedural sky with a sun, and LDR photos.

A procedural sky with a small, very bright sun, and the LDR photo of any panorama (what an
ordinary camera records: exposed, clipped, 8-bit sRGB).

Both are stress cases for relighting (docs/models.md; issue 7's benchmark): a sun is nearly all
of the light in half a degree, which few sampled lights and sparse measured lights handle
worst; an LDR photo clips that sun and the bright sky.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from core.colour import linear_to_srgb, luminance, srgb_to_linear
from core.directions import (
    direction_from_angles_deg,
    panorama_directions,
    panorama_solid_angles,
)
from core.errors import InputError

__all__ = ["SUN_DIAMETER_DEG", "ldr_photo", "procedural_sky"]

#: The sun's angular diameter seen from the earth, degrees.
SUN_DIAMETER_DEG = 0.53


def procedural_sky(
    height: int = 256,
    *,
    sun_azimuth_deg: float = 30.0,
    sun_inclination_deg: float = 40.0,
    sun_diameter_deg: float = SUN_DIAMETER_DEG,
    sun_share: float = 0.9,
    sky_rgb: tuple[float, float, float] = (0.35, 0.5, 0.9),
    ground_rgb: tuple[float, float, float] = (0.12, 0.1, 0.08),
) -> NDArray[np.float32]:
    """An equirectangular HDR sky (H, 2H, 3), float32, linear radiance.

    A blue sky brightening toward the horizon, a dark ground below it, and a sun disc carrying
    ``sun_share`` of the panorama's total luminous energy (integral of luminance x solid angle).
    The disc covers the pixels whose centres lie within its radius; at least the one pixel
    nearest the sun direction, so the sun's energy is exact at any resolution.

    Parameters
    ----------
    height : int, rows (width 2 x height)
    sun_azimuth_deg, sun_inclination_deg : the sun's direction, degrees (inclination < 90:
        above the horizon)
    sun_diameter_deg : float, angular diameter of the disc
    sun_share : float in [0, 1), share of the energy in the sun
    sky_rgb, ground_rgb : radiance of the zenith sky and of the ground
    """
    if height < 2:
        raise InputError(f"a sky needs at least 2 rows, got {height}")
    if not 0.0 <= sun_share < 1.0:
        raise InputError(f"sun_share must be in [0, 1), got {sun_share}")
    if not 0.0 <= sun_inclination_deg < 90.0:
        raise InputError(
            f"the sun must be above the horizon, got inclination {sun_inclination_deg}"
        )
    directions = panorama_directions(height, 2 * height)
    omega = panorama_solid_angles(height, 2 * height)
    up = directions[:, :, 2]
    horizon_glow = 1.0 + 1.5 * (1.0 - np.clip(up, 0.0, 1.0)) ** 4
    sky = np.asarray(sky_rgb)[None, None, :] * horizon_glow[:, :, None]
    rgb = np.where((up > 0.0)[:, :, None], sky, np.asarray(ground_rgb)[None, None, :])
    sun = direction_from_angles_deg(sun_azimuth_deg, sun_inclination_deg)
    cosine = directions @ sun
    disc = cosine >= math.cos(math.radians(sun_diameter_deg / 2.0))
    if not disc.any():
        disc[np.unravel_index(np.argmax(cosine), cosine.shape)] = True
    rest = float(np.sum(luminance(rgb) * omega * ~disc))
    sun_energy = rest * sun_share / (1.0 - sun_share)
    white = np.array([1.0, 0.95, 0.85])
    radiance = sun_energy / float(np.sum(omega[disc])) / float(luminance(white))
    rgb[disc] = radiance * white
    return rgb.astype(np.float32)


def ldr_photo(rgb: NDArray[np.floating], *, exposure: float | None = None) -> NDArray[np.float32]:
    """What an ordinary 8-bit photo of the panorama records, decoded back to linear.

    Exposed so the median luminance sits at 18 % grey (or by ``exposure``), clipped at 1,
    quantised to 8-bit sRGB and decoded: shape and dtype as the input's, float32.
    """
    linear = np.asarray(rgb, dtype=np.float32)
    if exposure is None:
        median = float(np.median(luminance(linear)))
        exposure = 0.18 / median if median > 0 else 1.0
    encoded = np.round(linear_to_srgb(np.clip(linear * exposure, 0.0, 1.0)) * 255.0) / 255.0
    return srgb_to_linear(encoded) / np.float32(exposure)
