from __future__ import annotations

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.point_spacing import point_spacing
from render.splat import plan_splats, splat
from sim.scenes import build_scene
from sim.synthetic_camera import image_of_points


@pytest.mark.parametrize("scene", ["glossy-sphere", "textured-torus"])
def test_plan_reproduces_the_simulator_splats(scene: str) -> None:
    samples = build_scene(scene, 20_000)
    camera = PinholeCamera(40.0, 55.0, 4.0, 40.0, 96, 80)
    colours = np.random.default_rng(1).random((samples.count, 3))
    plan = plan_splats(samples.points, samples.normals, camera, samples.spacing)
    expected = image_of_points(samples, camera, colours)
    np.testing.assert_array_equal(plan.coverage, expected.coverage)
    np.testing.assert_allclose(splat(plan, colours), expected.rgb, rtol=1e-5, atol=1e-6)
    # The points that need relighting are exactly those the simulator's camera sees.
    np.testing.assert_array_equal(plan.visible, expected.visible)


def test_spacing_estimate_matches_the_sampler() -> None:
    samples = build_scene("diffuse-sphere", 50_000)
    assert abs(point_spacing(samples.points) / samples.spacing - 1) < 0.03


def test_weights_sum_to_one_per_covered_pixel() -> None:
    samples = build_scene("diffuse-sphere", 10_000)
    plan = plan_splats(
        samples.points, samples.normals, PinholeCamera(0.0, 30.0, width=64, height=64)
    )
    records = plan.records
    sums = np.bincount(plan.pixel_index[records], weights=plan.weight[records], minlength=64 * 64)
    np.testing.assert_allclose(sums[plan.coverage.ravel()], 1.0, rtol=1e-5)
    assert np.all(sums[~plan.coverage.ravel()] == 0)
    ones = splat(plan, np.ones((samples.count, 3)))
    np.testing.assert_allclose(ones[plan.coverage], 1.0, rtol=1e-5)


def test_bad_radiance_shape_is_refused() -> None:
    samples = build_scene("diffuse-sphere", 1000)
    plan = plan_splats(
        samples.points, samples.normals, PinholeCamera(0.0, 30.0, width=16, height=16)
    )
    with pytest.raises(InputError, match=r"\(1000, 3\)"):
        splat(plan, np.ones((999, 3)))


def test_spacing_of_a_square_lattice_is_its_pitch() -> None:
    u, v = np.meshgrid(np.arange(300) * 0.01, np.arange(300) * 0.01)
    lattice = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    assert point_spacing(lattice) == pytest.approx(0.01, rel=0.03)
