from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.directions import angles_deg_from_direction, panorama_solid_angles
from core.errors import InputError
from core.image_io import write_linear16_tiff
from core.light_set import grid_lights
from processing.environment import (
    LightingControls,
    adjust_environment,
    cell_centroids,
    light_environment,
    read_modulation_map,
)
from processing.panorama import Panorama, panorama_from_array


def _panorama(height: int = 32) -> Panorama:
    rng = np.random.default_rng(0)
    rgb = rng.random((height, 2 * height, 3)).astype(np.float32)
    rgb[4:6, 10:12] += 50.0  # a sun
    return panorama_from_array(rgb, source="test sky")


def _total(rgb: np.ndarray) -> np.ndarray:
    height, width = rgb.shape[:2]
    return (rgb.astype(np.float64) * panorama_solid_angles(height, width)[:, :, None]).sum((0, 1))


def test_sampled_lighting_gathers_all_the_light_into_k_lights() -> None:
    panorama = _panorama()
    lighting = light_environment(panorama, LightingControls(k=16))
    lights = lighting.light_set()
    assert lights.k == 16
    np.testing.assert_allclose(lights.rgb.sum(axis=0), _total(panorama.rgb), rtol=1e-9)
    assert lighting.panorama.rgb is not None and lighting.controls.k == 16


def test_exposure_scales_the_light_and_yaw_turns_it() -> None:
    panorama = _panorama()
    plain = light_environment(panorama, LightingControls(k=8)).light_set()
    bright = light_environment(panorama, LightingControls(k=8, exposure=2.0)).light_set()
    np.testing.assert_allclose(bright.rgb.sum(axis=0), 2.0 * plain.rgb.sum(axis=0), rtol=1e-6)
    # The brightest light (the sun's cell, at its centroid) turns with the yaw,
    # counter-clockwise seen from above.
    centred = LightingControls(k=8, centroids=True)
    plain = light_environment(panorama, centred).light_set()
    turned = light_environment(panorama, replace(centred, yaw_deg=90.0)).light_set()
    sun = angles_deg_from_direction(plain.directions[np.argmax(plain.rgb.sum(axis=1))])
    moved = angles_deg_from_direction(turned.directions[np.argmax(turned.rgb.sum(axis=1))])
    assert (moved[0] - sun[0]) % 360.0 == pytest.approx(90.0, abs=6.0)
    assert moved[1] == pytest.approx(sun[1], abs=6.0)


def test_a_modulation_map_steers_samples_not_light() -> None:
    panorama = _panorama()
    modulation = np.ones((8, 16), dtype=np.float32)
    modulation[4:] = 0.0  # no samples below the horizon
    controls = LightingControls(k=24, modulation=modulation)
    lights = light_environment(panorama, controls).light_set()
    assert (lights.directions[:, 2] > -1e-9).all()
    np.testing.assert_allclose(lights.rgb.sum(axis=0), _total(panorama.rgb), rtol=1e-9)


def test_grid_and_panorama_lighting() -> None:
    panorama = _panorama()
    controls = LightingControls(lighting="grid", grid_height=8, yaw_deg=30.0)
    lighting = light_environment(panorama, controls)
    expected = grid_lights(adjust_environment(panorama, controls).rgb, 8)
    np.testing.assert_array_equal(lighting.light_set().rgb, expected.rgb)
    bare = light_environment(panorama, LightingControls(lighting="panorama", exposure=3.0))
    assert bare.lights is None
    np.testing.assert_allclose(bare.panorama.rgb, 3.0 * panorama.rgb, rtol=1e-6)
    with pytest.raises(InputError, match="no lights"):
        bare.light_set()
    with pytest.raises(InputError, match="no lights"):
        bare.to_json()


def test_modulation_is_refused_where_every_pixel_lights() -> None:
    with pytest.raises(InputError, match="modulation map steers sampled lights"):
        LightingControls(lighting="grid", modulation=np.ones((4, 8)))
    with pytest.raises(InputError, match="unknown lighting"):
        LightingControls(lighting="voronoi")  # type: ignore[arg-type]


def test_centroids_move_the_lights_not_their_light() -> None:
    panorama = _panorama()
    plain = light_environment(panorama, LightingControls(k=12)).light_set()
    centred = cell_centroids(plain, panorama.rgb)
    np.testing.assert_array_equal(centred.rgb, plain.rgb)
    np.testing.assert_allclose(np.linalg.norm(centred.directions, axis=1), 1.0)
    assert np.abs(centred.directions - plain.directions).max() > 1e-3
    same = light_environment(panorama, LightingControls(k=12, centroids=True)).light_set()
    np.testing.assert_allclose(same.directions, centred.directions)


def test_lights_json_document() -> None:
    document = light_environment(_panorama(), LightingControls(k=4, seed=3)).to_json()
    assert document["k"] == 4 and document["controls"]["seed"] == 3
    assert np.asarray(document["directions"]).shape == (4, 3)
    assert sum(document["solid_angle_sr"]) == pytest.approx(4 * np.pi)


def test_modulation_maps_are_read_linear(tmp_path: Path) -> None:
    pixels = np.full((4, 8, 3), 32768, dtype=np.uint16)
    write_linear16_tiff(tmp_path / "half.tif", pixels)
    values = read_modulation_map(tmp_path / "half.tif")
    np.testing.assert_allclose(values, 32768 / 65535, rtol=1e-6)  # not sRGB-decoded
    with pytest.raises(InputError, match="no such file"):
        read_modulation_map(tmp_path / "missing.png")
