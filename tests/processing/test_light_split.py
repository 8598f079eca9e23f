from __future__ import annotations

import numpy as np
import pytest

from core.directions import fibonacci_sphere, hemisphere_layout, panorama_solid_angles
from core.errors import InputError
from processing.light_split import LightSplitter, outside_pixels, split_light
from processing.lights import disassemble_lights

HEIGHT = 64


def _energy(rgb: np.ndarray) -> float:
    return float(np.sum(rgb * panorama_solid_angles(*rgb.shape[:2])[:, :, None]))


def test_the_two_parts_add_up_to_the_panorama_and_neither_is_negative() -> None:
    rgb = np.random.default_rng(3).gamma(0.5, size=(HEIGHT, 2 * HEIGHT, 3)).astype(np.float32)
    parts = split_light(rgb, hemisphere_layout(49, "fibonacci"))
    np.testing.assert_allclose(parts.smooth + parts.sharp, rgb, rtol=1e-6, atol=1e-7)
    assert parts.smooth.min() >= 0.0 and parts.sharp.min() >= 0.0
    assert parts.sharp_share == pytest.approx(_energy(parts.sharp) / _energy(rgb), rel=1e-5)
    # The sum's weights: the smooth part gathered into the lights' cells, as the sum gathers.
    gathered = disassemble_lights(parts.smooth, hemisphere_layout(49, "fibonacci")).rgb
    np.testing.assert_allclose(parts.smooth_cells, gathered, rtol=1e-4)


def test_a_uniform_sky_around_lights_on_the_whole_sphere_is_all_the_sums() -> None:
    parts = split_light(np.ones((HEIGHT, 2 * HEIGHT, 3)), fibonacci_sphere(60))
    assert parts.sharp_share < 1e-6
    assert not outside_pixels(fibonacci_sphere(60), HEIGHT).any()


def test_a_sun_is_split_off_and_its_sky_is_left_to_the_sum() -> None:
    rgb = np.ones((HEIGHT, 2 * HEIGHT, 3))
    rgb[10, 40] = 5e4  # one pixel: a sun far brighter than twice its cell's mean
    sun = float(_energy(rgb) - _energy(np.ones_like(rgb)))
    parts = split_light(rgb, fibonacci_sphere(60))
    brightest = np.unravel_index(np.argmax(parts.sharp[..., 0]), rgb.shape[:2])
    assert (int(brightest[0]), int(brightest[1])) == (10, 40)
    # All of the sun but twice its cell's mean stays with the pixel: most of it is sharp.
    assert 0.8 * sun < _energy(parts.sharp) <= sun
    assert np.count_nonzero(parts.sharp[..., 0]) == 1


def test_light_below_the_lowest_lights_is_sharp_however_smooth() -> None:
    sphere = fibonacci_sphere(200)
    lights = sphere[sphere[:, 2] > np.sin(np.radians(20.0))]  # none within 20 degrees of it
    outside = outside_pixels(lights, HEIGHT)
    below = np.arange(HEIGHT) >= HEIGHT // 2
    assert outside[below].all() and bool(outside[: HEIGHT // 2].any())  # the band above too
    parts = split_light(np.ones((HEIGHT, 2 * HEIGHT, 3)), lights)
    assert np.all(parts.sharp[outside] == 1.0) and np.all(parts.smooth[outside] == 0.0)


def test_a_contrast_of_one_or_less_and_a_mask_of_another_size_are_refused() -> None:
    rgb = np.ones((HEIGHT, 2 * HEIGHT, 3))
    with pytest.raises(InputError, match="above 1"):
        split_light(rgb, fibonacci_sphere(20), contrast=1.0)
    with pytest.raises(InputError, match="splitter's"):
        LightSplitter(fibonacci_sphere(20), 8).split(rgb)
