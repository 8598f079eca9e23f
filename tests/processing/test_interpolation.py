from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from core.directions import (
    angle_between,
    direction_from_angles_deg,
    hemisphere_layout,
    panorama_directions,
)
from core.errors import InputError
from processing.interpolation import (
    BRUTE_FORCE_LIMIT,
    METHODS,
    RBF_NEIGHBOURS,
    DirectionWeights,
    interpolation_weights,
    mean_spacing_deg,
)

LAYOUTS = [(layout, count) for layout in ("grid", "fibonacci") for count in (10, 30, 400)]


def _sphere(count: int, seed: int) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(count, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _blend(measured: np.ndarray, w: DirectionWeights) -> np.ndarray:
    """sum_j w_j v_j, the point the weights stand for (on the chord triangle or arc)."""
    return np.einsum("qk,qkc->qc", w.weights, measured[w.indices])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _hull_parts(measured: np.ndarray) -> tuple[list[np.ndarray], list[tuple[int, int]]]:
    """Triangles and boundary arcs of the region, from the hull of the set and the origin."""
    n = len(measured)
    hull = ConvexHull(np.vstack([measured, np.zeros((1, 3))]))
    triangles = [s for s in hull.simplices if n not in s]
    edges = [(int(a), int(b)) for s in hull.simplices if n in s for a, b in [s[s != n]]]
    return triangles, edges


# --- every method -----------------------------------------------------------------------------


@pytest.mark.parametrize(("layout", "count"), LAYOUTS)
@pytest.mark.parametrize("method", METHODS)
def test_weights_are_non_negative_and_sum_to_one(layout: str, count: int, method: str) -> None:
    measured = hemisphere_layout(count, layout)
    queries = np.vstack([_sphere(300, count), panorama_directions(8, 16).reshape(-1, 3)])
    w = interpolation_weights(measured, queries, method)
    columns = {"paper": 3, "nearest": 1, "barycentric": 3, "rbf": RBF_NEIGHBOURS}[method]
    assert w.indices.shape == w.weights.shape == (len(queries), columns)
    assert w.indices.dtype == np.int64 and w.weights.dtype == np.float64
    assert w.indices.min() >= 0 and w.indices.max() < count
    assert w.weights.min() >= 0.0
    np.testing.assert_allclose(w.weights.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    # Below the horizon is outside every hemisphere layout; the zenith and the lights are not.
    np.testing.assert_array_equal(w.outside[queries[:, 2] < 0], True)
    assert not interpolation_weights(measured, measured, method).outside.any()
    assert not interpolation_weights(measured, [[0.0, 0.0, 1.0]], method).outside.any()


@pytest.mark.parametrize(("layout", "count"), LAYOUTS)
@pytest.mark.parametrize("method", ["barycentric", "nearest"])
def test_exact_at_measured_directions(layout: str, count: int, method: str) -> None:
    measured = hemisphere_layout(count, layout)
    w = interpolation_weights(measured, measured, method)
    np.testing.assert_allclose(w.dense(count), np.eye(count), rtol=0, atol=1e-12)


def test_empty_queries_give_empty_weights() -> None:
    w = interpolation_weights(hemisphere_layout(30), np.zeros((0, 3)), "barycentric")
    assert w.indices.shape == (0, 3) and w.outside.shape == (0,)


@settings(max_examples=25)
@given(st.integers(3, 80), st.integers(0, 2**32 - 1), st.sampled_from(METHODS))
def test_random_sets_give_a_partition_of_unity(count: int, seed: int, method: str) -> None:
    rng = np.random.default_rng(seed)
    measured = _sphere(count, seed) * rng.uniform(0.5, 2.0, (count, 1))
    queries = _sphere(200, seed + 1)
    w = interpolation_weights(measured, queries, method)
    assert w.weights.min() >= 0.0
    np.testing.assert_allclose(w.weights.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    if method == "barycentric":
        # Weights reconstruct the query ray (inside) or the nearest point of the region.
        inside = ~w.outside
        points = _unit(_blend(_unit(measured), w))
        np.testing.assert_allclose(points[inside], queries[inside], atol=1e-9)


# --- paper ------------------------------------------------------------------------------------


@pytest.mark.parametrize("m", [1, 3, 5])
def test_paper_is_eq1(m: int) -> None:
    measured = hemisphere_layout(30, "fibonacci")
    queries = _sphere(20, 7)
    queries[:, 2] = np.abs(queries[:, 2])
    w = interpolation_weights(measured, queries, "paper", m=m)
    for q, indices, weights in zip(queries, w.indices, w.weights, strict=True):
        angles = angle_between(measured, q)
        nearest = np.argsort(angles)[:m]
        expected = np.cos(angles[nearest]) / np.cos(angles[nearest]).sum()
        np.testing.assert_array_equal(indices, nearest)
        np.testing.assert_allclose(weights, expected, rtol=1e-12)


@pytest.mark.parametrize("count", [BRUTE_FORCE_LIMIT, BRUTE_FORCE_LIMIT + 1])
@pytest.mark.parametrize("method", ["paper", "nearest", "rbf"])
def test_neighbours_by_trial_and_by_tree_agree(count: int, method: str) -> None:
    # Up to the limit the neighbours are tried one by one, above it a k-d tree finds them.
    measured = _sphere(count, 3)
    queries = _sphere(500, 4)
    w = interpolation_weights(measured, queries, method)
    k = w.indices.shape[1] + (1 if method == "rbf" else 0)
    nearest = np.argsort(np.linalg.norm(queries[:, None] - measured[None], axis=2), axis=1)
    np.testing.assert_array_equal(w.indices, nearest[:, : w.indices.shape[1]])
    assert k <= count


def test_paper_blends_neighbours_even_at_a_measured_direction() -> None:
    # The paper's eq. 1 is not interpolating: m = 3 always mixes in two neighbours.
    measured = hemisphere_layout(30, "grid")
    w = interpolation_weights(measured, measured[:5], "paper")
    assert np.all(w.indices[:, 0] == np.arange(5))
    assert np.all(w.weights[:, 0] < 0.5) and np.all(w.weights[:, 1:] > 0.25)


def test_paper_ignores_neighbours_beyond_ninety_degrees() -> None:
    measured = direction_from_angles_deg([0.0, 0.0, 180.0], [10.0, 50.0, 120.0])
    query = direction_from_angles_deg(0.0, 50.0)[None, :]  # 170 degrees from the third
    w = interpolation_weights(measured, query, "paper", m=3)
    np.testing.assert_allclose(w.dense(3)[0, 2], 0.0)
    expected = np.array([np.cos(np.radians(40.0)), 1.0])
    np.testing.assert_allclose(w.dense(3)[0, :2], expected / expected.sum(), rtol=1e-12)
    # All m beyond 90 degrees: the nearest takes everything.
    nadir = interpolation_weights(hemisphere_layout(30), [[0.0, 0.0, -1.0]], "paper")
    np.testing.assert_allclose(nadir.weights, [[1.0, 0.0, 0.0]])


def test_paper_caps_m_at_the_measured_count() -> None:
    w = interpolation_weights(hemisphere_layout(2), _sphere(5, 1), "paper", m=10)
    assert w.indices.shape == (5, 2)


# --- barycentric ------------------------------------------------------------------------------


@pytest.mark.parametrize(("layout", "count"), [("grid", 30), ("fibonacci", 30), ("grid", 400)])
def test_barycentric_reproduces_linear_functions_on_the_chord_triangle(
    layout: str, count: int
) -> None:
    # Planar barycentric on the flat triangle: f(x) = a . x + b, sampled at the measured
    # directions, is reproduced exactly at the point p where the query ray meets the triangle.
    measured = hemisphere_layout(count, layout)
    rng = np.random.default_rng(count)
    a, b = rng.normal(size=3), rng.normal()
    queries = _sphere(2000, count)
    w = interpolation_weights(measured, queries, "barycentric")
    inside = ~w.outside
    assert inside.sum() > 500
    interpolated = (w.weights * (measured[w.indices] @ a + b)).sum(axis=1)[inside]
    v = measured[w.indices[inside]]  # (Q, 3, 3), the triangle of each query
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    scale = np.einsum("qc,qc->q", normal, v[:, 0]) / np.einsum("qc,qc->q", normal, queries[inside])
    p = queries[inside] * scale[:, None]
    np.testing.assert_allclose(interpolated, p @ a + b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_barycentric_finds_the_containing_hull_triangle(seed: int) -> None:
    measured = hemisphere_layout(100, "fibonacci") if seed == 0 else _sphere(60, seed)
    queries = _sphere(1500, seed + 10)
    w = interpolation_weights(measured, queries, "barycentric")
    triangles, _ = _hull_parts(measured)
    expected = np.zeros((len(queries), len(measured)))
    found = np.zeros(len(queries), dtype=bool)
    for t in triangles:
        lam = np.linalg.solve(measured[t].T, queries.T).T
        inside = np.all(lam >= 0.0, axis=1)
        expected[np.ix_(inside, t)] = lam[inside] / lam[inside].sum(axis=1, keepdims=True)
        found |= inside
    np.testing.assert_array_equal(w.outside, ~found)
    np.testing.assert_allclose(w.dense(len(measured))[found], expected[found], atol=1e-12)
    # The point location does not depend on the query order (each block walks from its last).
    order = np.random.default_rng(seed).permutation(len(queries))
    shuffled = interpolation_weights(measured, queries[order], "barycentric")
    np.testing.assert_allclose(shuffled.dense(len(measured)), w.dense(len(measured))[order])


def test_barycentric_is_linear_along_edges() -> None:
    measured = hemisphere_layout(30, "fibonacci")
    triangles, _ = _hull_parts(measured)
    i, j = int(triangles[0][0]), int(triangles[0][1])
    t = np.linspace(0.0, 1.0, 11)
    chord = (1.0 - t)[:, None] * measured[i] + t[:, None] * measured[j]
    w = interpolation_weights(measured, _unit(chord), "barycentric").dense(30)
    expected = np.zeros_like(w)
    expected[:, i], expected[:, j] = 1.0 - t, t
    np.testing.assert_allclose(w, expected, atol=1e-12)


def test_barycentric_is_continuous() -> None:
    measured = hemisphere_layout(30, "grid")
    azimuth = np.linspace(0.0, 360.0, 20001)
    path = direction_from_angles_deg(azimuth, 40.0 + 30.0 * np.sin(np.radians(3 * azimuth)))
    for method in ("barycentric", "rbf"):
        dense = interpolation_weights(measured, path, method).dense(30)
        assert np.abs(np.diff(dense, axis=0)).max() < 0.02, method


# --- rbf --------------------------------------------------------------------------------------


def test_rbf_weights_decay_with_angle() -> None:
    measured = hemisphere_layout(400, "fibonacci")
    queries = _sphere(300, 3)
    w = interpolation_weights(measured, queries, "rbf")
    angles = angle_between(measured[w.indices], queries[:, None, :])
    order = np.argsort(angles, axis=1)
    sorted_weights = np.take_along_axis(w.weights, order, axis=1)
    assert np.all(np.diff(sorted_weights, axis=1) <= 1e-15)
    assert np.all(sorted_weights[:, 0] > 0.0)


def test_rbf_width() -> None:
    measured = hemisphere_layout(100, "fibonacci")
    queries = _sphere(50, 4)
    spacing = mean_spacing_deg(measured)
    default = interpolation_weights(measured, queries, "rbf")
    explicit = interpolation_weights(measured, queries, "rbf", width_deg=spacing)
    np.testing.assert_allclose(default.weights, explicit.weights, rtol=1e-12)
    narrow = interpolation_weights(measured, queries, "rbf", width_deg=spacing / 4)
    assert np.all(narrow.weights[:, 0] >= default.weights[:, 0] - 1e-12)


def test_mean_spacing_deg() -> None:
    ring = direction_from_angles_deg(np.arange(0.0, 360.0, 15.0), 90.0)
    assert mean_spacing_deg(ring) == pytest.approx(15.0, rel=1e-12)
    assert 10.0 < mean_spacing_deg(hemisphere_layout(100, "fibonacci")) < 20.0
    with pytest.raises(InputError, match="two directions"):
        mean_spacing_deg([[0.0, 0.0, 1.0]])


# --- outside the measured region --------------------------------------------------------------


@pytest.mark.parametrize(("layout", "count"), LAYOUTS)
def test_barycentric_clamps_to_the_nearest_boundary_point(layout: str, count: int) -> None:
    measured = hemisphere_layout(count, layout)
    queries = _sphere(400, count + 1)
    w = interpolation_weights(measured, queries, "barycentric", policy="clamp")
    _, edges = _hull_parts(measured)
    out = w.outside
    assert out.sum() > 150
    # At most two weights, on the ends of one boundary edge (or on one corner).
    boundary = {frozenset(e) for e in edges}
    for indices, weights in zip(w.indices[out], w.weights[out], strict=True):
        used = frozenset(int(i) for i in indices[weights > 0])
        assert len(used) == 1 or used in boundary
    # No point of the boundary (each arc sampled finely) is nearer.
    clamped = _unit(_blend(measured, w))[out]
    t = np.linspace(0.0, 1.0, 201)[:, None]
    samples = np.vstack([_unit((1 - t) * measured[a] + t * measured[b]) for a, b in edges])
    best = (queries[out] @ samples.T).max(axis=1)
    assert np.all(np.einsum("qc,qc->q", clamped, queries[out]) >= best - 1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_zero_policy_drops_outside_queries(method: str) -> None:
    measured = hemisphere_layout(30, "grid")
    queries = _sphere(500, 5)
    clamped = interpolation_weights(measured, queries, method, policy="clamp")
    zero = interpolation_weights(measured, queries, method, policy="zero")
    np.testing.assert_array_equal(zero.outside, clamped.outside)
    np.testing.assert_array_equal(zero.weights[zero.outside], 0.0)
    np.testing.assert_array_equal(zero.weights[~zero.outside], clamped.weights[~zero.outside])
    assert zero.indices.min() >= 0 and zero.indices.max() < 30


def test_the_region_ends_at_the_lowest_ring() -> None:
    # Grid layout of 30: the lowest ring is at 78.75 degrees; the region's edge between two of its
    # lights bulges up (a great-circle arc), so the ring's own inclination is outside in between.
    measured = hemisphere_layout(30, "grid")
    lowest = np.degrees(np.arccos(measured[:, 2].min()))
    azimuth = np.linspace(0.0, 360.0, 721)
    above = direction_from_angles_deg(azimuth, lowest - 5.0)
    below = direction_from_angles_deg(azimuth, lowest + 0.5)
    assert not interpolation_weights(measured, above, "nearest").outside.any()
    assert interpolation_weights(measured, below, "nearest").outside.all()


def test_a_set_over_the_whole_sphere_has_no_outside() -> None:
    w = interpolation_weights(_sphere(50, 2), _sphere(1000, 3), "barycentric")
    assert not w.outside.any()


def test_one_two_and_great_circle_sets() -> None:
    one = interpolation_weights([[0.0, 0.0, 2.0]], _sphere(10, 1), "barycentric")
    assert one.outside.all() and np.all(one.dense(1) == 1.0)
    two = direction_from_angles_deg([0.0, 0.0], [10.0, 50.0])
    on_arc = direction_from_angles_deg(0.0, 20.0)
    off_arc = direction_from_angles_deg(20.0, 30.0)  # projects onto the arc, between its ends
    w = interpolation_weights(two, np.stack([on_arc, off_arc]), "barycentric")
    np.testing.assert_array_equal(w.outside, [False, True])
    # On the arc, weights are the planar ratio along the chord.
    lam = np.linalg.lstsq(two.T, on_arc, rcond=None)[0]
    np.testing.assert_allclose(w.dense(2)[0], lam / lam.sum(), atol=1e-12)
    assert np.all(w.dense(2)[1] > 0)
    meridian = direction_from_angles_deg(0.0, [10.0, 30.0, 50.0, 70.0])
    w = interpolation_weights(meridian, meridian, "barycentric")
    np.testing.assert_allclose(w.dense(4), np.eye(4), atol=1e-12)
    assert not w.outside.any()


# --- the result type --------------------------------------------------------------------------


def test_dense_and_apply() -> None:
    measured = hemisphere_layout(30, "fibonacci")
    w = interpolation_weights(measured, _sphere(40, 8), "paper", m=4)
    values = np.random.default_rng(0).random((30, 5, 3)).astype(np.float32)
    expected = np.einsum("qn,npc->qpc", w.dense(30), values.astype(np.float64))
    np.testing.assert_allclose(w.apply(values), expected, rtol=1e-12)
    np.testing.assert_allclose(w.apply(measured[:, 2]), w.dense(30) @ measured[:, 2])
    with pytest.raises(InputError, match="measured directions"):
        w.dense(2)
    with pytest.raises(InputError, match="values"):
        w.apply(values[:2])


# --- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("measured", "queries", "kwargs", "message"),
    [
        ([[0, 0, 1], [0, 0, 0]], [[0, 0, 1]], {}, r"measured direction 1 is zero"),
        ([[0, 0, 1], [1, 0, np.nan]], [[0, 0, 1]], {}, r"measured direction 1 .*not finite"),
        ([[0, 0, 1]], [[0, 0, 1], [0, 0, 0]], {}, r"query direction 1 is zero"),
        ([[0, 0, 1]], [[np.inf, 0, 1]], {}, r"query direction 0 .*not finite"),
        ([[0, 0]], [[0, 0, 1]], {}, r"measured must have shape \(N, 3\).*\(1, 2\)"),
        (np.zeros((0, 3)), [[0, 0, 1]], {}, r"measured must have shape \(N, 3\) with N >= 1"),
        ([[0, 0, 1]], [0, 0, 1], {}, r"queries must have shape \(Q, 3\).*\(3,\)"),
        ([[0, 0, 1], [0, 0, 3]], [[0, 0, 1]], {}, r"measured directions 0 and 1 coincide"),
        ([[0, 0, 1]], [[0, 0, 1]], {"m": 0}, r"m .* integer >= 1, got 0"),
        ([[0, 0, 1]], [[0, 0, 1]], {"m": 2.5}, r"m .* got 2.5"),
        ([[0, 0, 1]], [[0, 0, 1]], {"method": "cubic"}, r"unknown interpolation method 'cubic'"),
        ([[0, 0, 1]], [[0, 0, 1]], {"policy": "wrap"}, r"unknown outside policy 'wrap'"),
        ([[0, 0, 1]], [[0, 0, 1]], {"method": "rbf", "width_deg": -1.0}, r"width_deg .* -1.0"),
        ([[0, 0, 1]], [[0, 0, 1]], {"method": "rbf", "width_deg": np.nan}, r"width_deg"),
        ([[0, 0, 1]], [[0, 0, 1]], {"width_deg": 5.0}, r"width_deg applies to method 'rbf'"),
        ([["a", 0, 1]], [[0, 0, 1]], {}, r"measured must be an array"),
    ],
)
def test_bad_input_is_refused(
    measured: object, queries: object, kwargs: dict[str, object], message: str
) -> None:
    method = str(kwargs.pop("method", "paper"))
    with pytest.raises(InputError, match=message):
        interpolation_weights(measured, queries, method, **kwargs)  # type: ignore[arg-type]


def test_a_light_sets_region_is_built_once_and_cannot_change() -> None:
    # The relighting asks for the region of one light set once per predicted light.
    from processing.measured_region import MeasuredRegion

    points = hemisphere_layout(30, "fibonacci")
    region = MeasuredRegion.build(points)
    assert MeasuredRegion.build(points.copy()) is region
    points[0] = -points[0]  # the caller's array is the caller's: the region kept its own
    assert not np.array_equal(region.vertices[0], points[0])
    assert MeasuredRegion.build(points) is not region
    with pytest.raises(ValueError, match="read-only"):
        region.triangles[0, 0] = 1
