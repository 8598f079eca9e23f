from __future__ import annotations

import numpy as np
import pytest

from core.directions import panorama_directions, panorama_solid_angles
from core.errors import InputError
from core.light_set import LightSet, grid_lights


def _panorama(seed: int, height: int = 16) -> np.ndarray:
    rng = np.random.default_rng(seed)
    image = rng.random((height, 2 * height, 3))
    image[3:5, 10:12] += 20.0  # a small sun
    return image


@pytest.mark.parametrize("grid", [None, 16, 8, 5, 1])
def test_grid_lights_keep_the_light_and_tile_the_panorama(grid: int | None) -> None:
    rgb = _panorama(1)
    lights = grid_lights(rgb, grid)
    total = (rgb * panorama_solid_angles(16, 32)[:, :, None]).sum(axis=(0, 1))
    np.testing.assert_allclose(lights.rgb.sum(axis=0), total, rtol=1e-12)
    assert lights.solid_angle_sr is not None and lights.labels is not None
    assert lights.solid_angle_sr.sum() == pytest.approx(4 * np.pi, rel=1e-12)
    # Each light's cell is exactly the pixels labelled with it.
    omega = panorama_solid_angles(16, 32)
    for k in range(lights.k):
        assert omega[lights.labels == k].sum() == pytest.approx(lights.solid_angle_sr[k])
    np.testing.assert_allclose(np.linalg.norm(lights.directions, axis=1), 1.0)


def test_every_pixel_is_its_own_light() -> None:
    rgb = _panorama(2, 8)
    lights = grid_lights(rgb, None)
    np.testing.assert_allclose(lights.directions, panorama_directions(8, 16).reshape(-1, 3))
    np.testing.assert_allclose(lights.to_panorama(), rgb, rtol=1e-6)


def test_nonempty_drops_dark_cells_and_keeps_the_picture() -> None:
    rgb = _panorama(3)
    rgb[8:] = 0.0  # a black ground
    lights = grid_lights(rgb, 8)
    lit = lights.nonempty()
    assert lit.k == lights.k // 2
    assert (lit.rgb.sum(axis=1) > 0).all()
    np.testing.assert_allclose(lit.rgb.sum(axis=0), lights.rgb.sum(axis=0))
    np.testing.assert_allclose(lit.to_panorama(), lights.to_panorama())
    assert lit.nonempty() is lit


def test_lights_without_cells_refuse_pictures() -> None:
    lights = LightSet(np.array([[0.0, 0.0, 1.0]]), np.ones((1, 3)))
    with pytest.raises(InputError, match="no cells"):
        lights.to_panorama()
    with pytest.raises(InputError, match="does not match"):
        LightSet(np.array([[0.0, 0.0, 1.0]]), np.ones((2, 3)))
    with pytest.raises(InputError, match="grid height"):
        grid_lights(_panorama(4), 0)
