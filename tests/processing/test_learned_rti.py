from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.directions import hemisphere_layout
from core.errors import InputError, NotApplicable
from processing.learned_rti import CODE_SIZE, LearnedRTI, light_features
from processing.learned_rti_training import TrainingSettings, _decoded, train_learned_rti
from processing.network_training import numpy_layers, torch_mlp, validation_lights

ROOT = Path(__file__).parents[2]

torch = pytest.importorskip("torch", reason="the learned extra (PyTorch) is not installed")

#: Enough steps for a Lambertian object to be learned (about 15 s on 2 cores): every step is
#: taken (no held-out choice, passes enough to reach the step cap).
QUICK = TrainingSettings(steps=1500, batch=64, lights_per_step=30, epochs=10_000, validation=0.0)


def _lambertian(lights: np.ndarray, samples: int = 300, seed: int = 0) -> np.ndarray:
    """(T, N, 3) radiance of Lambertian samples with random normals and albedos."""
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(samples, 3)) * [0.4, 0.4, 1.0]
    normals[:, 2] = np.abs(normals[:, 2])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    albedo = rng.uniform(0.2, 0.9, (samples, 3))
    cosine = np.clip(lights @ normals.T, 0.0, None)
    return (cosine[:, :, None] * albedo[None] / np.pi).astype(np.float32)


