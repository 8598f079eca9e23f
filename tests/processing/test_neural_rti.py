from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from core.directions import hemisphere_layout
from core.errors import InputError
from processing.neural_rti import CODE_SIZE, HIDDEN, NeuralRTI
from processing.neural_rti_fit import NeuralSettings, fit_codes, fit_neural_rti, tune_decoder

torch = pytest.importorskip("torch", reason="the learned extra (PyTorch) is not installed")

#: Steps, not seconds, end these fits (a loaded machine gives the same result, later).
STEPS = NeuralSettings(steps=1500, max_seconds=900.0, threads=1)


def _lambertian(lights: np.ndarray, samples: int = 300, seed: int = 0) -> np.ndarray:
    """(T, N, 3) 8-bit sRGB values of Lambertian pixels with random normals and albedos."""
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(samples, 3)) * [0.4, 0.4, 1.0]
    normals[:, 2] = np.abs(normals[:, 2])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    albedo = rng.uniform(0.2, 0.9, (samples, 3))
    linear = np.clip(lights @ normals.T, 0.0, None)[:, :, None] * albedo[None]
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return np.clip(np.rint(encoded * 255), 0, 255).astype(np.uint8)


def _lights(count: int = 40) -> np.ndarray:
    lights = hemisphere_layout(count * 2, "fibonacci")
    return lights[lights[:, 2] > 0.1][:count]


def _psnr(model: NeuralRTI, levels: np.ndarray, which: np.ndarray) -> float:
    assert model.codes is not None
    shown = np.clip(np.rint(model.decode(model.codes, model.lights[which]) * 255), 0, 255)
    error = np.mean((shown - levels[which]) ** 2)
    return 10 * math.log10(255**2 / error)


def test_the_numpy_decoder_is_the_torch_network_of_openlimes_shape() -> None:
    lights = _lights()
    levels = _lambertian(lights, 30)
    model = fit_neural_rti(levels, lights, dataclasses.replace(STEPS, steps=3))
    (w1, _), (w2, _), (w3, _) = model.decoder
    assert (w1.shape, w2.shape, w3.shape) == ((11, HIDDEN), (HIDDEN, HIDDEN), (HIDDEN, 3))
    network = torch.nn.Sequential(
        torch.nn.Linear(11, HIDDEN), torch.nn.ELU(), torch.nn.Linear(HIDDEN, HIDDEN),
        torch.nn.ELU(), torch.nn.Linear(HIDDEN, 3),
    )  # fmt: skip
    with torch.no_grad():
        linear = [m for m in network if isinstance(m, torch.nn.Linear)]
        for module, (weight, bias) in zip(linear, model.decoder, strict=True):
            module.weight.copy_(torch.from_numpy(weight.T.copy()))
            module.bias.copy_(torch.from_numpy(bias))
    assert model.codes is not None and model.codes.shape == (30, CODE_SIZE)
    rows = np.concatenate(
        [np.repeat(model.codes[None], len(lights), 0), np.repeat(lights[:, None, :2], 30, 1)],
        axis=2,
    ).astype(np.float32)  # (T, N, 11): the code, then the light's x and y
    with torch.no_grad():
        expected = network(torch.from_numpy(rows)).numpy()
    np.testing.assert_allclose(model.decode(model.codes, lights), expected, atol=2e-5)


def test_a_lambertian_object_is_learned_and_generalises_to_held_out_lights() -> None:
    lights = _lights(48)
    levels = _lambertian(lights)
    model = fit_neural_rti(levels, lights, dataclasses.replace(STEPS, holdout=0.15))
    assert 0 < len(model.held) < len(lights) and model.steps == STEPS.steps
    assert _psnr(model, levels, model.trained) > 26.5  # measured 28.8 dB (the mean: 17)
    assert _psnr(model, levels, model.held) > 23.0  # measured 25.4 dB


