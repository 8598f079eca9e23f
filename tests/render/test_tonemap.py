"""render.tonemap: auto exposure (Reinhard's key), the global operator, 8-bit quantising."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray

from core.errors import RigError
from render.tonemap import KEY, auto_exposure, to_uint8, tone_map, tone_mapped_8bit


def _srgb(linear: float) -> float:
    """IEC 61966-2-1 encoding, written out independently of core.colour."""
    return 12.92 * linear if linear <= 0.0031308 else 1.055 * linear ** (1 / 2.4) - 0.055


def _grey(value: float, shape: tuple[int, ...] = (2, 3)) -> NDArray[np.float32]:
    return np.full((*shape, 3), value, np.float32)


def test_the_key_is_reinhards_middle_grey() -> None:
    assert KEY == 0.18


def test_auto_exposure_maps_the_log_average_to_the_key() -> None:
    # A uniform grey of luminance 0.5 (the Rec. 709 weights sum to one).
    assert auto_exposure(_grey(0.5)) == pytest.approx(0.36, rel=1e-6)
    # Luminances 1 and 4: geometric mean 2, not the arithmetic 2.5.
    rgb = np.array([[[1.0, 1.0, 1.0], [4.0, 4.0, 4.0]]], np.float32)
    assert auto_exposure(rgb) == pytest.approx(0.09, rel=1e-6)
    # Pure green counts with its weight 0.7152.
    assert auto_exposure(np.array([[0.0, 1.0, 0.0]])) == pytest.approx(0.18 / 0.7152, rel=1e-6)


def test_auto_exposure_ignores_dark_pixels_and_defaults_to_one() -> None:
    rgb = np.array([[[0.0, 0.0, 0.0], [2.0, 2.0, 2.0], [-1.0, -1.0, -1.0]]], np.float32)
    assert auto_exposure(rgb) == pytest.approx(0.09, rel=1e-6)
    assert auto_exposure(_grey(0.0)) == 1.0
    assert auto_exposure(np.zeros((0, 3))) == 1.0
    assert isinstance(auto_exposure(_grey(1.0)), float)


def test_tone_map_of_known_greys() -> None:
    # Exposure 1: luminance y maps to y / (1 + y), then sRGB.
    for value in (0.0, 0.01, 0.25, 1.0, 3.0, 100.0):
        out = tone_map(_grey(value), exposure=1.0)
        assert out.dtype == np.float32 and out.shape == (2, 3, 3)
        np.testing.assert_allclose(out, _srgb(value / (1.0 + value)), rtol=2e-6, atol=1e-7)
    # Exposure 2 on 0.5 is exposure 1 on 1: 0.5 -> sRGB 0.7354.
    np.testing.assert_allclose(tone_map(_grey(0.5), exposure=2.0), 0.735357, atol=1e-6)


def test_tone_map_defaults_to_auto_exposure() -> None:
    rgb = (10.0 ** np.random.default_rng(0).uniform(-2, 2, (8, 16, 3))).astype(np.float32)
    np.testing.assert_array_equal(tone_map(rgb), tone_map(rgb, exposure=auto_exposure(rgb)))
    # A uniform image lands on the key: 0.18 / 1.18 in linear display values.
    np.testing.assert_allclose(tone_map(_grey(7.0)), _srgb(0.18 / 1.18), rtol=1e-5)


def test_tone_map_keeps_the_hue_of_each_pixel() -> None:
    rgb = np.array([[[2.0, 1.0, 0.5], [0.2, 0.1, 0.05]]], np.float32)
    out = tone_map(rgb, exposure=1.0)
    # Decoded back to linear the channels keep their ratios 4 : 2 : 1.
    linear = np.where(out <= 0.04045, out / 12.92, ((out + 0.055) / 1.055) ** 2.4)
    for pixel in linear[0]:
        np.testing.assert_allclose(pixel / pixel[2], [4.0, 2.0, 1.0], rtol=1e-4)
    # And the luminance is compressed: y / (1 + y).
    y = 0.2126 * 2.0 + 0.7152 * 1.0 + 0.0722 * 0.5
    assert float(linear[0, 0] @ [0.2126, 0.7152, 0.0722]) == pytest.approx(y / (1 + y), rel=1e-4)


def test_a_saturated_highlight_clips_its_brightest_channel() -> None:
    # Luminance 2.353 -> ratio 1 / 3.353: red 4 / 3.353 > 1 is clipped, so this hue is not kept.
    out = tone_map(np.array([4.0, 2.0, 1.0], np.float32), exposure=1.0)
    assert out[0] == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(out[1:], [_srgb(2.0 / 3.353), _srgb(1.0 / 3.353)], rtol=1e-4)


def test_tone_map_accepts_any_leading_shape() -> None:
    for shape in ((3,), (5, 3), (2, 4, 3), (2, 2, 2, 3)):
        out = tone_map(np.ones(shape), exposure=1.0)
        assert out.shape == shape and out.dtype == np.float32


def test_tone_map_is_monotone_in_exposure_and_radiance() -> None:
    ramp = np.geomspace(1e-3, 1e4, 50)[:, None].repeat(3, axis=1).astype(np.float32)
    out = tone_map(ramp, exposure=1.0)[:, 0]
    assert np.all(np.diff(out) > 0) and out[-1] < 1.0
    brighter = tone_map(ramp, exposure=4.0)[:, 0]
    assert np.all(brighter > out)


positive = st.floats(0.0009765625, 1024.0, width=32)


@settings(max_examples=50)
@given(
    rgb=arrays(np.float32, (4, 6, 3), elements=positive),
    scale=st.floats(1e-3, 1e3),
)
def test_auto_exposed_tone_map_ignores_the_overall_scale(
    rgb: NDArray[np.float32], scale: float
) -> None:
    out = tone_map(rgb)
    assert np.all((out >= 0.0) & (out <= 1.0))
    np.testing.assert_allclose(tone_map(rgb * np.float32(scale)), out, atol=2e-5)


@settings(max_examples=50)
@given(rgb=arrays(np.float32, (3, 5, 3), elements=st.floats(0.0, 1e6, width=32)))
def test_tone_map_output_is_display_range(rgb: NDArray[np.float32]) -> None:
    out = tone_map(rgb, exposure=1.0)
    assert np.all(np.isfinite(out)) and np.all((out >= 0.0) & (out <= 1.0))


@settings(max_examples=60, deadline=None)
@given(
    rgb=arrays(
        np.float32, (4, 6, 3),
        elements=st.one_of(
            st.floats(2.0**-20, 2.0**20, width=32), st.floats(-1.0, 0.0, width=32),
            st.sampled_from([0.0, np.nan, np.inf, 2.0**127]),
        ),
    ),
    exposure=st.one_of(st.none(), st.floats(1e-3, 1e3)),
)  # fmt: skip
def test_the_one_pass_display_is_tone_map_then_to_uint8(
    rgb: NDArray[np.float32], exposure: float | None
) -> None:
    expected = to_uint8(tone_map(rgb, exposure=exposure))
    np.testing.assert_array_equal(tone_mapped_8bit(rgb, exposure=exposure), expected)


def test_the_one_pass_display_of_a_picture_is_exact() -> None:
    # A frame-sized case: every level of a wide ramp, in the same float32 steps.
    rng = np.random.default_rng(0)
    rgb = rng.lognormal(0.0, 2.5, (64, 96, 3)).astype(np.float32)
    for exposure in (0.05, 1.0, 20.0):
        expected = to_uint8(tone_map(rgb, exposure=exposure))
        np.testing.assert_array_equal(tone_mapped_8bit(rgb, exposure=exposure), expected)


def test_to_uint8_rounds_and_clips() -> None:
    encoded = np.array([-0.5, 0.0, 0.5 / 255, 0.5, 1.0, 1.5, 127.4 / 255, 127.6 / 255])
    out = to_uint8(encoded)
    assert out.dtype == np.uint8
    # 0.5 x 255 = 127.5 rounds half to even: 128.
    np.testing.assert_array_equal(out, [0, 0, 0, 128, 255, 255, 127, 128])
    assert to_uint8(np.zeros((2, 3, 3), np.float32)).shape == (2, 3, 3)


def test_to_uint8_of_every_code_value_is_the_identity() -> None:
    codes = np.arange(256)
    np.testing.assert_array_equal(to_uint8(codes / 255.0), codes)


def _refused_or_finite(call: Callable[[], NDArray[Any]]) -> None:
    """Non-finite input is either refused with the project's error or mapped to finite output."""
    try:
        out = call()
    except RigError:
        return
    assert np.all(np.isfinite(np.asarray(out, dtype=np.float64)))


def test_nan_radiance_is_ignored_by_auto_exposure() -> None:
    rgb = np.array([[[np.nan, np.nan, np.nan], [2.0, 2.0, 2.0]]], np.float32)
    assert auto_exposure(rgb) == pytest.approx(0.09, rel=1e-6)


def test_infinite_radiance_is_refused_or_mapped() -> None:
    rgb = np.array([[[1.0, 1.0, 1.0], [math.inf, 0.0, 0.0]]], np.float32)
    _refused_or_finite(lambda: tone_map(rgb))


def test_nan_display_values_are_refused_or_mapped() -> None:
    _refused_or_finite(lambda: to_uint8(np.array([0.5, np.nan])))
