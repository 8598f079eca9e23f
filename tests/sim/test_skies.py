from __future__ import annotations

import numpy as np
import pytest

from core.colour import REC709_LUMINANCE
from core.directions import direction_from_angles_deg, panorama_directions, panorama_solid_angles
from core.errors import InputError
from render.guards import clipped_panorama_warning
from sim.skies import ldr_photo, procedural_sky


def _energy(rgb: np.ndarray) -> np.ndarray:
    """Luminous energy per pixel (luminance x solid angle)."""
    return (rgb @ REC709_LUMINANCE) * panorama_solid_angles(rgb.shape[0], rgb.shape[1])


@pytest.mark.parametrize("height", [16, 128])
@pytest.mark.parametrize("share", [0.5, 0.9, 0.99])
def test_the_sun_carries_its_share_of_the_light(height: int, share: float) -> None:
    rgb = procedural_sky(height, sun_azimuth_deg=120.0, sun_inclination_deg=35.0, sun_share=share)
    energy = _energy(rgb)
    brightest = np.unravel_index(np.argmax(energy), energy.shape)
    sun = direction_from_angles_deg(120.0, 35.0)
    towards = panorama_directions(height, 2 * height)[brightest]
    assert np.degrees(np.arccos(min(1.0, float(towards @ sun)))) < 180.0 / height * 1.5
    in_disc = rgb.max(axis=2) >= rgb.max() * 0.999
    assert energy[in_disc].sum() / energy.sum() == pytest.approx(share, rel=1e-5)
    assert np.all(rgb >= 0) and rgb.dtype == np.float32


def test_the_ldr_photo_clips_the_sun_and_the_guard_says_so() -> None:
    hdr = procedural_sky(64, sun_share=0.9)
    ldr = ldr_photo(hdr)
    assert ldr.shape == hdr.shape and ldr.dtype == np.float32
    assert _energy(ldr).sum() < 0.2 * _energy(hdr).sum()  # the sun is gone
    sky = hdr.max(axis=2) < 1.0  # the dim sky survives to 8-bit precision
    np.testing.assert_allclose(ldr[sky].mean(), hdr[sky].mean(), rtol=0.05)
    assert clipped_panorama_warning(hdr) is None
    assert clipped_panorama_warning(ldr * (ldr.max() ** -1)) is not None


def test_bad_skies_are_refused() -> None:
    with pytest.raises(InputError, match="horizon"):
        procedural_sky(16, sun_inclination_deg=100.0)
    with pytest.raises(InputError, match="sun_share"):
        procedural_sky(16, sun_share=1.0)
