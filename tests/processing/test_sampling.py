from __future__ import annotations

import numpy as np
import pytest

from core.directions import angle_between, panorama_directions, panorama_row_solid_angles
from core.errors import InputError
from processing.sampling import SAMPLERS, sample_environment, sampling_density


def _sky(h: int = 64) -> np.ndarray:
    rng = np.random.default_rng(7)
    return (0.2 + rng.random((h, 2 * h, 3))).astype(np.float32)


@pytest.mark.parametrize("method", SAMPLERS)
@pytest.mark.parametrize("k", [1, 7, 64, 300])
def test_exact_k(method: str, k: int) -> None:
    s = sample_environment(_sky(), k, method=method, seed=2)
    assert s.directions.shape == (k, 3)
    np.testing.assert_allclose(np.linalg.norm(s.directions, axis=1), 1.0)


@pytest.mark.parametrize("method", SAMPLERS)
def test_deterministic_per_seed(method: str) -> None:
    a = sample_environment(_sky(), 32, method=method, seed=5).directions
    np.testing.assert_array_equal(
        a, sample_environment(_sky(), 32, method=method, seed=5).directions
    )


@pytest.mark.parametrize("method", [m for m in SAMPLERS if m != "uniform"])  # uniform ignores light
def test_a_sun_receives_a_sample(method: str) -> None:
    sky = _sky() * 0.01
    sky[20, 70] = 5e4  # one bright pixel carrying most of the light
    sun = panorama_directions(64, 128)[20, 70]
    s = sample_environment(sky, 16, method=method)
    pixel = np.sqrt(panorama_row_solid_angles(64, 128)[20])  # about one pixel, radians
    assert angle_between(s.directions, sun).min() <= 1.5 * pixel


@pytest.mark.parametrize("method", SAMPLERS)
def test_zero_modulation_forbids_samples(method: str) -> None:
    modulation = np.ones((8, 16))
    modulation[:, :8] = 0.0  # left half of the panorama
    s = sample_environment(_sky(), 40, method=method, modulation=modulation)
    az = np.arctan2(s.directions[:, 1], s.directions[:, 0])
    # Left half of the image is azimuth in (0, pi].
    assert np.all(az <= 1e-9)


def test_density_follows_solid_angle_unless_paper() -> None:
    sky = np.ones((32, 64, 3), dtype=np.float32)
    d = sampling_density(sky, 10)
    assert d.sum() == pytest.approx(10)
    assert d[0, 0] < d[16, 0]  # pole pixels are smaller
    paper = sampling_density(sky, 10, paper=True)
    np.testing.assert_allclose(paper, 10 / paper.size)


def test_samples_follow_energy_on_the_sphere() -> None:
    # Uniform radiance: solid-angle weights spread samples evenly in z; paper mode crowds poles.
    sky = np.ones((128, 256, 3), dtype=np.float32)
    even = sample_environment(sky, 400).directions
    assert np.mean(np.abs(even[:, 2]) > 0.9) == pytest.approx(0.1, abs=0.04)
    crowded = sample_environment(sky, 400, paper=True).directions
    assert np.mean(np.abs(crowded[:, 2]) > 0.9) > 0.2


def test_bad_arguments() -> None:
    with pytest.raises(InputError, match="unknown sampler"):
        sample_environment(_sky(), 8, method="random")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="k must be"):
        sample_environment(_sky(), 0)
    with pytest.raises(InputError, match="density is zero"):
        sample_environment(np.zeros((8, 16, 3), dtype=np.float32), 4)
    with pytest.raises(InputError, match="density is zero"):
        sample_environment(_sky(), 4, modulation=np.zeros((4, 8)))


def test_uniform_with_modulation_ignores_the_light() -> None:
    sky = _sky() * 0.01
    sky[:32] *= 1e4  # upper hemisphere far brighter
    modulation = np.ones((4, 8))
    d = sample_environment(sky, 200, method="uniform", modulation=modulation).directions
    assert np.mean(d[:, 2] > 0) == pytest.approx(0.5, abs=0.1)
