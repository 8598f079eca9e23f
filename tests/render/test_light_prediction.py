from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from core.camera_model import PinholeCamera, camera_to_rig
from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from processing.learned_rti_training import TrainingSettings
from processing.relief_shadows import despeckled, relief_visibility
from processing.sample_models import evaluate_basis
from render import prediction_methods
from render.learned_predictor import LearnedPredictor
from render.light_prediction import PREDICTORS, make_predictor
from render.prediction_methods import BOUND, BOUND_SPACING_DEG, bound_factor
from render.rti_fits import RBF_SIGMAS, choose_rbf_sigma, rbf_weights
from sim.field import field_cameras, simulate_field
from tests.call_counting import counting_calls

HEIGHT, WIDTH = 4, 6
#: A few steps of the learned model: these tests check its plumbing, not its accuracy.
BRIEF = TrainingSettings(steps=10, batch=8, lights_per_step=4)
#: Enough passes for a 40 x 40 pixel field to be learned (seconds on 2 cores).
SHORT = TrainingSettings(epochs=100, threads=2)


def _pixel_field(
    path: Path, values_of: object, lights: int = 40, shape: tuple[int, int] = (HEIGHT, WIDTH)
) -> ReflectanceField:
    """A field of pixels whose radiance is ``values_of(camera-frame directions)`` (T, P, 3)."""
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, shape[1], shape[0])
    directions = hemisphere_layout(lights, "fibonacci")
    values = values_of(directions)  # type: ignore[operator]
    writer = FieldStoreWriter(
        path, points=None, normals=None, light_directions=camera_to_rig(directions, camera),
        cameras=[camera], image_shape=shape,
    )  # fmt: skip
    for t in range(lights):
        writer.write_slab(0, t, values[t].astype(np.float32))
    writer.write_visibility(0, np.ones(shape[0] * shape[1], dtype=bool))
    writer.finish()
    return ReflectanceField.open(path)


def _polynomial(name: str, seed: int = 0) -> object:
    coefficients = np.random.default_rng(seed).uniform(0.1, 0.3, (HEIGHT * WIDTH, 9, 3))

    def values(directions: np.ndarray) -> np.ndarray:
        design = evaluate_basis(name, directions)
        return np.einsum("tb,pbc->tpc", design, coefficients[:, : design.shape[1]])

    return values


@pytest.mark.parametrize("name", ["ptm", "hsh3"])
def test_a_basis_predicts_its_own_kind_exactly(tmp_path: Path, name: str) -> None:
    field = _pixel_field(tmp_path / "f.zarr", _polynomial(name))
    new = hemisphere_layout(7, "grid")
    truth = _polynomial(name)(new)  # type: ignore[operator]
    predicted = make_predictor(field, name).predict(0, camera_to_rig(new, field.cameras[0]))
    # Exact up to the bound (values above 1.25 x the brightest measured are clipped).
    np.testing.assert_allclose(predicted, np.clip(truth, 0, None), rtol=1e-4, atol=1e-5)


def test_interpolators_reproduce_the_measured_lights(tmp_path: Path) -> None:
    field = _pixel_field(tmp_path / "f.zarr", _polynomial("ptm", seed=1))
    slab = field.camera_slab(0)
    # Interpolators and model + residual are exact at the measured lights (the latter up to
    # the bound: these random polynomials dip below zero, which light cannot); a least-squares
    # fit of the data's own kind is exact too.
    for name, expected in (("nearest", slab), ("barycentric", slab), ("ptm", np.maximum(slab, 0)),
                           ("lambert+residual", np.maximum(slab, 0)),
                           ("adaptive", np.maximum(slab, 0)),
                           ("learned+residual", np.maximum(slab, 0))):  # fmt: skip
        predictor = make_predictor(field, name, learned=BRIEF)
        predicted = predictor.predict(0, field.light_directions)
        np.testing.assert_allclose(predicted, expected, atol=1e-5, err_msg=name)


def test_rbf_weights_are_the_rti_tools_normalised_gaussian() -> None:
    measured = hemisphere_layout(30, "fibonacci")
    queries = hemisphere_layout(5, "grid")
    weights = rbf_weights(measured, queries, 0.2)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)
    assert ((weights == 0) | (weights >= 1e-3 * 0.5)).all()  # tiny weights dropped
    nearest = np.argmax(queries @ measured.T, axis=1)
    sharp = rbf_weights(measured, queries, 1e-3)  # sigma -> 0: the nearest light alone
    np.testing.assert_allclose(sharp[np.arange(5), nearest], 1.0)
    with pytest.raises(InputError, match="sigma must be positive"):
        rbf_weights(measured, queries, 0.0)


