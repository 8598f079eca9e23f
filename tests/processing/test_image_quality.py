from __future__ import annotations

import math

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from core.colour import srgb_to_linear
from core.errors import InputError
from processing.image_quality import (
    clipped_srgb_8bit,
    display_scale,
    image_quality,
    psnr_8bit,
    relative_rmse,
    relative_rmse_values,
    ssim_8bit,
)


def _from_8bit(values: np.ndarray) -> np.ndarray:
    return srgb_to_linear(values.astype(np.float64) / 255.0).astype(np.float64)


def _image(seed: int = 0, size: tuple[int, int] = (16, 24)) -> np.ndarray:
    return _from_8bit(np.random.default_rng(seed).integers(20, 230, (*size, 3)))


def test_identical_images_score_perfectly() -> None:
    image = _image()
    quality = image_quality(image, image)
    assert quality.psnr == math.inf and quality.ssim == pytest.approx(1.0)
    assert quality.delta_e == 0.0 and quality.rel_rmse == 0.0
    assert quality.to_dict()["psnr"] is None  # JSON has no infinity


def test_psnr_counts_8bit_levels() -> None:
    levels = np.random.default_rng(1).integers(20, 230, (8, 8, 3))
    shifted = levels.copy()
    shifted[..., 0] += 2  # one channel of every pixel two levels up: MSE 4 / 3
    psnr = psnr_8bit(_from_8bit(shifted), _from_8bit(levels))
    assert psnr == pytest.approx(20 * math.log10(255) - 10 * math.log10(4 / 3), abs=1e-9)
    np.testing.assert_array_equal(clipped_srgb_8bit(_from_8bit(levels)), levels)


def test_the_mask_decides_which_pixels_count() -> None:
    reference = _image(2)
    predicted = reference.copy()
    predicted[:, :8] = 0.0  # wrong only in the left third
    mask = np.zeros(reference.shape[:2], dtype=bool)
    mask[:, 8:] = True
    assert psnr_8bit(predicted, reference, mask) == math.inf
    assert relative_rmse(predicted, reference, mask) == 0.0
    assert relative_rmse(predicted, reference) > 0.3
    with pytest.raises(InputError, match="selects no pixel"):
        psnr_8bit(predicted, reference, np.zeros_like(mask))


def test_ssim_is_wangs_on_the_8bit_images_and_falls_with_noise() -> None:
    reference = _image(3, (32, 32))
    noisy = np.clip(
        reference * (1 + np.random.default_rng(4).normal(0, 0.2, reference.shape)), 0, 1
    )
    ours = ssim_8bit(noisy, reference)
    theirs = structural_similarity(
        clipped_srgb_8bit(noisy), clipped_srgb_8bit(reference), channel_axis=2, data_range=255,
        gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
    )  # fmt: skip
    assert ours == pytest.approx(theirs, abs=1e-9) and ours < 0.99
    with pytest.raises(InputError, match="at least 11 x 11"):
        ssim_8bit(reference[:9, :9], reference[:9, :9])


def test_delta_e_and_relative_rmse() -> None:
    grey = np.full((16, 16, 3), 0.2)
    warmer = grey * np.array([1.1, 1.0, 0.9])
    quality = image_quality(warmer, grey)
    assert 1.0 < quality.delta_e < 10.0  # a visible but small colour shift
    assert quality.rel_rmse == pytest.approx(math.sqrt((0.02**2 * 2) / (3 * 0.04)), rel=1e-9)


def test_display_scale_maps_the_high_percentile_to_white() -> None:
    hdr = np.linspace(0.0, 100.0, 3 * 1000).reshape(1000, 3)
    assert display_scale(hdr) == pytest.approx(1 / np.percentile(hdr, 99.5))
    assert display_scale(np.zeros((4, 3))) == 1.0


def test_bad_shapes_and_values_are_refused() -> None:
    with pytest.raises(InputError, match=r"\(H, W, 3\)"):
        image_quality(np.zeros((4, 4)), np.zeros((4, 4)))
    bad = np.zeros((8, 8, 3))
    bad[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="finite"):
        relative_rmse(bad, np.zeros((8, 8, 3)))


def test_relative_rmse_of_any_values_is_the_images_one() -> None:
    reference, predicted = _image(5), _image(6)
    mask = np.zeros(reference.shape[:2], dtype=bool)
    mask[2:9, 3:17] = True
    # Images: the same number as the checked metric, from float32 as from float64.
    assert relative_rmse_values(predicted, reference, mask) == relative_rmse(
        predicted, reference, mask
    )
    single = relative_rmse_values(predicted.astype(np.float32), reference.astype(np.float32))
    assert single == pytest.approx(relative_rmse(predicted, reference), rel=1e-6)
    # A field's samples (P, 3) with a mask of samples, and plain values.
    samples = relative_rmse_values(predicted[mask], reference[mask])
    assert samples == pytest.approx(relative_rmse(predicted, reference, mask), rel=1e-12)
    assert relative_rmse_values([3.0, 4.0], [0.0, 4.0]) == pytest.approx(0.75)
    assert relative_rmse_values([1.0, 2.0], [0.0, 0.0]) == 0.0  # a black reference
    assert relative_rmse_values(predicted, reference, np.zeros_like(mask)) == 0.0
    with pytest.raises(InputError, match="one shape"):
        relative_rmse_values(np.zeros((4, 3)), np.zeros((3, 3)))
    with pytest.raises(InputError, match="leading part"):
        relative_rmse_values(predicted, reference, mask.T)
