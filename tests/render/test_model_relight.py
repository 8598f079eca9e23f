from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.directions import hemisphere_layout, panorama_solid_angles
from core.errors import InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.light_set import LightSet, grid_lights
from processing.environment import LightingControls, light_environment
from processing.panorama import panorama_from_array
from processing.sample_models import (
    BasisFit,
    ParametricFit,
    SampleModels,
    choose_model,
    evaluate_basis,
    fit_sample_models,
)
from render.engines.interpolated import Relighter, RelightSettings
from render.engines.model_shading import prepare_lighting, relight_models
from render.engines.models import ModelRelighter, ModelRelightSettings
from sim.ground_truth import render_environment, shade_environment
from sim.scenes import build_scene
from tests.sim_fields import peak_seen, simulated_field


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("glossy") / "f.zarr"
    return simulated_field(
        path, "glossy-sphere", lights=16, cameras=12, size=64, points=2500, cached_slabs=12
    )


@pytest.fixture(scope="module")
def models(glossy: ReflectanceField) -> SampleModels:
    return fit_sample_models(glossy)


def _panorama(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    image = rng.random((16, 32, 3)).astype(np.float32)
    image[3:5, 10:12] += 20.0  # a small sun
    return image


def _one_light(direction: np.ndarray, rgb: tuple[float, float, float] = (1, 1, 1)) -> LightSet:
    return LightSet(direction[None, :].astype(np.float64), np.array([rgb], dtype=float))


def _relative_rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2)))


def test_a_measured_light_at_a_measured_camera_reproduces_the_slab(
    glossy: ReflectanceField, models: SampleModels
) -> None:
    choice = choose_model(models)
    identified = peak_seen(glossy, 0.2)
    for s, t in ((2, 3), (7, 11)):
        lighting = prepare_lighting(models, _one_light(glossy.light_directions[t]))
        radiance = relight_models(models, choice, lighting, glossy.cameras[s])
        fit = models.fits[choice.chosen]
        assert isinstance(fit, ParametricFit)
        seen = glossy.visibility[s] & fit.fitted
        slab = glossy.camera_slab(s)[t]
        # Exact where the fit is (its lobe identified), close everywhere.
        assert _relative_rmse(radiance[seen], slab[seen]) < 0.01
        exact = seen & identified
        assert exact.sum() > 0.5 * seen.sum()
        np.testing.assert_allclose(radiance[exact], slab[exact], rtol=1e-3, atol=1e-5)


