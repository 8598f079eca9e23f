from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import InputError
from processing import halftone_tables as tables
from processing.halftone import DIFFUSION_METHODS, _trunc_div, error_diffuse, halftone


def test_table_sizes_and_sums() -> None:
    assert len(tables.TMED_COEFFICIENTS) == 128
    assert len(tables.TMED_THRESHOLD_MODULATION) == 128
    assert len(tables.OSTROMOUKHOV_COEFFICIENTS) == 256
    for table in (tables.TMED_COEFFICIENTS, tables.OSTROMOUKHOV_COEFFICIENTS):
        assert all(r + dl + d == s for r, dl, d, s in table)
    # The author's Ostromoukhov table (not the other circulating one) and its mirror symmetry.
    assert tables.OSTROMOUKHOV_COEFFICIENTS[23] == (459, 304, 161, 924)
    assert tables.OSTROMOUKHOV_COEFFICIENTS == tables.OSTROMOUKHOV_COEFFICIENTS[::-1]
    assert tables.TMED_COEFFICIENTS[0] == (13, 0, 5, 18)


@pytest.mark.parametrize("method", DIFFUSION_METHODS)
@pytest.mark.parametrize("grey", [16, 40, 64, 100, 128, 160, 200, 240])
def test_constant_grey_gives_its_density(method: str, grey: int) -> None:
    dots = halftone(np.full((256, 512), grey, dtype=np.uint8), method=method)
    assert dots[32:, :].mean() == pytest.approx(grey / 255, rel=0.01)


def test_deterministic_per_seed_and_seed_matters() -> None:
    image = np.full((64, 128), 100, dtype=np.uint8)
    a = halftone(image, seed=3)
    np.testing.assert_array_equal(a, halftone(image, seed=3))
    assert (a != halftone(image, seed=4)).any()


@settings(max_examples=25)
@given(st.integers(0, 2**31), st.sampled_from(DIFFUSION_METHODS))
def test_zero_input_never_fires(seed: int, method: str) -> None:
    rng = np.random.default_rng(seed)
    density = rng.random((32, 64)) * 2.0
    density[rng.random((32, 64)) < 0.5] = 0.0
    fired, _ = error_diffuse(density, method=method, seed=seed)
    assert not fired[density == 0].any()


def test_margin_marks_fired_pixels() -> None:
    density = np.random.default_rng(0).random((32, 64)) * 0.5
    fired, margin = error_diffuse(density)
    assert np.all(margin[fired] > 0) and np.all(margin[~fired] <= 0)


def test_bad_input_is_refused() -> None:
    with pytest.raises(InputError, match="non-negative"):
        error_diffuse(np.full((4, 8), -1.0))
    with pytest.raises(InputError, match="unknown"):
        error_diffuse(np.ones((4, 8)), method="bayer")
    with pytest.raises(InputError, match=r"0\.\.255"):
        halftone(np.full((4, 8), 300))


@given(st.integers(-(2**62), 2**62), st.integers(1, 2**21))
def test_error_shares_truncate_like_c(a: int, b: int) -> None:
    expected = abs(a) // b * (1 if a >= 0 else -1)
    assert _trunc_div(a, b) == expected


@pytest.mark.parametrize("a", [2**52 - 1, -(2**52) + 1, 2**52 - 2, 9 * 2**49 + 7])
@pytest.mark.parametrize("b", [1, 3, 1799499, 2**21])
def test_error_shares_near_the_float_limit(a: int, b: int) -> None:
    assert _trunc_div(a, b) == abs(a) // b * (1 if a >= 0 else -1)
