"""render.overlay: Voronoi cell borders, the sample overlay and the disassembled picture."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray

from core.directions import panorama_directions
from processing.lights import disassemble_lights
from render.overlay import (
    BORDER_RGB,
    SAMPLE_RGB,
    cell_borders,
    disassembled_picture,
    sample_overlay,
)

#: Pixels (row, col) of a 64 x 128 panorama the samples sit on.
PIXELS = ((20, 30), (40, 100), (10, 70), (50, 5))


def _directions_at(pixels: tuple[tuple[int, int], ...], height: int) -> NDArray[np.float64]:
    grid = panorama_directions(height, 2 * height)
    return np.array([grid[r, c] for r, c in pixels])


def _far_from(pixels: tuple[tuple[int, int], ...], height: int, reach: float) -> NDArray[np.bool_]:
    rows, cols = np.mgrid[:height, : 2 * height]
    far = np.ones((height, 2 * height), dtype=bool)
    for r, c in pixels:
        far &= (rows - r) ** 2 + (cols - c) ** 2 > reach**2
    return far


# -- cell_borders -------------------------------------------------------------------------------


def test_cell_borders_of_a_known_label_map() -> None:
    labels = np.array(
        [
            [0, 0, 1, 1, 1, 0],
            [0, 0, 1, 1, 1, 0],
            [2, 2, 2, 1, 1, 2],
        ]
    )
    expected = np.array(
        [
            # the right neighbour (col 5's is col 0: 0 == 0) or the one below differs
            [False, True, False, False, True, False],
            [True, True, True, False, True, True],
            [False, False, True, False, True, False],
        ]
    )
    borders = cell_borders(labels)
    assert borders.dtype == np.bool_ and borders.shape == labels.shape
    np.testing.assert_array_equal(borders, expected)


def test_cell_borders_wrap_around_the_seam() -> None:
    labels = np.array([[0, 0, 1, 1], [0, 0, 1, 1]])
    # The last column's right neighbour is the first column: label 1 beside label 0.
    np.testing.assert_array_equal(
        cell_borders(labels), [[False, True, False, True], [False, True, False, True]]
    )
    # Same label on both sides of the seam: no border there.
    np.testing.assert_array_equal(
        cell_borders(np.array([[1, 0, 0, 1]])), [[True, False, True, False]]
    )


def test_a_single_cell_has_no_border() -> None:
    assert not cell_borders(np.full((4, 8), 3, np.int32)).any()
    # The last row is never a border by its (missing) lower neighbour.
    labels = np.zeros((3, 4), np.int32)
    labels[2] = 1
    np.testing.assert_array_equal(cell_borders(labels), [[False] * 4, [True] * 4, [False] * 4])


label_maps = arrays(np.int32, st.tuples(st.integers(1, 6), st.integers(1, 12)),
                    elements=st.integers(0, 3))  # fmt: skip


@settings(max_examples=100)
@given(labels=label_maps, shift=st.integers(-20, 20), data=st.data())
def test_borders_turn_with_the_panorama_and_ignore_label_values(
    labels: NDArray[np.int32], shift: int, data: st.DataObject
) -> None:
    borders = cell_borders(labels)
    # Rolling the panorama about its vertical axis rolls its borders: the seam is no edge.
    np.testing.assert_array_equal(
        cell_borders(np.roll(labels, shift, axis=1)), np.roll(borders, shift, axis=1)
    )
    # Renaming the cells (any one-to-one relabelling) moves no border.
    permutation = np.array(data.draw(st.permutations(range(4))), dtype=np.int32) + 10
    np.testing.assert_array_equal(cell_borders(permutation[labels]), borders)
    assert borders.any() == (np.unique(labels).size > 1)


# -- sample_overlay -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def grey_lights() -> tuple[NDArray[np.float32], Any]:
    """A uniform grey panorama and its light set (the class is not imported: it is moving)."""
    rgb = np.full((64, 128, 3), 0.5, np.float32)
    return rgb, disassemble_lights(rgb, _directions_at(PIXELS, 64))


def test_sample_overlay_draws_borders_and_samples(
    grey_lights: tuple[NDArray[np.float32], Any],
) -> None:
    rgb, lights = grey_lights
    picture = sample_overlay(rgb, lights, exposure=1.0)
    assert picture.shape == (64, 128, 3) and picture.dtype == np.uint8
    # Each sample: a disc of radius 2 (64 rows / 170, at least 2) in the sample colour.
    for r, c in PIXELS:
        for dr, dc in ((0, 0), (0, 2), (0, -2), (2, 0), (-2, 0), (1, 1)):
            assert tuple(picture[r + dr, c + dc]) == SAMPLE_RGB, (r + dr, c + dc)
        # ... inside a dark outline one pixel wider.
        assert picture[r, c + 3].max() < 100 and picture[r + 3, c].max() < 100
    # Away from the samples: the borders in the border colour, elsewhere the tone-mapped grey
    # (0.5 at exposure 1: 0.5 / 1.5 -> sRGB 0.612 -> 156).
    far = _far_from(PIXELS, 64, 5.0)
    borders = cell_borders(lights.labels)
    assert borders[far].sum() > 100
    assert np.all(picture[borders & far] == BORDER_RGB)
    assert np.all(picture[~borders & far] == 156)


def test_sample_overlay_auto_exposure_and_input_untouched(
    grey_lights: tuple[NDArray[np.float32], Any],
) -> None:
    rgb, lights = grey_lights
    before = rgb.copy()
    picture = sample_overlay(rgb * np.float32(40.0), lights)
    # Auto exposure puts a uniform panorama at the key: 0.18 / 1.18 -> sRGB 0.429 -> 109.
    far = _far_from(PIXELS, 64, 5.0) & ~cell_borders(lights.labels)
    assert np.all(picture[far] == 109)
    np.testing.assert_array_equal(rgb, before)


def test_the_sample_disc_grows_with_the_panorama() -> None:
    height = 512  # radius round(512 / 170) = 3
    pixels = ((100, 300), (400, 800))
    rgb = np.full((height, 2 * height, 3), 0.5, np.float32)
    lights = disassemble_lights(rgb, _directions_at(pixels, height))
    picture = sample_overlay(rgb, lights, exposure=1.0)
    assert picture.shape == (512, 1024, 3)
    for r, c in pixels:
        assert tuple(picture[r, c + 3]) == SAMPLE_RGB and tuple(picture[r - 3, c]) == SAMPLE_RGB
        assert tuple(picture[r, c + 5]) != SAMPLE_RGB


# -- disassembled_picture -----------------------------------------------------------------------


def test_a_uniform_panorama_disassembles_to_itself() -> None:
    rgb = np.ones((32, 64, 3), np.float32)
    lights = disassemble_lights(rgb, _directions_at(((5, 10), (20, 40), (16, 0)), 32))
    picture = disassembled_picture(lights, exposure=1.0)
    assert picture.shape == (32, 64, 3) and picture.dtype == np.uint8
    # Every cell's mean radiance is 1: 1 / 2 -> sRGB 0.735 -> 188.
    assert np.all(picture == 188)


def test_each_cell_is_filled_with_its_mean_radiance() -> None:
    # Light above the horizon only; one sample at each pole: the cells are the hemispheres.
    rgb = np.zeros((32, 64, 3), np.float32)
    rgb[:16] = 1.0
    lights = disassemble_lights(rgb, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]))
    picture = disassembled_picture(lights, exposure=1.0)
    assert np.all(picture[:16] == 188) and np.all(picture[16:] == 0)
    # Exposure scales before the tone curve: 1 x 3 -> 3 / 4 -> sRGB 0.881 -> 225.
    assert np.all(disassembled_picture(lights, exposure=3.0)[:16] == 225)


def test_the_disassembled_picture_is_flat_within_each_cell() -> None:
    rng = np.random.default_rng(5)
    rgb = (10.0 ** rng.uniform(-1, 1, (32, 64, 3))).astype(np.float32)
    directions = rng.normal(size=(12, 3))
    lights = disassemble_lights(rgb, directions)
    picture = disassembled_picture(lights, exposure=0.5)
    means = []
    for label in range(12):
        colours = np.unique(picture[lights.labels == label], axis=0)
        assert len(colours) == 1, label
        means.append(colours[0])
    assert len(np.unique(np.array(means), axis=0)) > 1  # not one colour for everything
