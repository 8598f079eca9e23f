from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import SphericalVoronoi, cKDTree

from core.directions import panorama_directions, panorama_solid_angles
from processing.lights import disassemble_lights, nearest_sample_labels


def _directions(k: int, seed: int) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(k, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@settings(max_examples=30)
@given(st.integers(1, 200), st.integers(0, 2**32 - 1), st.integers(2, 40))
def test_energy_is_conserved(k: int, seed: int, h: int) -> None:
    rng = np.random.default_rng(seed)
    rgb = (rng.random((h, 2 * h, 3)) ** 4 * 100).astype(np.float32)
    lights = disassemble_lights(rgb, _directions(k, seed))
    total = (rgb.astype(np.float64) * panorama_solid_angles(h, 2 * h)[:, :, None]).sum((0, 1))
    np.testing.assert_allclose(lights.rgb.sum(0), total, rtol=1e-12, atol=1e-12)
    assert lights.solid_angle_sr.sum() == pytest.approx(4 * np.pi, rel=1e-12)


@pytest.mark.parametrize("k", [1, 2, 13, 64, 1024])
def test_labels_are_the_nearest_sample(k: int) -> None:
    d = _directions(k, k)
    labels = nearest_sample_labels(d, 128, 256)
    expected = cKDTree(d).query(panorama_directions(128, 256).reshape(-1, 3))[1]
    np.testing.assert_array_equal(labels.ravel(), expected)


@pytest.mark.parametrize("k", [8, 32, 64])
def test_cell_areas_match_scipy(k: int) -> None:
    d = _directions(k, 100 + k)
    lights = disassemble_lights(np.ones((512, 1024, 3), dtype=np.float32), d)
    areas = SphericalVoronoi(d).calculate_areas()
    np.testing.assert_allclose(lights.solid_angle_sr, areas, rtol=0.02)


def test_disassembled_panorama_keeps_energy() -> None:
    rgb = np.random.default_rng(3).random((32, 64, 3)).astype(np.float32)
    lights = disassemble_lights(rgb, _directions(10, 3))
    omega = panorama_solid_angles(32, 64)[:, :, None]
    np.testing.assert_allclose(
        (lights.to_panorama() * omega).sum((0, 1)), lights.rgb.sum(0), rtol=1e-5
    )
