"""A learned relightable model: a code per sample and one small decoder shared by the object.

The class of neural RTI (Dulecha, Fanni, Ponchio, Pellacini, Giachetti: "Neural reflectance
transformation imaging", The Visual Computer 2020): an encoder reads every measured value of a
sample (its T lights, RGB) into a short code; a decoder maps (code, light direction) to the
sample's colour under that light. Both are small fully connected networks, trained together on
the capture itself, so the decoder learns the object's own family of responses (its highlights,
shadows and interreflections) instead of assuming one.

Training uses PyTorch (CPU): automatic gradients and Adam on small dense layers are what it is
built for, and its CPU build is the one machine-learning library this machine carries (JAX would
be a second download; scikit-learn's MLPs cannot share a decoder between per-sample codes).
Inference is plain numpy (a few matrix products), so relighting never imports PyTorch and a
trained model is a handful of arrays.

Values are learned in a perceptual encoding, ``(x / scale) ** (1 / GAMMA)``, as RTI tools learn
8-bit images: the loss then weighs dark and bright regions as the PSNR on 8-bit sRGB does, and
a highlight cannot own the fit.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

if TYPE_CHECKING:  # imported when training: relighting never needs it
    import torch

__all__ = [
    "CODE_SIZE",
    "DECODER_WIDTH",
    "ENCODER_WIDTH",
    "GAMMA",
    "LearnedRTI",
    "TrainingSettings",
    "train_learned_rti",
]

#: Length of each sample's code (neural RTI's default).
CODE_SIZE = 9
#: Hidden units of the encoder's three layers and of the decoder's three layers (neural RTI).
ENCODER_WIDTH = 150
DECODER_WIDTH = 50
#: Exponent of the perceptual encoding the networks read and write.
GAMMA = 2.2
#: Percentile of the measured values that maps to 1 in the encoding.
SCALE_PERCENTILE = 99.5


@dataclass(frozen=True)
class TrainingSettings:
    """How a :class:`LearnedRTI` is trained.

    Attributes
    ----------
    steps : int, Adam steps (the learning rate decays from ``rate`` to ``rate / 10`` over them)
    batch : int, samples per step
    lights_per_step : int, lights the decoder is trained on per step (a random subset)
    rate : float, initial learning rate
    max_samples : int, samples drawn (at random) to train on; every sample is encoded
    max_seconds : float, training stops after this long even if steps remain (a cap for slow
        machines; the default steps take about a minute on 2 cores)
    seed : int
    """

    steps: int = 2000
    batch: int = 256
    lights_per_step: int = 32
    rate: float = 5e-3
    max_samples: int = 200_000
    max_seconds: float = 600.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("steps", "batch", "lights_per_step", "max_samples"):
            if getattr(self, name) < 1:
                raise InputError(f"learned model: {name} must be at least 1")
        if not self.rate > 0 or not self.max_seconds > 0:
            raise InputError("learned model: rate and max_seconds must be positive")


@dataclass(frozen=True)
class LearnedRTI:
    """A trained encoder and decoder, as numpy arrays.

    Attributes
    ----------
    lights : ndarray, shape (T, 3), the measured light directions the encoder reads, in the
        frame the model was trained in (camera frame for pixels, rig frame for points)
    encoder, decoder : tuple of (weight (in, out), bias (out,)) float32 pairs; ELU between
        layers, none after the last
    scale : float, the linear value encoded as 1
    seconds : float, training time
    steps : int, steps taken
    loss : float, final training loss (mean squared error in the encoding)
    """

    lights: NDArray[np.float32]
    encoder: tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]
    decoder: tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]
    scale: float
    seconds: float
    steps: int
    loss: float

    def encode(self, values: NDArray[np.floating], chunk: int = 65536) -> NDArray[np.float32]:
        """Codes (N, :data:`CODE_SIZE`) of N samples' measured values (T, N, 3), linear."""
        values = _checked_values(values, len(self.lights))
        codes = np.empty((values.shape[1], CODE_SIZE), dtype=np.float32)
        for start in range(0, values.shape[1], chunk):
            block = _encoded(values[:, start : start + chunk], self.scale)
            codes[start : start + chunk] = _mlp(self.encoder, _encoder_input(block))
        return codes

    def decode(
        self, codes: NDArray[np.floating], directions: NDArray[np.floating]
    ) -> NDArray[np.float32]:
        """Linear values (Q, N, 3) of N coded samples under Q light directions (Q, 3)."""
        codes = np.asarray(codes, dtype=np.float32)
        d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
        out = np.empty((len(d), len(codes), 3), dtype=np.float32)
        for q in range(len(d)):
            inputs = np.concatenate([codes, np.broadcast_to(d[q], (len(codes), 3))], axis=1)
            y = np.maximum(_mlp(self.decoder, inputs), 0.0)
            out[q] = self.scale * y**GAMMA
        return out


def _checked_values(values: NDArray[np.floating], lights: int) -> NDArray[np.float32]:
    v = np.asarray(values, dtype=np.float32)
    if v.ndim != 3 or v.shape[0] != lights or v.shape[2] != 3:
        raise InputError(f"learned model: values must have shape ({lights}, N, 3), got {v.shape}")
    return v


def _encoded(values: NDArray[np.float32], scale: float) -> NDArray[np.float32]:
    """The perceptual encoding (module docstring); a missing (non-finite) value reads as 0."""
    finite = np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)
    return np.power(np.maximum(finite, 0.0) / scale, 1.0 / GAMMA, dtype=np.float32)