def test_numpy_inference_is_the_trained_network() -> None:
    network = torch_mlp([7, 5, 5, 2])
    x = np.random.default_rng(1).normal(size=(11, 7)).astype(np.float32)
    with torch.no_grad():
        expected = network(torch.from_numpy(x)).numpy()
    layers = numpy_layers(network)
    assert [w.shape for w, _ in layers] == [(7, 5), (5, 5), (5, 2)]
    model = LearnedRTI(np.zeros((2, 3), np.float32), layers, layers, 1.0, 0.0, 0, 0.0)
    from processing.learned_rti import _mlp

    np.testing.assert_allclose(_mlp(model.encoder, x), expected, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("frequencies", [0, 2])
def test_numpy_decoding_is_the_split_torch_decoder(frequencies: int) -> None:
    # The decoder's first layer is applied in two parts (code, light features) in both.
    k, features = 4, 3 + 6 * frequencies
    torch.manual_seed(0)
    decoder = torch_mlp([k + features, 6, 6, 3])
    encoder = torch_mlp([6, 5, k])  # only its output size matters to decode
    rng = np.random.default_rng(2)
    codes = rng.normal(size=(13, k)).astype(np.float32)
    d = hemisphere_layout(5, "fibonacci").astype(np.float32)
    f = light_features(d, frequencies)
    assert f.shape == (5, features) and f.dtype == np.float32
    with torch.no_grad():
        y = _decoded(decoder, torch.from_numpy(codes), torch.from_numpy(f)).numpy()
        whole = decoder(
            torch.cat(
                [
                    torch.from_numpy(codes)[:, None].expand(13, 5, k),
                    torch.from_numpy(f)[None].expand(13, 5, features),
                ],
                2,
            )
        ).numpy()
    np.testing.assert_allclose(y, whole, rtol=1e-5, atol=1e-6)
    model = LearnedRTI(
        d,
        numpy_layers(encoder),
        numpy_layers(decoder),
        1.0,
        0.0,
        0,
        0.0,
        light_frequencies=frequencies,
    )
    assert model.code_size == k
    expected = np.maximum(y, 0.0).transpose(1, 0, 2) ** 2.2
    np.testing.assert_allclose(model.decode(codes, d), expected, rtol=1e-4, atol=1e-6)


def test_a_lambertian_object_is_learned_and_predicted_at_new_lights() -> None:
    lights = hemisphere_layout(30, "fibonacci")
    new = hemisphere_layout(9, "grid")
    values, truth = _lambertian(lights, 120), _lambertian(new, 120)
    model = train_learned_rti(values, lights, QUICK)
    assert model.steps == QUICK.steps and model.loss < 1e-2
    codes = model.encode(values)
    assert codes.shape == (120, CODE_SIZE) and codes.dtype == np.float32
    predicted = model.decode(codes, new)
    assert predicted.shape == (9, 120, 3) and predicted.min() >= 0.0
    error = np.sqrt(np.sum((predicted - truth) ** 2) / np.sum(truth**2))
    # Far better than knowing nothing of the light: each sample's mean value.
    mean = np.broadcast_to(values.mean(axis=0), truth.shape)
    baseline = np.sqrt(np.sum((mean - truth) ** 2) / np.sum(truth**2))
    assert error < 0.12 and error < baseline / 4, (error, baseline)


def _horizons(lights: np.ndarray, samples: int = 120, seed: int = 0) -> np.ndarray:
    """(T, N) visibility: each sample sees the lights above its own random horizon."""
    rng = np.random.default_rng(seed)
    horizon = rng.uniform(0.2, 0.8, samples)
    return (lights[:, 2:3] > horizon[None, :]).astype(np.float32)


def test_a_model_told_the_visibility_learns_the_samples_lit_and_in_shadow() -> None:
    lights = hemisphere_layout(30, "fibonacci")
    new = hemisphere_layout(9, "grid")
    lit, seen = _horizons(lights), _horizons(new)
    values = _lambertian(lights, 120) * lit[:, :, None]
    truth = _lambertian(new, 120) * seen[:, :, None]
    model = train_learned_rti(values, lights, QUICK, visibility=lit)
    assert model.shadowed
    codes = model.encode(values)
    predicted = model.decode(codes, new, seen)
    error = np.sqrt(np.sum((predicted - truth) ** 2) / np.sum(truth**2))
    assert error < 0.12, error
    # In shadow a Lambertian sample is black; told so, the model gives black.
    assert model.decode(codes, new, np.zeros_like(seen)).max() < 0.02 * truth.max()
    with pytest.raises(InputError, match="a visibility goes with a model trained with one"):
        model.decode(codes, new)
    with pytest.raises(InputError, match=r"visibility must have shape \(9, 120\)"):
        model.decode(codes, new, seen[:, :5])
    with pytest.raises(InputError, match=r"visibility must have shape \(30, 120\)"):
        train_learned_rti(values, lights, QUICK, visibility=lit[:5])


def test_an_encoder_can_make_the_codes() -> None:
    lights = hemisphere_layout(30, "fibonacci")
    new = hemisphere_layout(9, "grid")
    values, truth = _lambertian(lights, 120), _lambertian(new, 120)
    settings = TrainingSettings(**{**vars(QUICK), "encoder": True, "rate": 5e-3})
    model = train_learned_rti(values, lights, settings)
    assert model.codes is None and len(model.encoder) == 4
    predicted = model.decode(model.encode(values), new)
    error = np.sqrt(np.sum((predicted - truth) ** 2) / np.sum(truth**2))
    assert error < 0.15, error


def test_free_codes_are_found_by_the_values_they_were_trained_on() -> None:
    lights = hemisphere_layout(16, "fibonacci")
    values = _lambertian(lights, samples=40)
    # 30 of the 40 samples trained on: the others take their nearest trained neighbour's code
    model = train_learned_rti(values, lights, TrainingSettings(steps=3, batch=8, max_samples=30))
    assert model.codes is not None and model.coded is not None
    assert model.codes.shape == (30, CODE_SIZE) and model.coded.shape == (30, 48)
    codes = model.encode(values)
    own = {row.tobytes(): i for i, row in enumerate(model.coded)}
    from processing.learned_rti import _encoded, _encoder_input

    rows = _encoder_input(_encoded(values, model.scale))
    trained = [own.get(r.tobytes(), -1) for r in rows]
    assert sum(t >= 0 for t in trained) == 30
    for i, t in enumerate(trained):
        if t >= 0:
            np.testing.assert_array_equal(codes[i], model.codes[t])
        else:
            nearest = np.argmin(np.sum((model.coded - rows[i]) ** 2, axis=1))
            np.testing.assert_array_equal(codes[i], model.codes[nearest])


def test_training_is_deterministic_per_seed() -> None:
    lights = hemisphere_layout(12, "fibonacci")
    values = _lambertian(lights, samples=50)
    few = TrainingSettings(steps=6, batch=16, lights_per_step=4, threads=1, validation=0.2)
    a, b = train_learned_rti(values, lights, few), train_learned_rti(values, lights, few)
    c = train_learned_rti(
        values, lights, TrainingSettings(steps=6, batch=16, seed=1, validation=0.2)
    )
    np.testing.assert_array_equal(a.decoder[0][0], b.decoder[0][0])
    assert not np.array_equal(a.decoder[0][0], c.decoder[0][0])
    # Both phases ran within the step cap: the choice on held-out lights got half.
    assert a.steps == 6 and {r.phase for r in a.history} == {"choose", "final"}


def test_held_out_lights_stop_training_and_choose_the_passes() -> None:
    lights = hemisphere_layout(20, "fibonacci")
    values = _lambertian(lights, samples=64)
    settings = TrainingSettings(
        batch=32, epochs=300, patience=2, validation=0.2, rate=2e-2, threads=1
    )
    model = train_learned_rti(values, lights, settings)
    chosen = [r for r in model.history if r.phase == "choose"]
    final = [r for r in model.history if r.phase == "final"]
    # It really stopped: fewer passes than allowed, the last `patience` of them no better.
    assert len(chosen) < settings.epochs
    errors = [r.validation_error for r in chosen]
    best = int(np.argmin(errors))
    assert len(chosen) == best + 1 + settings.patience
    # The final fit, on every light, ran for the chosen passes.
    assert model.epochs == len(final) == best + 1
    assert all(math.isnan(r.validation_error) for r in final)
    assert model.validation_error == pytest.approx(errors[best])
    # The curve is recorded in order, with the time of each pass.
    seconds = [r.seconds for r in model.history]
    assert seconds == sorted(seconds) and seconds[-1] <= model.seconds
    assert all(np.isfinite([r.train_error for r in model.history]))
    assert model.steps == (len(chosen) + len(final)) * 2  # 64 samples, 32 a step


def test_validation_lights_are_spread_out() -> None:
    lights = hemisphere_layout(49, "fibonacci")
    held = validation_lights(lights, 0.15)
    assert len(held) == 7 and held.dtype == np.int64 and np.all(np.diff(held) > 0)
    # No two held-out lights are neighbours: each leaves a gap of one light spacing.
    distance = np.linalg.norm(lights[:, None] - lights[None], axis=2)
    np.fill_diagonal(distance, np.inf)
    nearest = np.min(distance, axis=1)
    between = distance[np.ix_(held, held)]
    assert between.min() > 1.5 * np.median(nearest)
    assert validation_lights(lights, 0.0).size == 0
    assert len(validation_lights(lights[:3], 0.4)) == 1


def test_the_code_size_is_a_setting() -> None:
    lights = hemisphere_layout(10, "fibonacci")
    values = _lambertian(lights, samples=20)
    model = train_learned_rti(values, lights, TrainingSettings(steps=2, code_size=5, batch=8))
    assert model.code_size == 5 and model.encode(values).shape == (20, 5)
    assert model.decode(model.encode(values), lights[:2]).shape == (2, 20, 3)
    with pytest.raises(InputError, match=r"codes must have shape \(N, 5\)"):
        model.decode(np.zeros((20, CODE_SIZE)), lights[:2])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA GPU")
def test_gpu_and_cpu_training_agree() -> None:
    lights = hemisphere_layout(20, "fibonacci")
    values = _lambertian(lights, samples=200)
    settings = TrainingSettings(epochs=30, batch=50, validation=0.0)
    cpu = train_learned_rti(values, lights, TrainingSettings(**{**vars(settings), "device": "cpu"}))
    gpu = train_learned_rti(
        values, lights, TrainingSettings(**{**vars(settings), "device": "cuda"})
    )
    assert cpu.device == "cpu" and gpu.device == "cuda"
    new = hemisphere_layout(9, "grid")
    a = cpu.decode(cpu.encode(values), new)
    b = gpu.decode(gpu.encode(values), new)
    # Not bit-equal (other kernels, other rounding), but the same fit.
    assert np.sqrt(np.mean((a - b) ** 2)) < 0.02 * np.sqrt(np.mean(a**2))


def test_bad_inputs_are_named() -> None:
    lights = hemisphere_layout(12, "fibonacci")
    with pytest.raises(InputError, match=r"values must have shape \(12, N, 3\)"):
        train_learned_rti(np.zeros((11, 5, 3)), lights)
    with pytest.raises(InputError, match="lights must have shape"):
        train_learned_rti(np.zeros((12, 5, 3)), lights[:, :2])
    with pytest.raises(NotApplicable, match="needs at least 2 lights, got 1"):
        train_learned_rti(np.zeros((1, 5, 3)), lights[:1])
    with pytest.raises(InputError, match="every measured value is zero"):
        train_learned_rti(np.zeros((12, 5, 3)), lights)
    with pytest.raises(InputError, match="steps must be at least 1"):
        TrainingSettings(steps=0)
    with pytest.raises(InputError, match="validation is the share of lights held out"):
        TrainingSettings(validation=0.5)
    with pytest.raises(InputError, match="device must be auto, cpu or cuda"):
        TrainingSettings(device="tpu")  # type: ignore[arg-type]
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match="PyTorch sees no CUDA GPU"):
            train_learned_rti(_lambertian(lights, 5), lights, TrainingSettings(device="cuda"))


def test_an_optimiser_leaves_nothing_in_the_temp_folder(tmp_path: Path) -> None:
    # torch.optim imports torch._dynamo, which makes its compiler cache in the temp folder: a
    # training (and a signal test whose signal came late) found torchinductor_<user> left there.
    # A process of its own: this one may have imported torch._dynamo already.
    code = (
        "import torch\n"
        "from processing.network_training import adam\n"
        "adam([torch.zeros(2, requires_grad=True)]).step()\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True,
                   env={**os.environ, "TMPDIR": str(tmp_path)})  # fmt: skip
    assert sorted(path.name for path in tmp_path.iterdir()) == []