def test_relighting_is_linear_in_the_light(glossy: ReflectanceField, models: SampleModels) -> None:
    choice = choose_model(models)
    camera = PinholeCamera(17.0, 52.0, width=64, height=64)
    a = grid_lights(_panorama(1), 8)
    b = grid_lights(_panorama(2), 8)
    both = LightSet(
        np.concatenate([a.directions, b.directions]), np.concatenate([a.rgb, 2.5 * b.rgb])
    )

    def relit(lights: LightSet) -> np.ndarray:
        return relight_models(models, choice, prepare_lighting(models, lights), camera)

    scaled = LightSet(b.directions, 2.5 * b.rgb)
    np.testing.assert_allclose(relit(both), relit(a) + relit(scaled), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(relit(scaled), 2.5 * relit(b), rtol=1e-5, atol=1e-6)


def test_the_model_beats_interpolation_between_captured_views(
    glossy: ReflectanceField, models: SampleModels
) -> None:
    # Halfway in azimuth between two cameras of a ring, under a random sky with a sun.
    camera = replace(glossy.cameras[6], azimuth_deg=glossy.cameras[6].azimuth_deg + 30.0)
    samples = build_scene("glossy-sphere", glossy.shape[2])
    rgb = _panorama(3)
    rgb[8:] = 0.0  # light from the measured hemisphere only: the baseline's best case
    truth = render_environment(samples, rgb, camera, grid_height=8, shadows=False)
    panorama = panorama_from_array(rgb)
    relighter = ModelRelighter(
        glossy,
        ModelRelightSettings(lighting="grid", grid_height=8, spacing=samples.spacing),
        models=models,
    )
    relighter.set_lighting(panorama)
    relighter.set_view(camera)
    image = relighter.render()
    baseline = Relighter(
        glossy,
        RelightSettings(
            scheme="pixels",
            interpolation="barycentric",
            view_interpolation="barycentric",
            grid_height=8,
        ),
    )
    baseline.set_lighting(panorama)
    baseline.set_view(camera)
    reference = baseline.render()
    mask = image.coverage & truth.coverage & reference.coverage
    model_error = _relative_rmse(image.rgb[mask], truth.rgb[mask])
    baseline_error = _relative_rmse(reference.rgb[mask], truth.rgb[mask])
    assert model_error < 0.02
    assert model_error < 0.25 * baseline_error


def test_light_from_below_the_rig_is_evaluated_physically(
    glossy: ReflectanceField, models: SampleModels
) -> None:
    # A light from below the horizon: no rig light is near it, the fitted BRDF still knows the
    # answer (the linear schemes can only move it up to the lowest ring).
    below = np.array([0.3, 0.0, -1.0]) / np.linalg.norm([0.3, 0.0, -1.0])
    camera = PinholeCamera(0.0, 100.0, width=64, height=64)  # looking slightly up
    samples = build_scene("glossy-sphere", glossy.shape[2])
    expected = shade_environment(samples, camera.position, _one_light(below), shadows=False)
    choice = choose_model(models, candidates=["lambert+ggx"])
    lighting = prepare_lighting(models, _one_light(below))
    assert lighting.outside_fraction == 1.0
    radiance = relight_models(models, choice, lighting, camera)
    fit = models.fits["lambert+ggx"]
    assert isinstance(fit, ParametricFit) and glossy.normals is not None
    # Samples facing the light whose lobe the rig identified (the others have no fit, or a
    # broader lobe than the truth).
    useful = fit.fitted & (glossy.normals @ below > 0.2) & peak_seen(glossy, 0.2)
    assert useful.sum() > 20
    np.testing.assert_allclose(radiance[useful], expected[useful], rtol=1e-3, atol=1e-6)


def test_sampled_lights_keep_the_light_and_sit_at_their_cells_centroids() -> None:
    rgb = _panorama(5)
    total = (rgb * panorama_solid_angles(16, 32)[:, :, None]).sum(axis=(0, 1))
    panorama = panorama_from_array(rgb)
    centred = light_environment(panorama, LightingControls(k=16, centroids=True)).light_set()
    plain = light_environment(panorama, LightingControls(k=16)).light_set()
    np.testing.assert_allclose(centred.rgb.sum(axis=0), total, rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(centred.directions, axis=1), 1.0)
    # The centroid of a cell differs from its sample, the light is the same.
    np.testing.assert_allclose(centred.rgb, plain.rgb)
    assert np.abs(centred.directions - plain.directions).max() > 1e-3


def test_the_relighter_renders_and_reports_holes(
    glossy: ReflectanceField, models: SampleModels
) -> None:
    relighter = ModelRelighter(glossy, ModelRelightSettings(k=32), models=models)
    assert relighter.choice.chosen == "lambert+ggx"
    assert relighter.visibility == "measured"  # a sphere casts no shadow: nothing to gain
    with pytest.raises(InputError, match="set a lighting and a view"):
        relighter.render()
    relighter.set_lighting(panorama_from_array(_panorama(6)))
    relighter.set_view(PinholeCamera(45.0, 170.0, width=48, height=48))  # from below
    image = relighter.render()
    assert image.rgb.shape == (48, 48, 3) and image.coverage.any()
    assert image.holes.any()  # no rig camera saw the bottom of the sphere
    assert np.all(np.isfinite(image.rgb)) and image.rgb[image.coverage].max() > 0


def test_settings_are_checked() -> None:
    with pytest.raises(InputError, match="'spot'"):
        ModelRelightSettings(lighting="spot")
    with pytest.raises(InputError, match="'shadowless'"):
        ModelRelightSettings(visibility="shadowless")
    with pytest.raises(InputError, match="spacing"):
        ModelRelightSettings(spacing=0.0)


@pytest.fixture(scope="module")
def rti(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    """A small Lambertian RTI-like pixel field (camera straight above) with a tilted patch."""
    path: Path = tmp_path_factory.mktemp("rti") / "f.zarr"
    lights = hemisphere_layout(40)
    height, width = 4, 5
    normals = np.tile([0.0, 0.0, 1.0], (height * width, 1))
    normals[:6] = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    values = np.maximum(lights @ normals.T, 0.0)[:, :, None] * np.array([0.6, 0.5, 0.4]) / np.pi
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, width, height)
    writer = FieldStoreWriter(
        path, points=None, normals=None, light_directions=lights, cameras=[camera],
        image_shape=(height, width),
    )  # fmt: skip
    for t in range(len(lights)):
        writer.write_slab(0, t, values[t].astype(np.float32))
    writer.write_visibility(0, np.ones(height * width, dtype=bool))
    writer.finish()
    return ReflectanceField.open(path)


def test_a_pixel_field_relights_at_its_own_view_only(rti: ReflectanceField) -> None:
    models = fit_sample_models(rti)
    relighter = ModelRelighter(rti, ModelRelightSettings(lighting="grid", grid_height=8), models)
    assert relighter.choice.chosen == "lambert"
    relighter.set_lighting(panorama_from_array(_panorama(7)))
    relighter.set_view(rti.cameras[0])
    image = relighter.render()
    assert image.rgb.shape == (4, 5, 3) and image.coverage.all()
    with pytest.raises(InputError, match="one view"):
        relighter.set_view(PinholeCamera(30.0, 40.0))
    with pytest.raises(InputError, match="needs surface points"):
        ModelRelighter(rti, ModelRelightSettings(visibility="geometry"), models)


@pytest.mark.parametrize("model", ["lambert", "ptm", "hsh3"])
def test_a_pixel_model_relights_a_measured_light_as_fitted(
    rti: ReflectanceField, model: str
) -> None:
    models = fit_sample_models(rti, models=[model])
    choice = choose_model(models)
    t = 17
    lighting = prepare_lighting(models, _one_light(rti.light_directions[t]))
    radiance = relight_models(models, choice, lighting, rti.cameras[0])
    fit = models.fits[model]
    if isinstance(fit, BasisFit):
        # A basis only approximates a clamped cosine; relighting must give its own value.
        basis = evaluate_basis(model, rti.light_directions[t : t + 1] @ models.camera_frame.T)
        expected = np.einsum("b,pbc->pc", basis[0], fit.coefficients)
    else:
        expected = rti.camera_slab(0)[t]
    np.testing.assert_allclose(radiance, expected, rtol=1e-4, atol=1e-7)


def test_pixel_fields_take_no_light_from_behind_the_object_plane(rti: ReflectanceField) -> None:
    models = fit_sample_models(rti, models=["lambert", "hsh2"])
    below = np.array([0.5, 0.0, -0.5]) / np.sqrt(0.5)
    for name in ("lambert", "hsh2"):
        choice = choose_model(models, candidates=[name])
        lighting = prepare_lighting(models, _one_light(below))
        assert not lighting.reaches.any()
        radiance = relight_models(models, choice, lighting, rti.cameras[0])
        assert np.abs(radiance).max() == 0.0
