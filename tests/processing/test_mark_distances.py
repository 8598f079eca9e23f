from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from processing.mark_distances import distance_marks, distance_share, mark_distances

SHAPE = (6, 40)


def _shadow(start: int, stop: int) -> np.ndarray:
    """Marks (1, H * W) of a shadow over columns [start, stop)."""
    lit = np.ones(SHAPE, dtype=np.float32)
    lit[:, start:stop] = 0.0
    return lit.reshape(1, -1)


def test_the_distances_are_signed_pixels_to_the_shadows_edge() -> None:
    row = mark_distances(_shadow(10, 20), SHAPE).reshape(SHAPE)[2]
    assert row[9] == 0.5 and row[10] == -0.5  # the pixels either side of the edge
    assert row[0] == 9.5 and row[15] == -4.5 and row[30] == 10.5
    np.testing.assert_array_equal(distance_marks(row), (row > 0).astype(np.float32))


def test_a_light_without_an_edge_is_far_from_one_everywhere() -> None:
    lit = np.concatenate([np.ones((1, 240)), np.zeros((1, 240))])
    far = np.float32(np.hypot(*SHAPE))
    distances = mark_distances(lit, SHAPE)
    assert np.all(distances[0] == far) and np.all(distances[1] == -far)


def test_blending_the_distances_moves_the_edges_where_fading_leaves_ghosts() -> None:
    lit = np.concatenate([_shadow(10, 20), _shadow(14, 24)])  # a shadow slid four pixels
    moved = distance_marks(0.5 * mark_distances(lit, SHAPE).sum(axis=0)).reshape(SHAPE)[2]
    np.testing.assert_array_equal(moved, _shadow(12, 22).reshape(SHAPE)[2])
    faded = (0.5 * lit.sum(axis=0)).reshape(SHAPE)[2]
    assert np.all(faded[10:14] == 0.5) and np.all(faded[20:24] == 0.5)  # two half shadows


def test_the_share_is_the_faded_marks_part_of_the_errors() -> None:
    share = distance_share(np.array([0.0, 3.0, 1.0]), np.array([0.0, 1.0, 3.0]))
    np.testing.assert_allclose(share, [0.5, 0.75, 0.25])
    with pytest.raises(InputError, match="shape"):
        distance_share(np.zeros(3), np.zeros(4))


def test_marks_off_the_image_are_refused() -> None:
    with pytest.raises(InputError, match="do not lie on an image"):
        mark_distances(np.ones((2, 10)), SHAPE)
