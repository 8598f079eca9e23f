from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.directions import panorama_directions, panorama_solid_angles, rotate_directions_yaw
from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet
from processing.panorama import Panorama, adjust_panorama, read_panorama
from processing.sample_model_store import models_for_field
from render.engines.models import ModelRelightSettings
from render.precomputed_lighting import (
    ALPHAS,
    lobe_albedo,
    prefilter_panorama,
    rotate_sh_yaw,
    sh_basis,
)
from sim.field import field_cameras, simulate_field


def test_harmonics_are_orthonormal_and_a_yaw_turns_their_coefficients() -> None:
    directions = panorama_directions(128, 256).reshape(-1, 3)
    omega = np.array(panorama_solid_angles(128, 256)).ravel()
    basis = sh_basis(directions)
    gram = (basis * omega[:, None]).T @ basis
    assert np.abs(gram - np.eye(25)).max() < 1e-3
    lobe = np.exp(3.0 * directions @ np.array([0.6, 0.0, 0.8]))
    turned = np.exp(3.0 * rotate_directions_yaw(directions, -40.0) @ np.array([0.6, 0.0, 0.8]))
    coefficients = basis.T @ (lobe * omega)
    expected = basis.T @ (turned * omega)
    assert rotate_sh_yaw(coefficients[:, None], 40.0)[:, 0] == pytest.approx(expected, abs=1e-9)


def test_a_uniform_sky_prefilters_to_itself_and_the_lobe_conserves_energy() -> None:
    prefilter = prefilter_panorama(np.full((64, 128, 3), 0.5, np.float32), bright=0)
    assert prefilter.specular == pytest.approx(0.5, rel=1e-3)
    # Only the constant harmonic: 0.5 x 4 pi x Y00.
    assert prefilter.sh[0] == pytest.approx(0.5 * 4 * np.pi / np.sqrt(4 * np.pi), rel=1e-3)
    assert np.abs(prefilter.sh[1:]).max() < 1e-3
    albedo = lobe_albedo()
    assert albedo.shape[0] == len(ALPHAS)
    assert np.all(albedo <= 1.0 + 1e-3) and np.all(albedo > 0.0)


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("precomputed") / "glossy.zarr"
    simulate_field(
        path, "glossy-sphere", lights=16, cameras=field_cameras(8, width=48, height=48),
        points=3000,
    )  # fmt: skip
    return ReflectanceField.open(path)


def _render(field: ReflectanceField, lighting: str, panorama: Panorama, yaw: float) -> np.ndarray:
    engine = ModelRelightSettings(lighting=lighting, grid_height=64).open(  # type: ignore[arg-type]
        field, models_for_field(field)
    )
    engine.set_view(PinholeCamera(20.0, 45.0, width=64, height=64))
    engine.set_lighting(panorama, yaw_deg=yaw)
    image = engine.render()
    _outside[lighting, yaw] = image.outside_fraction
    return image.radiance[image.needed]


_outside: dict[tuple[str, float], float] = {}


def test_precomputed_lighting_follows_the_exact_sum_and_turns_with_the_yaw(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    panorama = read_panorama(courtyard_path)
    for yaw in (0.0, 100.0):
        exact = _render(glossy, "grid", panorama, yaw)
        fast = _render(glossy, "precomputed", panorama, yaw)
        error = np.sqrt(np.mean((fast - exact) ** 2) / np.mean(exact**2))
        # The split sum errs at grazing views (docs/relighting.md): a few per cent here.
        assert error < 0.12, f"yaw {yaw}: {error:.3f}"
        # The share of light from outside the measured lights, read off a map of the region.
        assert _outside["precomputed", yaw] == pytest.approx(_outside["grid", yaw], abs=0.01)
    # A yaw of the controls is the same lighting as the panorama turned beforehand.
    turned = adjust_panorama(panorama, yaw_deg=100.0)
    direct = _render(glossy, "precomputed", turned, 0.0)
    by_yaw = _render(glossy, "precomputed", panorama, 100.0)
    assert np.sqrt(np.mean((direct - by_yaw) ** 2) / np.mean(by_yaw**2)) < 0.02


def test_precomputed_engine_refuses_a_modulation_and_sums_given_lights_exactly(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    models = models_for_field(glossy)
    fast = ModelRelightSettings(lighting="precomputed").open(glossy, models)
    with pytest.raises(InputError, match="modulation"):
        fast.set_lighting(read_panorama(courtyard_path), modulation=np.ones((4, 8)))
    exact = ModelRelightSettings(lighting="grid").open(glossy, models)
    lights = LightSet(np.array([[0.0, 0.6, 0.8]]), np.array([[1.0, 0.9, 0.8]]))
    camera = PinholeCamera(20.0, 45.0, width=64, height=64)
    frames = []
    for engine in (fast, exact):
        engine.set_lights(lights)
        engine.set_view(camera)
        frames.append(engine.render().radiance)
    assert np.array_equal(frames[0], frames[1])