def _encoder_input(encoded: NDArray[np.float32]) -> NDArray[np.float32]:
    """(T, N, 3) -> (N, 3T): each sample's measured values in one row."""
    return np.ascontiguousarray(encoded.transpose(1, 0, 2).reshape(encoded.shape[1], -1))


def _elu(x: NDArray[np.float32]) -> NDArray[np.float32]:
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))


def _mlp(
    layers: tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...], x: NDArray[np.float32]
) -> NDArray[np.float32]:
    for i, (weight, bias) in enumerate(layers):
        x = x @ weight + bias
        if i < len(layers) - 1:
            x = _elu(x)
    return x


def train_learned_rti(
    values: NDArray[np.floating],
    lights: NDArray[np.floating],
    settings: TrainingSettings = TrainingSettings(),
    progress: Callable[[int, int], None] | None = None,
) -> LearnedRTI:
    """Train an encoder and decoder on N samples measured under T lights.

    Parameters
    ----------
    values : ndarray, shape (T, N, 3), linear radiance of each sample under each light
    lights : ndarray, shape (T, 3), unit light directions (the frame the model will be asked in)
    settings : TrainingSettings
    progress : callable(step, steps), optional, called after each step

    Raises
    ------
    InputError
        Shapes that do not match, fewer than two lights, no bright value, or PyTorch missing.
    """
    directions = np.asarray(lights, dtype=np.float32)
    if directions.ndim != 2 or directions.shape[1] != 3 or len(directions) < 2:
        raise InputError(
            f"learned model: lights must have shape (T >= 2, 3), got {directions.shape}"
        )
    v = _checked_values(values, len(directions))
    finite = v[np.isfinite(v)]
    scale = float(np.percentile(finite, SCALE_PERCENTILE)) if finite.size else 0.0
    if not scale > 0:
        raise InputError("learned model: every measured value is zero; nothing to learn")
    try:
        import torch
    except ImportError as exc:  # the `learned` extra
        raise InputError(
            "the learned model needs PyTorch: pip install -e '.[learned]' (make test does)"
        ) from exc

    rng = np.random.default_rng(settings.seed)
    n = v.shape[1]
    chosen = np.sort(rng.choice(n, size=min(n, settings.max_samples), replace=False))
    encoded = _encoded(v[:, chosen], scale)
    t_count = len(directions)
    torch.manual_seed(settings.seed)
    torch.set_num_threads(os.cpu_count() or 1)
    inputs = torch.from_numpy(_encoder_input(encoded))
    targets = torch.from_numpy(np.ascontiguousarray(encoded.transpose(1, 0, 2)))  # (N, T, 3)
    light_t = torch.from_numpy(directions)
    encoder = _torch_mlp([3 * t_count, *[ENCODER_WIDTH] * 3, CODE_SIZE])
    decoder = _torch_mlp([CODE_SIZE + 3, *[DECODER_WIDTH] * 3, 3])
    parameters = list(encoder.parameters()) + list(decoder.parameters())
    optimiser = torch.optim.Adam(parameters, lr=settings.rate)
    decay = torch.optim.lr_scheduler.CosineAnnealingLR(
        optimiser, settings.steps, eta_min=settings.rate / 10
    )
    generator = torch.Generator().manual_seed(settings.seed)
    per_step = min(settings.lights_per_step, t_count)
    start = time.perf_counter()
    loss_value = math.nan
    step = 0
    while step < settings.steps and time.perf_counter() - start < settings.max_seconds:
        rows = torch.randint(len(chosen), (settings.batch,), generator=generator)
        seen = torch.randperm(t_count, generator=generator)[:per_step]
        codes = encoder(inputs[rows])  # (B, k)
        b = len(rows)
        decoder_in = torch.cat(
            [
                codes[:, None, :].expand(b, per_step, CODE_SIZE),
                light_t[seen][None, :, :].expand(b, per_step, 3),
            ],
            dim=2,
        )
        predicted = decoder(decoder_in)
        loss = torch.mean((predicted - targets[rows][:, seen]) ** 2)
        optimiser.zero_grad()
        loss.backward()  # type: ignore[no-untyped-call]
        optimiser.step()
        decay.step()
        loss_value = float(loss.detach())
        step += 1
        if progress is not None:
            progress(step, settings.steps)
    seconds = time.perf_counter() - start
    return LearnedRTI(
        lights=directions,
        encoder=_numpy_layers(encoder),
        decoder=_numpy_layers(decoder),
        scale=scale,
        seconds=seconds,
        steps=step,
        loss=loss_value,
    )


def _torch_mlp(sizes: list[int]) -> torch.nn.Sequential:
    """Dense layers of ``sizes`` with ELU between them (none after the last)."""
    import torch

    layers: list[torch.nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.ELU())
    return torch.nn.Sequential(*layers)


def _numpy_layers(
    network: torch.nn.Sequential,
) -> tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]:
    """The (weight (in, out), bias) pairs of the network's dense layers, as numpy arrays."""
    import torch

    return tuple(
        (
            np.ascontiguousarray(module.weight.detach().numpy().T, dtype=np.float32),
            module.bias.detach().numpy().astype(np.float32),
        )
        for module in network
        if isinstance(module, torch.nn.Linear)
    )
