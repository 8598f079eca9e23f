from __future__ import annotations

import numpy as np
import pytest

from core.directions import hemisphere_layout
from core.errors import InputError
from processing.learned_rti import (
    CODE_SIZE,
    LearnedRTI,
    TrainingSettings,
    _numpy_layers,
    _torch_mlp,
    train_learned_rti,
)

torch = pytest.importorskip("torch", reason="the learned extra (PyTorch) is not installed")

#: Enough steps for a Lambertian object to be learned (about 15 s on 2 cores).
QUICK = TrainingSettings(steps=1500, batch=64, lights_per_step=30)


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
    network = _torch_mlp([7, 5, 5, 2])
    x = np.random.default_rng(1).normal(size=(11, 7)).astype(np.float32)
    with torch.no_grad():
        expected = network(torch.from_numpy(x)).numpy()
    layers = _numpy_layers(network)
    assert [w.shape for w, _ in layers] == [(7, 5), (5, 5), (5, 2)]
    model = LearnedRTI(np.zeros((2, 3), np.float32), layers, layers, 1.0, 0.0, 0, 0.0)
    from processing.learned_rti import _mlp

    np.testing.assert_allclose(_mlp(model.encoder, x), expected, rtol=1e-5, atol=1e-6)


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


def test_training_is_deterministic_per_seed() -> None:
    lights = hemisphere_layout(12, "fibonacci")
    values = _lambertian(lights, samples=50)
    few = TrainingSettings(steps=5, batch=16, lights_per_step=4)
    a, b = train_learned_rti(values, lights, few), train_learned_rti(values, lights, few)
    c = train_learned_rti(values, lights, TrainingSettings(steps=5, batch=16, seed=1))
    np.testing.assert_array_equal(a.decoder[0][0], b.decoder[0][0])
    assert not np.array_equal(a.decoder[0][0], c.decoder[0][0])


def test_bad_inputs_are_named() -> None:
    lights = hemisphere_layout(12, "fibonacci")
    with pytest.raises(InputError, match=r"values must have shape \(12, N, 3\)"):
        train_learned_rti(np.zeros((11, 5, 3)), lights)
    with pytest.raises(InputError, match="lights must have shape"):
        train_learned_rti(np.zeros((1, 5, 3)), lights[:1])
    with pytest.raises(InputError, match="every measured value is zero"):
        train_learned_rti(np.zeros((12, 5, 3)), lights)
    with pytest.raises(InputError, match="steps must be at least 1"):
        TrainingSettings(steps=0)