def test_the_rbf_width_follows_the_data() -> None:
    lights = hemisphere_layout(60, "fibonacci")
    # A smooth function of the light is predicted best from its neighbours; values drawn
    # independently per light, best by the mean of all the others (the widest kernel).
    smooth = lights[:, 2:3] * np.ones((1, 50))
    rough = np.random.default_rng(0).random((60, 50))
    assert choose_rbf_sigma(lights, smooth) < RBF_SIGMAS[-1] == choose_rbf_sigma(lights, rough)


def test_predictions_are_bounded_by_the_data(tmp_path: Path) -> None:
    # A lobe-like field: the linear bases overshoot it between lights and below zero.
    def spiky(directions: np.ndarray) -> np.ndarray:
        lobe = np.exp(-np.sum((directions - [0.3, 0.2, 0.93]) ** 2, axis=1) / 0.02)
        return np.repeat(lobe[:, None, None], HEIGHT * WIDTH, axis=1) * np.ones(3)

    field = _pixel_field(tmp_path / "f.zarr", spiky)
    peak = field.camera_slab(0).max()
    queries = camera_to_rig(hemisphere_layout(50, "grid"), field.cameras[0])
    for name in ("ptm", "hsh3", "ptm-8bit", "lambert+ggx", "lambert+ggx+residual"):
        predicted = make_predictor(field, name).predict(0, queries)
        limit = bound_factor(field.light_directions) * peak
        assert predicted.min() >= 0 and predicted.max() <= limit * (1 + 1e-6), name


def test_the_models_predict_a_simulated_field_of_their_own_kind(tmp_path: Path) -> None:
    path = tmp_path / "diffuse.zarr"
    cameras = field_cameras(4, width=24, height=24)
    simulate_field(path, "diffuse-sphere", lights=24, cameras=cameras, points=400)
    test_path = tmp_path / "diffuse-test.zarr"
    field = ReflectanceField.open(path)
    new = hemisphere_layout(5, "fibonacci")  # lights the field did not measure
    simulate_field(test_path, "diffuse-sphere", lights=new, cameras=cameras, points=400)
    test = ReflectanceField.open(test_path)
    for s in range(4):
        seen = field.visibility[s]
        truth = test.camera_slab(s)[:, seen]
        for name, tolerance in (("lambert", 0.05), ("barycentric", 0.3)):
            predicted = make_predictor(field, name).predict(s, new)[:, seen]
            error = np.sqrt(np.sum((predicted - truth) ** 2) / np.sum(truth**2))
            assert error < tolerance, (name, s, error)


def test_every_method_has_a_predictor_and_unknown_ones_are_refused(tmp_path: Path) -> None:
    field = _pixel_field(tmp_path / "f.zarr", _polynomial("hsh3", seed=2))
    direction = field.light_directions[:1]
    for name in PREDICTORS:
        predictor = make_predictor(field, name, learned=BRIEF)
        assert predictor.name == name
        assert predictor.predict(0, direction).shape == (1, HEIGHT * WIDTH, 3)
    with pytest.raises(InputError, match="unknown method 'splines'"):
        make_predictor(field, "splines")


def _block_field(
    path: Path, block: slice, height: float
) -> tuple[ReflectanceField, Callable[[np.ndarray], np.ndarray]]:
    """A 40 x 40 matte base with a square ``block`` of ``height`` pixels under 49 lights.

    Returns the field and its radiance (T, P, 3) of camera-frame directions (T, 3).
    """
    size = 40
    heights = np.zeros((size, size))
    heights[block, block] = height
    visible = np.ones((size, size), dtype=bool)

    def values(directions: np.ndarray) -> np.ndarray:
        lit = relief_visibility(heights, directions, visible, spread=0).T
        shade = 0.6 * np.clip(directions[:, 2], 0.0, None)[:, None] * lit
        return np.repeat(shade[:, :, None], 3, axis=2)

    return _pixel_field(path, values, lights=49, shape=(size, size)), values


