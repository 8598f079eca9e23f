"""core.point_spacing: the splat size estimated from the points alone."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from core.directions import fibonacci_sphere
from core.errors import InputError
from core.point_spacing import DENSITY_RADIUS, median_neighbour_distance, point_spacing


def _lattice(spacing: float, side: int = 100) -> NDArray[np.float64]:
    """A side x side square lattice in the plane z = 0, as (P, 3) points."""
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), axis=-1).reshape(-1, 2)
    return np.column_stack([grid * spacing, np.zeros(len(grid))])


def _lattice_points_within(radius: float) -> int:
    """Integer points (x, y) with x^2 + y^2 <= radius^2 (Gauss's circle problem), counted."""
    reach = int(radius) + 1
    return sum(
        1 for x in range(-reach, reach + 1) for y in range(-reach, reach + 1)
        if x * x + y * y <= radius * radius
    )  # fmt: skip


@pytest.mark.parametrize("h", [0.5, 0.125, 2.0])
def test_a_square_lattice_has_its_spacing(h: float) -> None:
    points = _lattice(h)
    assert median_neighbour_distance(points) == h  # powers of two: exact distances
    # 137 lattice points lie within 6.5 spacings of an interior point: the area per point
    # pi 6.5^2 / 137 is 0.969 h^2, so the estimate is 0.984 h.
    count = _lattice_points_within(DENSITY_RADIUS)
    assert count == 137
    expected = h * math.sqrt(math.pi * DENSITY_RADIUS**2 / count)
    assert point_spacing(points) == pytest.approx(expected, rel=1e-12)
    assert point_spacing(points) == pytest.approx(h, rel=0.02)


def test_a_lattice_of_non_binary_spacing() -> None:
    points = _lattice(0.1)
    assert median_neighbour_distance(points) == pytest.approx(0.1, rel=1e-12)
    assert point_spacing(points) == pytest.approx(0.1 * 0.98430118830594, rel=1e-9)


def test_a_lattice_tilted_in_space_keeps_its_spacing() -> None:
    angle = np.radians(37.0)
    tilt = np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(angle), -np.sin(angle)], [0.0, np.sin(angle), np.cos(angle)]]
    )
    points = _lattice(0.25) @ tilt.T + np.array([3.0, -1.0, 5.0])
    assert median_neighbour_distance(points) == pytest.approx(0.25, rel=1e-9)
    assert point_spacing(points) == pytest.approx(0.25 * 0.98430118830594, rel=1e-9)


@pytest.mark.parametrize("count", [2000, 20_000])
def test_a_sphere_gives_the_simulators_sqrt_area_per_point(count: int) -> None:
    radius = 3.0
    points = fibonacci_sphere(count) * radius
    truth = math.sqrt(4.0 * math.pi * radius**2 / count)
    assert point_spacing(points) == pytest.approx(truth, rel=0.015)
    # The nearest-neighbour distance is about 5 % smaller (the module's note).
    assert median_neighbour_distance(points) / truth == pytest.approx(0.953, abs=0.01)


def test_random_points_on_a_square() -> None:
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.random((4000, 2)), np.zeros(4000)])
    assert point_spacing(points) == pytest.approx(math.sqrt(1.0 / 4000), rel=0.03)


def test_two_points() -> None:
    points = np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 4.0]])
    assert median_neighbour_distance(points) == 5.0
    # Within 6.5 x 5 each point counts itself and the other.
    assert point_spacing(points) == pytest.approx(math.sqrt(math.pi * 32.5**2 / 2), rel=1e-12)


@pytest.mark.parametrize("count", [0, 1])
def test_fewer_than_two_points_are_refused(count: int) -> None:
    points = np.zeros((count, 3))
    for estimate in (point_spacing, median_neighbour_distance):
        with pytest.raises(InputError, match=f"at least 2 points to splat, got {count}"):
            estimate(points)


def test_coincident_points_are_refused() -> None:
    points = np.repeat(np.array([[1.0, 2.0, 3.0]]), 50, axis=0)
    with pytest.raises(InputError, match="coincident points"):
        point_spacing(points)
    assert median_neighbour_distance(points) == 0.0
    # Mostly doubled points: the median nearest neighbour is zero too.
    doubled = np.repeat(_lattice(1.0, side=10), 2, axis=0)
    with pytest.raises(InputError, match="coincident points"):
        point_spacing(doubled)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_points_are_refused(bad: float) -> None:
    points = _lattice(1.0, side=10)
    points[3, 1] = bad
    with pytest.raises(InputError):
        point_spacing(points)


def test_the_estimate_is_deterministic_for_a_seed() -> None:
    cloud = np.random.default_rng(3).random((1000, 3))
    first = point_spacing(cloud, sample=50, seed=0)
    assert point_spacing(cloud, sample=50, seed=0) == first
    assert median_neighbour_distance(cloud, sample=50, seed=4) == median_neighbour_distance(
        cloud, sample=50, seed=4
    )
    # Another subset gives another median on an irregular cloud...
    assert point_spacing(cloud, sample=50, seed=1) != first
    assert median_neighbour_distance(cloud, sample=50, seed=1) != median_neighbour_distance(
        cloud, sample=50, seed=0
    )
    # ... and a subset as large as the cloud is the whole cloud, whatever the seed.
    assert point_spacing(cloud, sample=1000, seed=0) == point_spacing(cloud, sample=5000, seed=9)


@settings(max_examples=30)
@given(seed=st.integers(0, 2**32 - 1), exponent=st.integers(-12, 12), count=st.integers(2, 300))
def test_scaling_a_cloud_scales_both_estimates(seed: int, exponent: int, count: int) -> None:
    cloud = np.random.default_rng(seed).normal(size=(count, 3))
    scale = 2.0**exponent  # exact in binary floating point
    assert median_neighbour_distance(cloud * scale, sample=100) == pytest.approx(
        median_neighbour_distance(cloud, sample=100) * scale, rel=1e-12
    )
    assert point_spacing(cloud * scale, sample=100) == pytest.approx(
        point_spacing(cloud, sample=100) * scale, rel=1e-12
    )


def test_lists_of_points_are_accepted() -> None:
    points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [3.0, 0.0, 0.0]]
    assert median_neighbour_distance(points) == 1.0  # type: ignore[arg-type]
