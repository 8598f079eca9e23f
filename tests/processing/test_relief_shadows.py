from __future__ import annotations

import math

import numpy as np
import pytest

import processing.relief_shadows as relief
from core.directions import hemisphere_layout
from core.errors import InputError
from processing.interpolation import interpolation_weights
from processing.relief_shadows import (
    GRAZING_COSINE,
    relief_contradictions,
    relief_disagreement,
    relief_heights,
    relief_visibility,
    shadow_travel,
)

SIZE = 48


def _block(height: float = 6.0) -> np.ndarray:
    """A flat base with a square block standing on it (pixel units)."""
    heights = np.zeros((SIZE, SIZE))
    heights[18:30, 18:30] = height
    return heights


def _measured(count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The block seen whole under ``count`` dome lights: visible, lights, marks, normals."""
    visible = np.ones((SIZE, SIZE), dtype=bool)
    lights = hemisphere_layout(count, "fibonacci")
    marks = relief_visibility(_block(), lights, visible, spread=0).astype(np.uint8)
    return visible, lights, marks, np.tile([0.0, 0.0, 1.0], (SIZE * SIZE, 1))


def _light(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([[math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]])


def test_a_wall_casts_its_shadow_away_from_the_light_as_long_as_its_slope_says() -> None:
    visible = np.ones((SIZE, SIZE), dtype=bool)
    # Light from the right (camera x), 30 degrees up: the block (6 px) shadows 6 / tan 30
    # = 10.4 px of the base on its left.
    lit = relief_visibility(_block(), _light(30, 0), visible, spread=0).reshape(SIZE, SIZE)
    row = lit[24]
    assert row[18:30].all()  # the block's top
    assert row[30:].all()  # the lit side
    shadow = np.flatnonzero(row[:18] == 0)
    assert shadow.max() == 17 and 10 <= len(shadow) <= 11
    # Light from the top of the image (camera y up): the shadow falls below the block.
    column = relief_visibility(_block(), _light(30, 90), visible, spread=0).reshape(SIZE, SIZE)
    assert (column[30:38, 24] == 0).all() and column[:18, 24].all()


def test_flat_ground_is_lit_from_above_and_dark_from_below() -> None:
    visible = np.ones((SIZE, SIZE), dtype=bool)
    flat = np.zeros((SIZE, SIZE))
    above = relief_visibility(flat, hemisphere_layout(12, "fibonacci"), visible)
    assert above.shape == (SIZE * SIZE, 12) and (above == 1).all()
    assert (relief_visibility(flat, np.array([[0.6, 0.0, -0.8]]), visible) == 0).all()


def test_the_fitted_relief_places_shadows_between_lights_better_than_interpolated_marks() -> None:
    truth = _block()
    visible, lights, marks, normals = _measured(49)
    heights = relief_heights(marks, normals, lights, visible, threads=1)
    assert heights.shape == (SIZE, SIZE)
    # Low lights between the measured ones, where shadows are long and move most.
    new = np.concatenate([_light(15, a) for a in range(10, 360, 40)])
    wanted = relief_visibility(truth, new, visible, spread=0)
    cast = relief_visibility(heights, new, visible, spread=0)
    interpolated = (
        interpolation_weights(lights, new, "barycentric", policy="clamp")
        .apply(marks.T.astype(np.float64))
        .T
    )
    relief_error = float(np.abs(cast - wanted).mean())
    interpolation_error = float(np.abs(interpolated - wanted).mean())
    assert relief_error < 0.5 * interpolation_error


def test_a_field_without_shadows_is_a_flat_relief() -> None:
    visible = np.ones((8, 8), dtype=bool)
    lights = hemisphere_layout(9, "fibonacci")
    marks = np.ones((64, 9), dtype=np.uint8)
    normals = np.tile([0.0, 0.0, 1.0], (64, 1))
    assert (relief_heights(marks, normals, lights, visible, threads=1) == 0).all()


def test_a_large_image_is_fitted_coarser_and_returned_at_its_own_size(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(relief, "MAX_FIT_PIXELS", SIZE * SIZE // 4)
    visible, lights, marks, normals = _measured(25)
    heights = relief_heights(marks, normals, lights, visible, steps=100, threads=1)
    assert heights.shape == (SIZE, SIZE)
    # In pixel units of the image: the block stands out by about its own height.
    assert 3.0 < float(heights[21:27, 21:27].mean() - heights[:8, :8].mean()) < 10.0


def test_a_dense_dome_is_fitted_through_lights_spread_over_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(relief, "MAX_FIT_LIGHTS", 16)
    seen: list[int] = []
    horizons = relief._horizons

    def counted(height: np.ndarray, index: np.ndarray, pixels: np.ndarray) -> object:
        seen.append(index.shape[1])
        return horizons(height, index, pixels)

    monkeypatch.setattr(relief, "_horizons", counted)
    visible, lights, marks, normals = _measured(64)
    heights = relief_heights(marks, normals, lights, visible, steps=100, threads=1)
    assert set(seen) == {16}  # every step sees 16 of the 64 lights
    assert 3.0 < float(heights[21:27, 21:27].mean() - heights[:8, :8].mean()) < 10.0


def test_marks_that_do_not_fit_the_image_are_refused() -> None:
    visible = np.ones((4, 4), dtype=bool)
    lights = hemisphere_layout(5, "fibonacci")
    with pytest.raises(InputError, match="do not fit an image of"):
        relief_heights(np.ones((15, 5), dtype=np.uint8), np.ones((16, 3)), lights, visible)
    with pytest.raises(InputError, match="differ"):
        relief_visibility(np.zeros((4, 5)), lights, visible)


def test_disagreement_is_the_share_of_a_pixels_lights_the_relief_contradicts() -> None:
    visible, lights, marks, normals = _measured(25)
    block = relief_contradictions(_block(), marks, normals, lights, visible)
    assert (relief_disagreement(block) == 0).all()
    flat = relief_contradictions(np.zeros((SIZE, SIZE)), marks, normals, lights, visible)
    informative = lights[:, 2] > GRAZING_COSINE
    np.testing.assert_array_equal(flat[:, ~informative], -1)
    np.testing.assert_array_equal(flat[:, informative], 1 - marks[:, informative])
    np.testing.assert_allclose(
        relief_disagreement(flat), (1 - marks[:, informative]).sum(1) / informative.sum()
    )
    assert relief_disagreement(flat).max() > 0


def test_shadow_travel_is_the_shadows_move_per_unit_of_height() -> None:
    def light(elevation: float, azimuth: float = 0.0) -> np.ndarray:
        e, a = np.radians(elevation), np.radians(azimuth)
        return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])

    requested = np.stack([light(45.0), light(45.0)])
    around = np.stack([[light(45.0), light(15.0)], [light(45.0), light(45.0, 90.0)]])
    travel = shadow_travel(requested, around, np.array([[True, True], [True, False]]))
    # A shadow one height long at 45 degrees; at 15 degrees cot(15) = 3.73 heights long.
    np.testing.assert_allclose(travel, [1.0 / np.tan(np.radians(15.0)) - 1.0, 0.0], atol=1e-9)
    moved = shadow_travel(requested[:1], around[1:], np.array([[False, True]]))
    np.testing.assert_allclose(moved, [np.sqrt(2.0)])  # a quarter turn at 45 degrees