def _block_errors(
    path: Path,
    block: slice,
    height: float,
    elevation_deg: float,
    names: tuple[str, ...] = ("relief", "lambert+ggx+residual"),
) -> dict[str, float]:
    """Mean squared errors of the methods ``names`` on :func:`_block_field`'s block.

    Predicted at nine azimuths at ``elevation_deg``.
    """
    field, values = _block_field(path, block, height)
    elevation = np.radians(elevation_deg)
    azimuths = np.radians(np.arange(10.0, 360.0, 40.0))
    new = np.stack(
        [np.cos(elevation) * np.cos(azimuths), np.cos(elevation) * np.sin(azimuths),
         np.full_like(azimuths, np.sin(elevation))], axis=1,
    )  # fmt: skip
    truth = values(new)
    rig = camera_to_rig(new, field.cameras[0])
    return {
        name: float(
            np.mean((make_predictor(field, name, learned=SHORT).predict(0, rig) - truth) ** 2)
        )
        for name in names
    }


def test_a_fields_relief_is_fitted_once_for_every_rung_that_uses_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A choice's fold makes the relief rung and the network told its shadows apart.
    fitted = counting_calls(monkeypatch, prediction_methods, "relief_heights")
    field, _ = _block_field(tmp_path / "f.zarr", slice(14, 26), 5.0)
    relief = make_predictor(field, "relief")
    learned = make_predictor(field, "learned+relief", learned=BRIEF)
    assert isinstance(relief, prediction_methods._Relief)
    assert isinstance(learned, LearnedPredictor) and learned.shadows is not None
    assert np.array_equal(relief.heights(0), learned.shadows.heights(0))
    assert len(fitted) == 1
    # A fit the caller gives may not be the field's own: its relief is its own too.
    models = relief.residual.base.models  # type: ignore[attr-defined]
    given = make_predictor(field, "relief", models=models)
    assert isinstance(given, prediction_methods._Relief)
    given.heights(0)
    assert len(fitted) == 2


def test_the_relief_rung_moves_cast_shadows_between_the_measured_lights(tmp_path: Path) -> None:
    # At low lights between the measured ones the shadow has moved, and interpolated marks
    # give two half shadows.
    error = _block_errors(tmp_path / "f.zarr", slice(14, 26), 5.0, 15.0)
    assert error["relief"] < 0.25 * error["lambert+ggx+residual"]


def test_the_relief_rung_slides_shadows_it_does_not_cast_between_the_measured_lights(
    tmp_path: Path,
) -> None:
    # At 45 degrees a shadow moves less than its occluder is tall between the lights, and the
    # relief does not decide it: the marks' edges are blended as distances, not faded.
    error = _block_errors(tmp_path / "f.zarr", slice(15, 25), 12.0, 45.0)
    assert error["relief"] < 0.75 * error["lambert+ggx+residual"], error


def test_the_learned_rung_told_the_reliefs_shadows_moves_them_between_the_lights(
    tmp_path: Path,
) -> None:
    # The network alone learns each pixel's shadows at the measured lights only, and its
    # residual blends them as the marks do; told the relief's visibility it learns the pixel
    # lit and in shadow, and the relief says where the shadow falls.
    names = ("learned+residual", "learned+relief+residual")
    error = _block_errors(tmp_path / "f.zarr", slice(14, 26), 5.0, 15.0, names)
    assert error["learned+relief+residual"] < 0.5 * error["learned+residual"], error


def test_despeckled_fills_a_lone_lit_pixel_and_keeps_the_shadow_edge() -> None:
    shape = (8, 10)
    light = np.ones(shape, dtype=np.float32)
    light[:, :5] = 0.0  # the relief's shadow, its edge between columns 4 and 5
    light[3, 2] = 0.5  # a pixel the relief is not trusted on: interpolated marks
    light[6, 8] = 0.5  # a half mark away from the relief's shadows keeps its detail
    near = light == 0.0
    out = despeckled(light.reshape(-1, 1), near.reshape(-1, 1), shape).reshape(shape)
    assert np.all(out[:, :5] == 0.0)
    assert out[6, 8] == 0.5
    assert np.all(out[:, 5:][light[:, 5:] == 1.0] == 1.0)


def test_the_bound_loosens_as_the_lights_grow_sparse() -> None:
    dense = hemisphere_layout(400, "fibonacci")  # about 7 degrees apart
    sparse = hemisphere_layout(8, "fibonacci")  # about 50 degrees apart
    assert bound_factor(dense) == BOUND
    spacing = 50.0
    assert bound_factor(sparse) == pytest.approx(
        BOUND * (spacing / BOUND_SPACING_DEG) ** 2, rel=0.3
    )