def test_held_out_lights_do_not_reach_the_codes() -> None:
    lights = _lights()
    levels = _lambertian(lights, 60)
    settings = dataclasses.replace(STEPS, steps=40, holdout=0.2)
    first = fit_neural_rti(levels, lights, settings)
    changed = levels.copy()
    changed[first.held] = 255 - changed[first.held]  # anything at the held-out lights
    second = fit_neural_rti(changed, lights, settings)
    np.testing.assert_array_equal(first.held, second.held)
    assert first.codes is not None and second.codes is not None
    np.testing.assert_allclose(first.codes, second.codes, atol=1e-6)
    # ... but the lights fitted do.
    changed[first.trained[:3]] = 0
    third = fit_neural_rti(changed, lights, settings)
    assert third.codes is not None and np.abs(third.codes - first.codes).max() > 1e-3


def test_an_encoder_codes_pixels_it_was_not_fitted_on() -> None:
    lights = _lights()
    levels = _lambertian(lights, 600)
    settings = dataclasses.replace(STEPS, encoder=True)
    model = fit_neural_rti(levels[:, :300], lights, settings)
    assert model.codes is None and len(model.encoder) == 4
    other = levels[:, 300:]
    codes = model.encode(other)
    shown = np.clip(np.rint(model.decode(codes, lights) * 255), 0, 255)
    psnr = 10 * math.log10(255**2 / np.mean((shown - other) ** 2))
    assert psnr > 25.0  # measured 27.4 dB on pixels never seen (27.5 on those fitted)
    free = fit_neural_rti(levels[:, :20], lights, dataclasses.replace(STEPS, steps=2))
    with pytest.raises(InputError, match="free codes"):
        free.encode(other)


def test_tuning_fits_the_decoder_to_moved_codes() -> None:
    # Codes moved by an affine map: a decoder whose first layer absorbs it renders as before.
    lights = _lights()
    levels = _lambertian(lights, 200)
    model = fit_neural_rti(levels, lights, STEPS)
    assert model.codes is not None
    fitted = np.mean((model.decode(model.codes, lights) * 255 - levels) ** 2)
    moved = (model.codes * 1.2 + 0.1).astype(np.float32)
    before = np.mean((model.decode(moved, lights) * 255 - levels) ** 2)
    tuned = tune_decoder(model, moved, levels, dataclasses.replace(STEPS, steps=400, rate=3e-3))
    after = np.mean((tuned.decode(moved, lights) * 255 - levels) ** 2)
    assert before > 2 * fitted  # measured 302 against 95 (squared 8-bit levels)
    assert after < 1.2 * fitted  # measured 94
    assert tuned.codes is model.codes and tuned.steps == model.steps + 400


def test_codes_are_fitted_to_new_pixels_with_the_decoder_fixed() -> None:
    lights = _lights()
    levels = _lambertian(lights, 400)
    model = fit_neural_rti(levels[:, :300], lights, STEPS)
    weights = [w.copy() for w, _ in model.decoder]
    other = levels[:, 300:]
    settings = dataclasses.replace(STEPS, steps=400, batch=100, lights_per_step=None)
    codes = fit_codes(model, other, settings)  # from the mean of the fitted codes

    def psnr(c: np.ndarray) -> float:
        shown = np.clip(np.rint(model.decode(c, lights) * 255), 0, 255)
        return 10 * math.log10(255**2 / np.mean((shown - other) ** 2))

    assert model.codes is not None
    assert psnr(np.tile(model.codes.mean(0), (100, 1))) < 15.0  # measured 12.5 dB
    assert psnr(codes) > 25.0  # measured 29.2 dB
    for before, (after, _) in zip(weights, model.decoder, strict=True):
        np.testing.assert_array_equal(before, after)


def test_bad_inputs_are_named() -> None:
    lights = _lights(10)
    levels = _lambertian(lights, 5)
    with pytest.raises(InputError, match="must be 8-bit"):
        fit_neural_rti(levels.astype(np.float32), lights)
    with pytest.raises(InputError, match=r"shape \(10, N >= 1, 3\)"):
        fit_neural_rti(levels[:, :, :2], lights)
    with pytest.raises(InputError, match=r"T >= 3"):
        fit_neural_rti(levels[:2], lights[:2])
    with pytest.raises(InputError, match="holdout"):
        NeuralSettings(holdout=0.5)
    with pytest.raises(InputError, match="time budget"):
        NeuralSettings(max_seconds=0)
    with pytest.raises(InputError, match="hidden"):
        NeuralSettings(hidden=0)
