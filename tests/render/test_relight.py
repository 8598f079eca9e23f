from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.light_set import LightSet
from processing.interpolation import interpolation_weights
from processing.panorama import panorama_from_array
from render.engines.interpolated import Relighter, RelightSettings
from render.engines.paper_sums import blend_cameras, relight, relight_pixels_literal
from render.light_weights import (
    pixel_light_weights,
    projection_light_weights,
    sampled_light_weights,
)
from sim.field import field_cameras, simulate_field


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("glossy") / "f.zarr"
    simulate_field(
        path, "glossy-sphere", lights=12, cameras=field_cameras(8, width=64, height=64), points=3000
    )
    return ReflectanceField.open(path)


@pytest.fixture(scope="module")
def torus(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("torus") / "f.zarr"
    simulate_field(
        path,
        "textured-torus",
        lights=6,
        cameras=field_cameras(3, width=64, height=64),
        points=4000,
        dtype="float16",
    )
    return ReflectanceField.open(path)


def _one_light(
    direction: np.ndarray, rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
) -> LightSet:
    return LightSet(
        directions=direction[None, :],
        rgb=np.array([rgb]),
        solid_angle_sr=np.array([4 * np.pi]),
        labels=np.zeros((2, 4), dtype=np.int32),
    )


def _panorama(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    image = rng.random((16, 32, 3)).astype(np.float32)
    image[3:5, 10:12] += 20.0  # a small sun
    return image


@pytest.mark.parametrize("store", ["glossy", "torus"])
def test_a_measured_light_at_a_measured_camera_reproduces_the_slab(
    store: str, request: pytest.FixtureRequest
) -> None:
    field: ReflectanceField = request.getfixturevalue(store)
    s, t = 1, 4
    lighting = sampled_light_weights(
        _one_light(field.light_directions[t]), field.light_directions, "nearest"
    )
    blend = blend_cameras(field, field.cameras[s], "paper", n=1)
    radiance = relight(field, lighting, blend)
    seen = field.visibility[s] & ~blend.holes
    np.testing.assert_allclose(
        radiance[seen], field.camera_slab(s)[t][seen].astype(np.float32), rtol=1e-6
    )


def test_camera_weights_sum_to_one_and_holes_are_reported(torus: ReflectanceField) -> None:
    between = PinholeCamera(200.0, 50.0, width=64, height=64)
    blend = blend_cameras(torus, between, "paper", n=2)
    sums = blend.weights.sum(axis=0)
    assert np.all((np.abs(sums - 1) < 1e-5) | (sums == 0))
    assert blend.holes.any()  # the torus hides some samples from the two chosen cameras
    assert np.all(sums[blend.holes] == 0)
    lighting = projection_light_weights(_panorama(0), torus.light_directions)
    assert np.all(relight(torus, lighting, blend)[blend.holes] == 0)


@pytest.mark.parametrize("method", ["paper", "barycentric"])
def test_camera_blend_keeps_the_cameras_that_see_each_sample(
    torus: ReflectanceField, method: str
) -> None:
    # The rule, in numpy: the interpolation's cameras that see a sample, renormalised; else
    # the nearest camera (by angle from where the ray to the eye meets the cameras' sphere)
    # that sees it; else a hole.
    between = PinholeCamera(200.0, 50.0, width=64, height=64)
    blend = blend_cameras(torus, between, method, n=2)
    points = torus.points.astype(np.float64)
    ray = between.position - points
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    along = np.einsum("pk,pk->p", points, ray)
    radius = np.mean([c.distance for c in torus.cameras])
    reach = along**2 - np.einsum("pk,pk->p", points, points) + radius**2
    crossing = points + (np.sqrt(np.maximum(reach, 0.0)) - along)[:, None] * ray
    towards = crossing / np.linalg.norm(crossing, axis=1, keepdims=True)
    chosen = interpolation_weights(torus.camera_directions, towards, method, m=2)
    expected = np.zeros((len(torus.cameras), len(points)))
    for p in range(len(points)):
        seen = torus.visibility[chosen.indices[p], p]
        weights = chosen.weights[p] * seen
        if weights.sum() > 0:
            np.add.at(expected[:, p], chosen.indices[p], weights / weights.sum())
        elif torus.visibility[:, p].any():
            order = np.argsort(-(torus.camera_directions @ towards[p]))
            expected[order[torus.visibility[order, p]][0], p] = 1.0
    np.testing.assert_array_equal(blend.holes, ~torus.visibility.any(axis=0))
    np.testing.assert_array_equal(blend.cameras, np.flatnonzero(expected.any(axis=1)))
    np.testing.assert_allclose(blend.weights, expected[blend.cameras], atol=1e-6)


def test_light_weights_carry_all_the_light(glossy: ReflectanceField) -> None:
    rgb = _panorama(1)
    total = projection_light_weights(rgb, glossy.light_directions).rgb.sum(axis=(0, 1))
    unclipped = pixel_light_weights(rgb, glossy.light_directions, None, grid_height=None).rgb.sum(
        axis=(0, 1)
    )
    np.testing.assert_allclose(unclipped, total, rtol=1e-5)


@pytest.mark.parametrize("scheme", ["pixels", "projection"])
def test_relighting_is_linear_in_the_light(glossy: ReflectanceField, scheme: str) -> None:
    camera = PinholeCamera(30.0, 40.0, width=64, height=64)
    images = []
    for rgb in (_panorama(2), _panorama(3), _panorama(2) + _panorama(3)):
        relighter = Relighter(glossy, RelightSettings(scheme=scheme, grid_height=None))
        relighter.set_lighting(panorama_from_array(rgb, source="test"))
        relighter.set_view(camera)
        images.append(relighter.render().rgb)
    np.testing.assert_allclose(images[0] + images[1], images[2], rtol=1e-4, atol=1e-6)


def test_the_two_forms_of_eq2_agree(glossy: ReflectanceField) -> None:
    rgb = _panorama(4)
    blend = blend_cameras(glossy, PinholeCamera(100.0, 35.0, width=64, height=64), "paper", n=3)
    literal = relight_pixels_literal(glossy, rgb, blend, "paper")
    exact = pixel_light_weights(
        rgb, glossy.light_directions, glossy.normals, "paper", normal_bins=None, grid_height=None
    )
    rearranged = relight(glossy, exact, blend)
    assert literal.max() > 0
    np.testing.assert_allclose(rearranged, literal, rtol=1e-4, atol=1e-7)
    binned = relight(
        glossy,
        pixel_light_weights(
            rgb,
            glossy.light_directions,
            glossy.normals,
            "paper",
            normal_bins=4096,
            grid_height=None,
        ),
        blend,
    )
    error = np.sqrt(np.mean((binned - literal) ** 2) / np.mean(literal**2))
    assert error < 0.01


def test_pixel_fields_relight_their_one_view(tmp_path: Path) -> None:
    lights = hemisphere_layout(5)
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, width=6, height=4)
    store = FieldStoreWriter(
        tmp_path / "rti.zarr", points=None, normals=None, light_directions=lights,
        cameras=[camera], image_shape=(4, 6),
    )  # fmt: skip
    values = np.random.default_rng(5).random((5, 24, 3)).astype(np.float32)
    for t in range(5):
        store.write_slab(0, t, values[t])
    store.write_visibility(0, np.ones(24, dtype=bool))
    store.finish()
    field = ReflectanceField.open(tmp_path / "rti.zarr")
    relighter = Relighter(field, RelightSettings(scheme="projection"))
    relighter.set_lighting(panorama_from_array(_panorama(6), source="test"))
    relighter.set_view(camera)
    image = relighter.render()
    weights = projection_light_weights(_panorama(6), lights).rgb[0]
    expected = np.einsum("tc,tpc->pc", weights, values).reshape(4, 6, 3)
    np.testing.assert_allclose(image.rgb, expected, rtol=1e-5)
    assert image.coverage.all()
    with pytest.raises(InputError, match="pixels of one view"):
        relighter.set_view(PinholeCamera(0.0, 30.0))


def test_render_needs_a_lighting_and_a_view(glossy: ReflectanceField) -> None:
    with pytest.raises(InputError, match="set a lighting and a view"):
        Relighter(glossy).render()


def test_paper_configuration_relights_the_glossy_sphere(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    from processing.panorama import read_panorama

    relighter = Relighter(glossy, RelightSettings.paper_configuration(k=32))
    relighter.set_lighting(read_panorama(courtyard_path))
    relighter.set_view(glossy.cameras[2])
    image = relighter.render()
    assert image.coverage.mean() > 0.2 and image.rgb[image.coverage].min() >= 0
    assert image.rgb[image.coverage].mean() > 0
    assert relighter.lights is not None and relighter.lights.k == 32


def test_new_view_and_new_lighting_paths_agree(glossy: ReflectanceField) -> None:
    first, second = (panorama_from_array(_panorama(s), source="test") for s in (7, 8))
    camera = PinholeCamera(75.0, 45.0, width=64, height=64)
    relighter = Relighter(glossy, RelightSettings(scheme="projection"))
    relighter.set_lighting(first)
    relighter.set_view(camera)
    relighter.render()  # a new view: per-camera relit samples
    relighter.set_lighting(second)
    by_view_field = relighter.render().radiance  # a new lighting: the view's blended field
    fresh = Relighter(glossy, RelightSettings(scheme="projection"))
    fresh.set_lighting(second)
    fresh.set_view(camera)
    np.testing.assert_allclose(by_view_field, fresh.render().radiance, rtol=1e-5, atol=1e-7)
