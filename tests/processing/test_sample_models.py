from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.brdf import brdf
from core.camera_model import PinholeCamera
from core.directions import direction_from_angles_deg, hemisphere_layout
from core.errors import DatasetError, InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from processing.interpolation import interpolation_weights, mean_spacing_deg
from processing.sample_models import (
    ALPHA_RANGE,
    LOBE_SPACING,
    BasisFit,
    ParametricFit,
    SampleModels,
    choose_model,
    evaluate_basis,
    fit_sample_models,
    format_loo_table,
    geometric_shadow_marks,
    interpolation_loo,
    leave_one_out_barycentric,
    leave_one_out_weights,
    lobe_alpha_range,
    photometric_stereo,
    shadow_mark_errors,
    with_geometric_visibility,
)
from sim.scenes import build_scene
from sim.synthetic_camera import DirectionalLight, light_visibility
from tests.sim_fields import peak_seen, simulated_field


def _field(tmp: Path, scene: str, lights: int, cameras: int, points: int) -> ReflectanceField:
    path = tmp / f"{scene}.zarr"
    return simulated_field(path, scene, lights=lights, cameras=cameras, size=48, points=points)


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    return _field(tmp_path_factory.mktemp("glossy"), "glossy-sphere", 16, 8, 600)


@pytest.fixture(scope="module")
def diffuse(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    return _field(tmp_path_factory.mktemp("diffuse"), "diffuse-sphere", 16, 8, 600)


@pytest.fixture(scope="module")
def torus(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    return _field(tmp_path_factory.mktemp("torus"), "textured-torus", 16, 6, 3000)


@pytest.fixture(scope="module")
def glossy_models(glossy: ReflectanceField) -> SampleModels:
    return fit_sample_models(glossy)


@pytest.fixture(scope="module")
def diffuse_models(diffuse: ReflectanceField) -> SampleModels:
    return fit_sample_models(diffuse)


def _pixel_field(
    tmp: Path,
    values: np.ndarray,
    lights: np.ndarray,
    normals: np.ndarray | None = None,
    name: str = "pixels.zarr",
) -> ReflectanceField:
    """A one-view pixel field (camera straight above) holding ``values`` (T, P, 3)."""
    t_count, p_count, _ = values.shape
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, p_count, 1)
    writer = FieldStoreWriter(
        tmp / name,
        points=None,
        normals=normals,
        light_directions=lights,
        cameras=[camera],
        image_shape=(1, p_count),
    )
    for t in range(t_count):
        writer.write_slab(0, t, values[t].astype(np.float32))
    writer.write_visibility(0, np.ones(p_count, dtype=bool))
    writer.finish()
    return ReflectanceField.open(tmp / name)


def test_fits_recover_the_glossy_material(
    glossy: ReflectanceField, glossy_models: SampleModels
) -> None:
    fit = glossy_models.fit("lambert+ggx")
    assert isinstance(fit, ParametricFit)
    ok = fit.fitted
    assert ok.mean() > 0.8  # the bottom of the sphere is seen by no camera
    np.testing.assert_allclose(np.median(fit.rho_d[ok], axis=0), [0.30, 0.40, 0.60], atol=2e-3)
    np.testing.assert_allclose(np.median(fit.f0[ok], axis=0), [0.25, 0.25, 0.25], atol=2e-3)
    assert np.median(fit.alpha[ok]) == pytest.approx(0.2, abs=2e-3)
    # Sample by sample, not only the median: where some observation sees the lobe near its
    # peak it is identified and recovered; elsewhere (samples seen by few cameras at grazing
    # angles) the fit leaves the lobe out rather than guess it from its far tail.
    identified = ok & peak_seen(glossy, 0.2)
    assert identified.mean() > 0.4
    good = (np.abs(fit.alpha - 0.2) < 0.01) & np.all(np.abs(fit.f0 - 0.25) < 0.01, axis=1)
    assert good[identified].mean() > 0.97
    assert fit.lit[ok].min() == 1.0  # a convex object casts no shadow on itself


def test_fits_recover_the_diffuse_albedo(diffuse_models: SampleModels) -> None:
    fit = diffuse_models.fit("lambert")
    assert isinstance(fit, ParametricFit)
    albedo = fit.rho_d[fit.fitted]
    np.testing.assert_allclose(albedo, np.broadcast_to([0.75, 0.60, 0.45], albedo.shape), atol=1e-4)
    assert fit.loo.relative_rmse < 1e-4


def test_loo_picks_lambert_for_diffuse_and_ggx_for_glossy(
    diffuse_models: SampleModels, glossy_models: SampleModels
) -> None:
    assert choose_model(diffuse_models).chosen == "lambert"
    choice = choose_model(glossy_models)
    assert choice.chosen == "lambert+ggx"
    rows = {row.name: row for row in choice.table}
    assert rows["lambert"].loo_relative_rmse > 0.2
    assert rows["lambert+ggx"].loo_relative_rmse < 0.01
    assert "| lambert+ggx | 7 |" in format_loo_table(choice.table)
    per_sample = choose_model(glossy_models, per_sample=True)
    assert per_sample.per_sample is not None
    assert per_sample.per_sample.shape == (glossy_models.sample_count,)
    assert rows["lambert+ggx"].chosen_share == 1.0


def test_the_models_beat_interpolation_on_held_out_lights(
    glossy: ReflectanceField, glossy_models: SampleModels
) -> None:
    interpolated = interpolation_loo(glossy, "barycentric").relative_rmse
    assert glossy_models.fit("lambert+ggx").loo.relative_rmse < 0.1 * interpolated


def test_parametric_loo_is_an_exact_refit_without_the_light(tmp_path: Path) -> None:
    # Lambertian pixels with known normals, plus noise: the LOO error must equal refitting
    # rho_d without each light and predicting it.
    rng = np.random.default_rng(3)
    lights = hemisphere_layout(20)
    normals = np.array([[0.0, 0.0, 1.0], [0.3, 0.1, 0.95], [-0.2, 0.25, 0.9]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    cosines = np.maximum(lights @ normals.T, 0.0)  # (T, P)
    albedo = np.array([[0.6, 0.5, 0.4], [0.2, 0.3, 0.4], [0.9, 0.8, 0.1]])
    values = cosines[:, :, None] * albedo[None] / np.pi + rng.normal(0, 0.002, (20, 3, 3))
    values = np.maximum(values, 0.0)  # radiance stays non-negative
    field = _pixel_field(tmp_path, values, lights, normals.astype(np.float32))
    # A tiny shadow ratio: the noise must not mark grazing lights as shadowed here.
    models = fit_sample_models(field, models=["lambert"], refine_normals=False, shadow_ratio=1e-6)
    fit = models.fit("lambert")
    assert isinstance(fit, ParametricFit)
    assert fit.lit.min() == 1.0
    design = cosines / np.pi
    expected = np.zeros(3)
    for t in range(20):
        keep = np.arange(20) != t
        for p in range(3):
            rows = keep & (cosines[:, p] > 0)
            a, b = design[rows, p], values[rows, p].astype(np.float32).astype(np.float64)
            rho = np.maximum(a @ b / (a @ a), 0.0)
            predicted = rho * design[t, p]
            expected[p] += ((predicted - values[t, p].astype(np.float32)) ** 2).sum()
    np.testing.assert_allclose(fit.loo.squared_error, expected, rtol=1e-5)


def test_basis_loo_is_the_hat_matrix_closed_form(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    lights = hemisphere_layout(24)
    values = rng.uniform(0.1, 1.0, size=(24, 2, 3))
    field = _pixel_field(tmp_path, values, lights)
    models = fit_sample_models(field, models=["ptm", "hsh3"])
    for name in ("ptm", "hsh3"):
        fit = models.fit(name)
        assert isinstance(fit, BasisFit)
        camera_lights = lights @ models.camera_frame.T
        design = evaluate_basis(name, camera_lights)
        expected = np.zeros(2)
        for t in range(24):
            keep = np.arange(24) != t
            for p in range(2):
                coefficients, *_ = np.linalg.lstsq(design[keep], values[keep, p], rcond=None)
                expected[p] += ((design[t] @ coefficients - values[t, p]) ** 2).sum()
        np.testing.assert_allclose(fit.loo.squared_error, expected, rtol=1e-4)


def test_a_basis_reproduces_data_it_can_represent(tmp_path: Path) -> None:
    lights = hemisphere_layout(30)
    frame_field = _pixel_field(tmp_path, np.ones((30, 1, 3)), lights, name="frame.zarr")
    frame = fit_sample_models(frame_field, models=["hsh2"]).camera_frame
    design = evaluate_basis("hsh2", lights @ frame.T)
    coefficients = np.array([[1.0, 0.5, 0.2], [0.1, -0.2, 0.3], [0.0, 0.1, 0.0], [0.4, 0.3, 0.2]])
    values = (design @ coefficients)[:, None, :]
    fit = fit_sample_models(_pixel_field(tmp_path, values, lights), models=["hsh2"]).fit("hsh2")
    assert isinstance(fit, BasisFit)
    np.testing.assert_allclose(fit.coefficients[0], coefficients, atol=1e-5)
    assert fit.loo.relative_rmse < 1e-5


def test_hemispherical_harmonics_are_orthonormal_over_the_hemisphere() -> None:
    rows = 200
    inclination = (np.arange(rows) + 0.5) * 90.0 / rows
    azimuth = (np.arange(2 * rows) + 0.5) * 360.0 / (2 * rows)
    directions = direction_from_angles_deg(azimuth[None, :], inclination[:, None]).reshape(-1, 3)
    weight = (
        np.repeat(np.sin(np.radians(inclination)), 2 * rows) * (np.pi / 2 / rows) * (np.pi / rows)
    )
    basis = evaluate_basis("hsh3", directions)
    gram = basis.T @ (basis * weight[:, None])
    np.testing.assert_allclose(gram, np.eye(9), atol=2e-3)


def test_photometric_stereo_recovers_lambertian_normals() -> None:
    rng = np.random.default_rng(5)
    lights = hemisphere_layout(40)
    normals = rng.normal(size=(50, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    values = np.maximum(lights @ normals.T, 0.0)[:, :, None] * np.array([0.5, 0.4, 0.3]) / np.pi
    found = photometric_stereo(values, lights, np.array([0.0, 0.0, 1.0]))
    assert np.degrees(np.arccos(np.clip(np.sum(found * normals, axis=1), -1, 1))).max() < 0.1


def test_refined_normals_fit_a_glossy_pixel_field(tmp_path: Path) -> None:
    # A lambert+ggx pixel field whose normals must be found: photometric stereo is thrown off
    # by the highlights, refinement recovers the material.

    lights = hemisphere_layout(60)
    normal = np.array([0.25, -0.15, 1.0]) / np.linalg.norm([0.25, -0.15, 1.0])
    view = np.array([0.0, 0.0, 1.0])
    f = brdf(normal, lights, view, [0.3, 0.4, 0.5], [0.2, 0.2, 0.2], 0.25)
    values = (f * np.maximum(lights @ normal, 0.0)[:, None])[:, None, :]
    field = _pixel_field(tmp_path, values, lights)
    fit = fit_sample_models(field, models=["lambert+ggx"]).fit("lambert+ggx")
    assert isinstance(fit, ParametricFit) and fit.normals_fitted
    assert np.degrees(np.arccos(min(float(fit.normals[0] @ normal), 1.0))) < 0.5
    assert float(fit.alpha[0]) == pytest.approx(0.25, abs=0.01)
    np.testing.assert_allclose(fit.f0[0], [0.2, 0.2, 0.2], atol=0.01)
    np.testing.assert_allclose(fit.rho_d[0], [0.3, 0.4, 0.5], atol=0.01)


def test_one_view_fits_no_lobe_narrower_than_its_lights_resolve() -> None:
    lights = hemisphere_layout(49, "fibonacci")
    low, high = lobe_alpha_range(lights, one_view=True)
    assert low == pytest.approx(LOBE_SPACING * np.radians(mean_spacing_deg(lights)))
    assert 0.1 < low < 0.2 and high == ALPHA_RANGE[1]
    # Half the lights: the spacing grows, and so does the narrowest lobe.
    assert lobe_alpha_range(hemisphere_layout(25, "fibonacci"), one_view=True)[0] > 1.3 * low
    # Points are seen from several cameras: their half vectors are denser than the lights.
    assert lobe_alpha_range(lights, one_view=False) == ALPHA_RANGE
    # A handful of lights still leaves a range to search.
    sparse = lobe_alpha_range(hemisphere_layout(3), one_view=True)
    assert sparse[0] == pytest.approx(0.5 * sparse[1])


def _glossy_pixels(lights: np.ndarray, alpha: float, rng: np.random.Generator) -> np.ndarray:
    """Values (T, 300, 3) of normals within 35 degrees of the overhead view, 2 % noise."""
    tilt, azimuth = np.radians(rng.uniform(0.0, 35.0, 300)), rng.uniform(0.0, 2 * np.pi, 300)
    normals = np.stack(
        [np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)], axis=1
    )
    view = np.array([0.0, 0.0, 1.0])
    values = np.stack(
        [
            brdf(n, lights, view, [0.3, 0.1, 0.05], [0.04] * 3, alpha)
            * np.maximum(lights @ n, 0.0)[:, None]
            for n in normals
        ],
        axis=1,
    )
    return values * rng.normal(1.0, 0.02, values.shape)


def test_held_out_lights_of_a_noisy_glossy_capture_are_not_lost_to_needle_lobes(
    tmp_path: Path,
) -> None:
    # 2 % noise and every other light of a 49-light dome: searched down to ALPHA_RANGE, some
    # pixels settle on a needle that shines where a light was held out.
    lights = hemisphere_layout(49, "fibonacci")
    values = _glossy_pixels(lights, 0.2, np.random.default_rng(1))
    fit, test = np.arange(0, 49, 2), np.arange(1, 49, 2)
    field = _pixel_field(tmp_path, values[fit], lights[fit])
    view = np.array([0.0, 0.0, 1.0])
    errors = {}
    for label, alpha_range in (("resolved", None), ("widest", ALPHA_RANGE)):
        model = fit_sample_models(field, models=["lambert+ggx"], alpha_range=alpha_range)
        lobe = model.fit("lambert+ggx")
        assert isinstance(lobe, ParametricFit)
        predicted = np.stack(
            [
                brdf(n, lights[test], view, rho, f0, float(a))
                * np.maximum(lights[test] @ n, 0.0)[:, None]
                for n, rho, f0, a in zip(lobe.normals, lobe.rho_d, lobe.f0, lobe.alpha, strict=True)
            ],
            axis=1,
        )
        errors[label] = np.sqrt(np.sum((predicted - values[test]) ** 2) / np.sum(values[test] ** 2))
        if alpha_range is None:
            assert lobe.alpha.min() >= lobe_alpha_range(lights[fit], one_view=True)[0] - 1e-9
    assert errors["resolved"] < 0.12
    assert errors["resolved"] < 0.5 * errors["widest"]


def test_shadows_are_marked_where_the_simulator_cast_them(torus: ReflectanceField) -> None:
    models = fit_sample_models(torus, models=["lambert+ggx"])
    fit = models.fit("lambert+ggx")
    assert isinstance(fit, ParametricFit)
    samples = build_scene("textured-torus", torus.shape[2])
    shadowed = np.stack(
        [~light_visibility(samples, DirectionalLight(tuple(d))) for d in torus.light_directions],
        axis=1,
    ) & (torus.normals @ torus.light_directions.T > 0)
    seen = fit.fitted
    assert shadowed[seen].mean() > 0.02  # the test needs shadows
    agreement = ((fit.lit < 0.5) == shadowed)[seen].mean()
    assert agreement > 0.995
    # The material under the shadows is still recovered.
    assert np.median(fit.alpha[seen]) == pytest.approx(0.35, abs=0.01)
    assert np.median(fit.f0[seen]) == pytest.approx(0.04, abs=0.002)


def test_geometric_shadow_marks_match_the_simulator(torus: ReflectanceField) -> None:
    assert torus.points is not None and torus.normals is not None
    samples = build_scene("textured-torus", torus.shape[2])
    directions = np.array([[0.3, 0.2, -0.93], [0.9, 0.0, 0.44], [0.0, 0.0, 1.0]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    marks = geometric_shadow_marks(torus.points, torus.normals, directions, samples.spacing)
    for g, direction in enumerate(directions):
        truth = light_visibility(samples, DirectionalLight(tuple(direction)))
        facing = torus.normals @ direction > 0
        assert (marks[facing, g].astype(bool) == truth[facing]).mean() > 0.99
        assert marks[~facing, g].min() == 1.0  # behind the surface: the cosine's business


def test_geometry_completes_the_marks_and_predicts_them(torus: ReflectanceField) -> None:
    assert torus.normals is not None
    models = fit_sample_models(torus, models=["lambert+ggx"])
    errors = shadow_mark_errors(models, torus.normals)
    assert errors["geometry"] < errors["interpolated"]
    completed = with_geometric_visibility(models, torus.normals, count=64)
    t_count = torus.shape[1]
    assert completed.mark_directions is not None
    extra = completed.mark_directions[t_count:]
    assert len(extra) > 20 and np.all(extra[:, 2] < np.cos(np.radians(60.0)))
    fit = completed.fit("lambert+ggx")
    assert isinstance(fit, ParametricFit)
    assert fit.lit.shape == (torus.shape[2], len(completed.mark_directions))
    with pytest.raises(InputError, match="completed already"):
        with_geometric_visibility(completed, torus.normals)


def test_leave_one_out_weights_never_use_the_light_itself() -> None:
    lights = hemisphere_layout(12)
    indices, weights = leave_one_out_weights(lights)
    for t in range(12):
        assert t not in indices[t][weights[t] > 0]
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)


def test_interpolation_loo_of_a_constant_field_is_zero(tmp_path: Path) -> None:
    lights = hemisphere_layout(10)
    field = _pixel_field(tmp_path, np.full((10, 4, 3), 0.5), lights)
    for method in ("nearest", "barycentric", "paper"):
        assert interpolation_loo(field, method).relative_rmse < 1e-7


def test_bad_requests_are_refused(glossy: ReflectanceField, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="'phong'"):
        fit_sample_models(glossy, models=["phong"])
    with pytest.raises(InputError, match="'ptm' is a basis"):
        fit_sample_models(glossy, models=["ptm"])
    with pytest.raises(InputError, match=r"alpha range .*\(0.5, 0.1\)"):
        fit_sample_models(glossy, alpha_range=(0.5, 0.1))
    with pytest.raises(InputError, match="shadow ratio"):
        fit_sample_models(glossy, shadow_ratio=1.5)
    few = _pixel_field(tmp_path, np.ones((5, 2, 3)), hemisphere_layout(5))
    with pytest.raises(InputError, match="'hsh3' has 9 terms"):
        fit_sample_models(few, models=["hsh3"])
    with pytest.raises(InputError, match="unknown basis model 'sh'"):
        evaluate_basis("sh", np.zeros((1, 3)))


def test_a_point_field_without_normals_is_refused(tmp_path: Path) -> None:
    # A store claiming points but holding none is refused on opening already; the fit names
    # the missing normals if a caller builds such a field by hand.
    field = _field(tmp_path, "diffuse-sphere", 4, 2, 100)
    broken = replace(field, normals=None)
    with pytest.raises(DatasetError, match="normals"):
        fit_sample_models(broken)


def test_unfitted_model_names_are_refused(glossy_models: SampleModels) -> None:
    with pytest.raises(InputError, match="'hsh2' was not fitted"):
        choose_model(glossy_models, candidates=["hsh2"])


def test_leave_one_out_barycentric_rebuilds_the_triangulation_without_the_light() -> None:
    lights = hemisphere_layout(20, "fibonacci")
    values = lights[:, 2:3] ** 2 + 0.1 * lights[:, :1]  # smooth in the light direction
    held_out = leave_one_out_barycentric(lights, values)
    for j in (0, 7, 19):
        others = np.delete(np.arange(20), j)
        weights = interpolation_weights(lights[others], lights[j : j + 1], "barycentric",
                                        policy="clamp")  # fmt: skip
        np.testing.assert_allclose(held_out[j], weights.apply(values[others])[0])
    assert not np.allclose(held_out, values)  # the light itself never helps predict it
