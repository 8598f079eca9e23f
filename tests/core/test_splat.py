"""The banded, parallel disk passes against a plain dense reference (every point x pixel)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.splat import ROWS_PER_BAND, blend_splats, camera_splats, row_bands, shown_points, zbuffer
from render.splat import plan_splats


def _cloud(seed: int, count: int = 600) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    # Points in a slab facing the camera at (0, 60): overlapping disks of several sizes, some
    # hidden behind others, some facing away.
    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.6, 0.6, (count, 3))
    normals = np.tile(PinholeCamera(0.0, 60.0).direction, (count, 1))
    normals[rng.random(count) < 0.1] *= -1.0
    return points, normals


def _dense_covers(
    cols: NDArray[np.float64],
    rows: NDArray[np.float64],
    depth: NDArray[np.float64],
    radius: NDArray[np.float64],
    height: int,
    width: int,
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """(covers (P, H W), squared distances (P, H W), z-buffer (H W,)) by brute force."""
    i, j = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    d2 = (j.ravel()[None] + 0.5 - cols[:, None]) ** 2 + (i.ravel()[None] + 0.5 - rows[:, None]) ** 2
    finite = np.isfinite(depth) & (depth > 0)
    covers = (d2 <= (radius * radius)[:, None]) & finite[:, None]
    buffer = np.where(covers, depth[:, None], np.inf).min(axis=0)
    return covers, d2, buffer


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_banded_passes_match_the_dense_reference(seed: int) -> None:
    # 37 rows: two whole bands of 16 and a short one; disks straddle the band edges.
    camera = PinholeCamera(0.0, 60.0, distance=4.0, fov_deg=30.0, width=29, height=37)
    points, normals = _cloud(seed)
    s = camera_splats(points, normals, camera, spacing=0.06)
    covers, d2, buffer = _dense_covers(s.cols, s.rows, s.depth, s.radius, 37, 29)
    assert len(s.bands.start) - 1 == -(-37 // ROWS_PER_BAND)
    np.testing.assert_array_equal(s.buffer.ravel(), buffer)
    front = covers & (s.depth[:, None] <= buffer[None] + s.tolerance)
    np.testing.assert_array_equal(shown_points(s), front.any(axis=1))
    # The plan: every front cover, filed by pixel in increasing point order.
    plan = plan_splats(points, normals, camera, spacing=0.06)
    pixel, point = np.nonzero(front.T)
    records = plan.records[np.argsort(plan.pixel_index[plan.records], kind="stable")]
    np.testing.assert_array_equal(plan.pixel_index[records], pixel)
    np.testing.assert_array_equal(plan.point_index[records], point)
    weight = 1.0 - d2[point, pixel] / (s.radius[point] ** 2 + 1e-12) + 1e-3
    total = np.bincount(pixel, weights=weight, minlength=37 * 29)
    np.testing.assert_allclose(plan.weight[records], weight / total[pixel], rtol=1e-6)
    np.testing.assert_array_equal(plan.coverage.ravel(), total > 0)
    np.testing.assert_array_equal(plan.visible, front.any(axis=1))
    # Blending colours sums the same weights.
    colours = np.random.default_rng(seed).random((len(points), 3))
    image, summed = blend_splats(s, colours)
    np.testing.assert_allclose(summed.ravel(), total, rtol=1e-6)
    expected = np.zeros((37 * 29, 3))
    np.add.at(expected, pixel, weight[:, None] * colours[point])
    covered = total > 0
    expected[covered] /= total[covered, None]
    np.testing.assert_allclose(image.reshape(-1, 3), expected, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("rows_per_band", [1, 3, 16, 64])
def test_row_bands_hold_each_disk_in_every_band_it_reaches(rows_per_band: int) -> None:
    camera = PinholeCamera(0.0, 60.0, distance=4.0, fov_deg=30.0, width=29, height=37)
    s = camera_splats(*_cloud(3), camera, spacing=0.06)
    bands = row_bands(s.cols, s.rows, s.depth, s.radius, 37, 29, rows_per_band)
    covers, _, _ = _dense_covers(s.cols, s.rows, s.depth, s.radius, 37, 29)
    for band in range(len(bands.start) - 1):
        members = bands.points[bands.start[band] : bands.start[band + 1]]
        assert np.all(np.diff(members) > 0)  # increasing: each pixel sees points in order
        rows = slice(band * rows_per_band * 29, (band + 1) * rows_per_band * 29)
        # Every disk that covers a pixel of the band is a member (members may only graze it).
        assert set(np.flatnonzero(covers[:, rows].any(axis=1))) <= set(members.tolist())
    assert int(bands.cells.sum()) >= int(covers.sum())


def test_zbuffer_of_disks_off_the_image_or_behind_is_empty() -> None:
    inf = np.inf
    buffer = zbuffer(
        np.array([-5.0, 3.0, 3.0]), np.array([3.0, 40.0, 3.0]), np.array([1.0, 1.0, inf]),
        np.array([1.0, 1.0, 1.0]), 8, 8,
    )  # fmt: skip
    assert np.all(np.isinf(buffer))
