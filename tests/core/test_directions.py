from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core.directions import (
    angle_between,
    angles_deg_from_direction,
    direction_from_angles_deg,
    farthest_point_order,
    hemisphere_layout,
    normalize,
    panorama_directions,
    panorama_pixel_from_direction,
    panorama_pixel_index,
    panorama_pixel_points,
    panorama_solid_angles,
    rotate_directions_yaw,
    rotate_panorama_yaw,
    spread_partition,
)
from core.errors import InputError

azimuths = st.floats(0.0, 359.999)
inclinations = st.floats(0.01, 179.99)


@given(azimuths, inclinations)
def test_degrees_round_trip(az: float, incl: float) -> None:
    d = direction_from_angles_deg(az, incl)
    assert np.linalg.norm(d) == pytest.approx(1.0)
    az2, incl2 = angles_deg_from_direction(d)
    assert incl2 == pytest.approx(incl, abs=1e-9)
    assert np.cos(np.deg2rad(az2 - az)) == pytest.approx(1.0, abs=1e-9)


def test_named_directions() -> None:
    np.testing.assert_allclose(direction_from_angles_deg(0, 0), [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(direction_from_angles_deg(0, 90), [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(direction_from_angles_deg(90, 90), [0, 1, 0], atol=1e-15)


@given(azimuths, inclinations, azimuths, inclinations)
def test_angle_between_matches_dot(a1: float, i1: float, a2: float, i2: float) -> None:
    u, v = direction_from_angles_deg(a1, i1), direction_from_angles_deg(a2, i2)
    assert angle_between(u, v) == pytest.approx(np.arccos(np.clip(u @ v, -1, 1)), abs=1e-6)


def test_angle_between_is_exact_for_tiny_angles() -> None:
    u = np.array([1.0, 0.0, 0.0])
    v = np.array([1.0, 1e-9, 0.0])
    assert angle_between(u, v) == pytest.approx(1e-9, rel=1e-6)


@pytest.mark.parametrize("height", [1, 2, 7, 64, 512])
def test_solid_angles_sum_to_four_pi(height: int) -> None:
    assert panorama_solid_angles(height, 2 * height).sum() == pytest.approx(4 * np.pi, rel=1e-12)


def test_centre_column_looks_along_x_and_right_turns_clockwise() -> None:
    h, w = 64, 128
    d = panorama_directions(h, w)
    # The boundary between the two centre columns, on the horizon, is +x.
    centre = 0.5 * (d[h // 2 - 1, w // 2 - 1] + d[h // 2, w // 2])
    np.testing.assert_allclose(normalize(centre), [1, 0, 0], atol=1e-12)
    az, _ = angles_deg_from_direction(d[h // 2, w // 2 : w // 2 + 5])
    # Moving right decreases the azimuth: clockwise seen from above (+z).
    assert np.all(np.diff(az) < 0)
    assert d[0, 0, 2] > 0.99 and d[-1, 0, 2] < -0.99  # row 0 at the zenith


@given(st.integers(0, 63), st.integers(0, 127))
def test_pixel_round_trip(row: int, col: int) -> None:
    d = panorama_directions(64, 128)[row, col]
    r, c = panorama_pixel_from_direction(d, 64, 128)
    assert r == pytest.approx(row, abs=1e-9) and c == pytest.approx(col, abs=1e-9)
    ri, ci = panorama_pixel_index(d, 64, 128)
    assert (ri, ci) == (row, col)


@given(st.integers(0, 31), st.integers(0, 63), st.floats(0.01, 0.99), st.floats(0.01, 0.99))
def test_pixel_points_stay_in_their_pixel(row: int, col: int, u: float, v: float) -> None:
    d = panorama_pixel_points(row, col, u, v, 32, 64)
    assert tuple(int(x) for x in panorama_pixel_index(d, 32, 64)) == (row, col)


def test_rotating_a_panorama_moves_light_counter_clockwise() -> None:
    h, w = 32, 64
    image = np.zeros((h, w), dtype=np.float32)
    light = direction_from_angles_deg(10.0, 80.0)
    r, c = panorama_pixel_index(light, h, w)
    image[r, c] = 1.0
    rotated = rotate_panorama_yaw(image, 90.0)
    r2, c2 = np.unravel_index(np.argmax(rotated), rotated.shape)
    expected = panorama_pixel_index(rotate_directions_yaw(light, 90.0), h, w)
    assert (r2, c2) == tuple(int(x) for x in expected)
    assert rotated.sum() == pytest.approx(1.0)


@given(st.floats(-720, 720))
def test_rotation_keeps_energy(yaw: float) -> None:
    image = np.random.default_rng(0).random((16, 32, 3)).astype(np.float32)
    np.testing.assert_allclose(
        rotate_panorama_yaw(image, yaw).sum((0, 1)), image.sum((0, 1)), rtol=1e-5
    )


def test_bad_directions_are_refused() -> None:
    with pytest.raises(InputError, match="zero or not finite"):
        normalize([[1, 0, 0], [0, 0, 0]])
    with pytest.raises(InputError, match="W = 2H"):
        panorama_directions(10, 30)


def test_the_numba_cell_is_the_panorama_mapping_turned_back_by_the_yaw() -> None:
    from core.directions import panorama_bilinear_cell, panorama_pixel_from_direction

    height, width, yaw = 16, 32, math.radians(37.0)
    rng = np.random.default_rng(4)
    directions = rng.normal(size=(200, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    row, col = panorama_pixel_from_direction(
        rotate_directions_yaw(directions, -37.0), height, width
    )
    for (x, y, z), r, c in zip(directions, row, col, strict=True):
        r0, r1, c0, c1, fr, fc = panorama_bilinear_cell(x, y, z, yaw, height, width)
        clamped = min(max(r, 0.0), height - 1.0)
        assert r1 == r0 + 1 and 0 <= r0 <= height - 2 and c1 == (c0 + 1) % width
        assert r0 + fr == pytest.approx(clamped, abs=1e-9)
        offset = (c0 + fc - c) % width  # the same column, whichever side of the wrap
        assert min(offset, width - offset) < 1e-9


def test_the_farthest_point_order_spreads_every_prefix() -> None:
    lights = hemisphere_layout(49, "fibonacci")
    order = farthest_point_order(lights, seed=3)
    assert order.dtype == np.int64 and sorted(order.tolist()) == list(range(49))
    distance = np.linalg.norm(lights[:, None] - lights[None], axis=2)
    np.fill_diagonal(distance, np.inf)
    spacing = float(np.median(distance.min(axis=1)))
    assert distance[np.ix_(order[:8], order[:8])].min() > 2.0 * spacing
    # repeated directions are still each taken once
    assert sorted(farthest_point_order(np.tile(lights[:3], (3, 1))).tolist()) == list(range(9))
    assert farthest_point_order(np.zeros((0, 3))).size == 0


@pytest.mark.parametrize("count", [12, 36, 49, 60, 100])
def test_a_spread_partition_keeps_each_group_apart_and_the_groups_even(count: int) -> None:
    lights = hemisphere_layout(count, "fibonacci")
    group = spread_partition(lights, 4)
    distance = np.linalg.norm(lights[:, None] - lights[None], axis=2)
    np.fill_diagonal(distance, np.inf)
    spacing = float(np.median(distance.min(axis=1)))
    sizes = np.bincount(group, minlength=4)
    assert sizes.sum() == count and sizes.max() - sizes.min() <= 1
    # each member's nearest fellow is about twice the spacing away (a random deal: 1.2-1.5)
    fellows = [distance[np.ix_(group == g, group == g)].min(axis=1) for g in range(4)]
    assert np.mean(np.concatenate(fellows)) > 1.5 * spacing
