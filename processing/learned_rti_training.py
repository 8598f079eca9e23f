"""Training a learned relightable model (:class:`processing.learned_rti.LearnedRTI`).

Training uses PyTorch (on a CUDA GPU when one is present, else the CPU): automatic gradients
and Adam on small dense layers are what it is built for, and its CPU build is the one
machine-learning library this machine carries. Inference is plain numpy (a few matrix
products), so relighting never imports PyTorch and a trained model is a handful of arrays.

What limited the rung, measured by ``bench/learned_study.py`` and scratch runs on path-traced
RTI domes (49 lights, 8-bit sRGB JPEG) and the bundled real capture:

- optimisation: 2,000 steps of 256 samples x 32 lights stop far short of convergence (train
  error close to the held-out error, both falling): training now runs for passes over the
  samples (``epochs``) within a time cap. A step trains on 24 random lights of its samples,
  not all of them: on 49-light domes at the same 90 s this gave 1.6-2.6 times the passes
  and +0.04 to +1.0 dB held-out (copper bowl 29.94 -> 30.97, clear coat 25.97 -> 26.49,
  brushed knot 26.72 -> 27.32, matte 24.25 -> 24.29, lion 33.33 -> 33.53, learned+residual);
- the encoder: mapping 3T measured values to a code is what the network learns slowest. By
  default each trained sample's code is optimised directly (an "auto-decoder", as the model
  only relights its own capture), started at the sample's principal-component scores;
  training error then falls 4-10 times lower for the same steps and the held-out error
  follows (``encoder=True`` restores neural RTI's encoder);
- the light encoding: Fourier features of the direction (``d``, ``sin``/``cos`` of
  ``2^f pi d``) let the small decoder follow sharp shadow edges and highlights;
- capacity (decoder 128 wide, codes of 16) changed little with an encoder;
- the codes' rate: a code is updated once a pass, the decoder every step; at ``code_rate`` 10
  times the decoder's, learned+residual gained 0.15-0.45 dB at the time cap on three captures
  and lost 0.22 on one (docs/evaluation.md);
- the passes: a capture of few pixels makes its passes long before the time cap, so their
  cap (``epochs``) is set where the bundled capture's held-out error stops improving (every
  other light held out, learned+residual: 200, 400, 800 and 1,600 passes 33.88, 34.81, 35.07
  and 35.02 dB, 19 to 157 s); a 160 x 160 capture reaches the time cap first.

Held-out lights (``validation``) can choose the number of passes: a spread share of the
lights is removed from the codes' input and the targets, the held-out error is recorded per
pass, training stops when it has not improved for ``patience`` passes, and the model is
trained again on every light for the chosen passes. It is off by default: a held-out light
of the dome leaves a gap about twice as wide as the ones relighting fills, and its error
turned up while the test error was still falling (stopping there cost about 1 dB).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError, NotApplicable
from processing.learned_rti import (
    CODE_SIZE,
    DECODER_LAYERS,
    DECODER_WIDTH,
    ENCODER_WIDTH,
    LIGHT_FREQUENCIES,
    EpochRecord,
    LearnedRTI,
    _checked_values,
    _encoded,
    _encoder_input,
    light_features,
    shaded,
)
from processing.network_training import (
    Device,
    adam,
    check_settings,
    idle_cores,
    numpy_layers,
    principal_codes,
    torch_mlp,
    training_device,
    validation_lights,
)

if TYPE_CHECKING:  # imported when training: relighting never needs it
    import torch

__all__ = ["TrainingSettings", "train_learned_rti"]

#: Percentile of the measured values that maps to 1 in the encoding.
SCALE_PERCENTILE = 99.5
#: Samples the per-pass held-out error is measured on (a fixed random subset: cheap, stable).
MONITOR_SAMPLES = 4096


@dataclass(frozen=True)
class TrainingSettings:
    """How a :class:`LearnedRTI` is trained.

    Attributes
    ----------
    steps : int, most Adam steps in all (both phases): a hard cap
    batch : int, samples per step
    lights_per_step : int or None, lights the decoder is trained on per step (a random
        subset, drawn anew each step); None: all of them. 24 by default: more passes in
        the time cap paid more than every light per step (module docstring)
    rate : float, initial learning rate (cosine decay to ``rate / 10`` over each phase, by
        its planned steps or its share of ``max_seconds``, whichever runs out first)
    code_rate : float, the codes' learning rate as a multiple of ``rate`` (auto-decoder): a
        code is updated once a pass, the decoder every step (module docstring)
    max_samples : int, samples drawn (at random) to train on; every sample is encoded
    max_seconds : float, training (both phases) stops after this long even if passes remain
    seed : int
    epochs : int, most passes over the samples; the held-out lights choose fewer
    validation : float, share of the lights held out to choose the passes (0: no choice,
        ``epochs`` passes on every light). Off by default: held-out lights leave gaps wider
        than relighting fills, and their error turns up passes before the test error does
    encoder : bool, codes made by an encoder network from the sample's measured values
        (neural RTI) rather than optimised per sample directly (an "auto-decoder": the
        model relights the samples it was trained on; others get the code of the trained
        sample of the nearest values, see :meth:`LearnedRTI.encode`)
    patience : int, passes without a better held-out error before the choice stops
    code_size : int, length of each sample's code
    encoder_width, decoder_width : int, hidden units of each encoder and decoder layer
    decoder_layers : int, hidden layers of the decoder
    light_frequencies : int, octaves of Fourier features of the light direction (0: raw)
    threads : int or None, PyTorch CPU threads (None: the cores idle when training starts)
    device : "auto" (CUDA when available), "cpu" or "cuda"
    """

    steps: int = 200_000
    batch: int = 256
    lights_per_step: int | None = 24
    rate: float = 1e-2
    code_rate: float = 10.0
    max_samples: int = 200_000
    max_seconds: float = 170.0
    seed: int = 0
    epochs: int = 800
    validation: float = 0.0
    patience: int = 8
    encoder: bool = False
    code_size: int = CODE_SIZE
    encoder_width: int = ENCODER_WIDTH
    decoder_width: int = DECODER_WIDTH
    decoder_layers: int = DECODER_LAYERS
    light_frequencies: int = LIGHT_FREQUENCIES
    threads: int | None = None
    device: Device = "auto"

    def __post_init__(self) -> None:
        check_settings(
            self,
            model="learned",
            counts=(
                "steps",
                "batch",
                "max_samples",
                "epochs",
                "patience",
                "code_size",
                "encoder_width",
                "decoder_width",
                "decoder_layers",
            ),
            share="validation",
            also=(
                (self.light_frequencies >= 0, "light_frequencies must be 0 or more"),
                (
                    self.rate > 0 and self.code_rate > 0 and self.max_seconds > 0,
                    "rate, code_rate and max_seconds must be positive",
                ),
            ),
        )


def train_learned_rti(
    values: NDArray[np.floating],
    lights: NDArray[np.floating],
    settings: TrainingSettings = TrainingSettings(),
    progress: Callable[[int, int], None] | None = None,
    *,
    visibility: NDArray[np.floating] | None = None,
) -> LearnedRTI:
    """Train an encoder and decoder on N samples measured under T lights.

    With ``settings.validation`` > 0 (and 5 or more lights) training runs twice: first with
    a spread share of the lights held out (:func:`validation_lights`), stopping when their
    error has not improved for ``patience`` passes, then from the same start on every light
    for the best number of passes. Both phases share ``max_seconds`` and ``steps``.

    Parameters
    ----------
    values : ndarray, shape (T, N, 3), linear radiance of each sample under each light
    lights : ndarray, shape (T, 3), unit light directions (the frame the model will be asked in)
    settings : TrainingSettings
    progress : callable(step, planned), optional, called after each step; ``planned`` is the
        steps now foreseen (it shrinks when the held-out lights stop training early)
    visibility : ndarray, shape (T, N), optional, each light's visibility at each sample (1
        lit, 0 in shadow): the model is then ``shadowed`` (:class:`LearnedRTI`)

    Raises
    ------
    InputError
        Shapes that do not match, or a CUDA device asked for and not present.
    NotApplicable
        Fewer than two lights, no bright value, or PyTorch missing.
    """
    directions = np.asarray(lights, dtype=np.float32)
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise InputError(f"learned model: lights must have shape (T, 3), got {directions.shape}")
    if len(directions) < 2:
        raise NotApplicable(f"learned model: it needs at least 2 lights, got {len(directions)}")
    v = _checked_values(values, len(directions))
    if visibility is not None and np.shape(visibility) != v.shape[:2]:
        raise InputError(
            f"learned model: visibility must have shape {v.shape[:2]}, got {np.shape(visibility)}"
        )
    finite = v[np.isfinite(v)]
    scale = float(np.percentile(finite, SCALE_PERCENTILE)) if finite.size else 0.0
    if not scale > 0:
        raise NotApplicable("learned model: every measured value is zero; nothing to learn")
    try:
        import torch
    except ImportError as exc:  # the `learned` extra
        raise NotApplicable(
            "the learned model needs PyTorch: pip install -e '.[learned]' (make test does)"
        ) from exc
    device = training_device(settings.device)
    if device == "cpu":
        torch.set_num_threads(settings.threads or idle_cores())

    rng = np.random.default_rng(settings.seed)
    n = v.shape[1]
    chosen = np.sort(rng.choice(n, size=min(n, settings.max_samples), replace=False))
    shadows = None if visibility is None else np.asarray(visibility, np.float32)[:, chosen]
    data = _Data(_encoded(v[:, chosen], scale), directions, shadows, settings, device)
    held = validation_lights(directions, settings.validation, seed=settings.seed)
    if len(directions) < 5:  # too few lights to spare any
        held = held[:0]
    steps_per_epoch = -(-len(chosen) // settings.batch)
    clock = _Clock(settings, progress, steps_per_epoch)
    history: list[EpochRecord] = []
    epochs = settings.epochs
    if held.size:
        clock.planned = min(settings.steps, 2 * settings.epochs * steps_per_epoch)
        # The choice may spend half the budget: the final fit needs no more than it used.
        clock.step_limit = max(1, settings.steps // 2)
        clock.second_limit = settings.max_seconds / 2
        *_, best = _train_phase(data, held, settings, settings.epochs, clock, history, "choose")
        epochs = max(1, best)
        clock.step_limit, clock.second_limit = settings.steps, settings.max_seconds
        clock.planned = min(settings.steps, clock.step + epochs * steps_per_epoch)
    else:
        clock.planned = min(settings.steps, settings.epochs * steps_per_epoch)
    coder, decoder, loss, _ = _train_phase(
        data, held[:0], settings, epochs, clock, history, "final"
    )
    if isinstance(coder, torch.nn.Sequential):
        encoder, codes, coded = numpy_layers(coder), None, None
    else:
        encoder = ()
        codes = coder.detach().cpu().numpy().astype(np.float32)
        coded = _encoder_input(_encoded(v[:, chosen], scale))
    return LearnedRTI(
        lights=directions,
        encoder=encoder,
        decoder=numpy_layers(decoder),
        scale=scale,
        seconds=clock.seconds(),
        steps=clock.step,
        loss=loss,
        light_frequencies=settings.light_frequencies,
        history=tuple(history),
        epochs=sum(1 for r in history if r.phase == "final"),
        device=device,
        codes=codes,
        coded=coded,
        shadowed=visibility is not None,
    )


class _Clock:
    """Steps and seconds spent, against the caps of the settings; reports progress."""

    def __init__(
        self,
        settings: TrainingSettings,
        progress: Callable[[int, int], None] | None,
        steps_per_epoch: int,
    ) -> None:
        self.settings = settings
        self.progress = progress
        self.steps_per_epoch = steps_per_epoch
        self.start = time.perf_counter()
        self.step = 0
        self.planned = settings.steps
        self.step_limit = settings.steps
        self.second_limit = settings.max_seconds

    def seconds(self) -> float:
        return time.perf_counter() - self.start

    def spent(self) -> bool:
        return self.step >= self.step_limit or self.seconds() >= self.second_limit

    def tick(self) -> None:
        self.step += 1
        if self.progress is not None:
            self.progress(self.step, max(self.planned, self.step))


class _Data:
    """The training tensors, on the training device."""

    def __init__(
        self,
        encoded: NDArray[np.float32],
        directions: NDArray[np.float32],
        visibility: NDArray[np.float32] | None,
        settings: TrainingSettings,
        device: str,
    ) -> None:
        import torch

        self.device = device
        self.count = encoded.shape[1]
        self.lights = len(directions)
        # (N, T, 3): the encoder reads a row flattened, the decoder's targets are its lights
        self.values = torch.from_numpy(np.ascontiguousarray(encoded.transpose(1, 0, 2))).to(device)
        features = light_features(directions, settings.light_frequencies)
        self.features = torch.from_numpy(features).to(device)
        told = None if visibility is None else np.ascontiguousarray(visibility.T)  # (N, T)
        self.visibility = None if told is None else torch.from_numpy(told).to(device)
        self.start_codes = principal_codes(encoded, settings.code_size, settings.seed)
        monitor = np.random.default_rng(settings.seed + 1).permutation(self.count)
        self.monitor = torch.from_numpy(np.sort(monitor[:MONITOR_SAMPLES])).to(device)

    def shadows(self, rows: torch.Tensor, lights: torch.Tensor) -> torch.Tensor | None:
        """The visibility (B, Q) of ``lights`` at the samples ``rows`` (None: not told)."""
        return None if self.visibility is None else self.visibility[rows][:, lights]


def _networks(
    settings: TrainingSettings, lights: int, start_codes: NDArray[np.float32], outputs: int
) -> tuple[torch.nn.Sequential | torch.nn.Parameter, torch.nn.Sequential]:
    """The coder (an encoder network, or free codes starting at ``start_codes``) and decoder."""
    import torch

    k = settings.code_size
    features = 3 + 6 * settings.light_frequencies
    coder: torch.nn.Sequential | torch.nn.Parameter
    if settings.encoder:
        coder = torch_mlp([3 * lights, *[settings.encoder_width] * 3, k])
    else:
        coder = torch.nn.Parameter(torch.from_numpy(start_codes))
    decoder = torch_mlp(
        [k + features, *[settings.decoder_width] * settings.decoder_layers, outputs]
    )
    return coder, decoder


def _decoded(
    decoder: torch.nn.Sequential,
    codes: torch.Tensor,
    features: torch.Tensor,
    visibility: torch.Tensor | None = None,
) -> torch.Tensor:
    """Colours (B, Q, 3) of codes (B, k) under light features (Q, F).

    A shadowed decoder's outputs are mixed by the ``visibility`` (B, Q)
    (:func:`processing.learned_rti.shaded`).
    """
    import torch

    first = decoder[0]
    assert isinstance(first, torch.nn.Linear)
    k = codes.shape[1]
    # Same as first(cat(code, feature)) for every pair, at a fraction of the cost.
    hidden = (codes @ first.weight[:, :k].T + first.bias)[:, None, :] + (
        features @ first.weight[:, k:].T
    )[None, :, :]
    out: torch.Tensor = decoder[1:](hidden)
    return out if visibility is None else shaded(out, visibility)


def _train_phase(
    data: _Data,
    held: NDArray[np.int64],
    settings: TrainingSettings,
    epochs: int,
    clock: _Clock,
    history: list[EpochRecord],
    phase: str,
) -> tuple[torch.nn.Sequential | torch.nn.Parameter, torch.nn.Sequential, float, int]:
    """Train new networks for up to ``epochs`` passes, ``held`` lights out.

    With held-out lights, stop after ``patience`` passes without a better held-out error.
    Returns the networks, the last step's loss and the pass (1-based) of the least held-out
    error (``epochs`` without held-out lights).
    """
    import torch

    torch.manual_seed(settings.seed)  # both phases start from the same networks
    outputs = 3 if data.visibility is None else 6
    coder, decoder = _networks(settings, data.lights, data.start_codes, outputs)
    decoder.to(data.device)
    # Each group's "rate" is its multiple of settings.rate, the schedule's factor.
    parts: list[tuple[list[torch.Tensor], float]]
    if isinstance(coder, torch.nn.Sequential):
        coder.to(data.device)
        parts = [([*coder.parameters(), *decoder.parameters()], 1.0)]
    else:
        coder = torch.nn.Parameter(coder.detach().to(data.device))
        parts = [([coder], settings.code_rate), (list(decoder.parameters()), 1.0)]
    optimiser = adam([{"params": p, "lr": settings.rate * r, "rate": r} for p, r in parts])
    planned = max(1, epochs * clock.steps_per_epoch)
    first_step, first_second = clock.step, clock.seconds()
    seconds = max(clock.second_limit - first_second, 1e-9)
    generator = torch.Generator().manual_seed(settings.seed)
    trained = np.setdiff1d(np.arange(data.lights), held)
    trained_t = torch.from_numpy(trained).to(data.device)
    held_t = torch.from_numpy(held).to(data.device)
    inputs = data.values.clone()
    inputs[:, held_t] = 0.0  # the held-out lights are not measured, as far as the codes know
    inputs = inputs.reshape(data.count, -1)
    per_step = min(settings.lights_per_step or len(trained), len(trained))
    loss_value = math.nan
    best_error, best_epoch = math.inf, epochs
    for epoch in range(1, epochs + 1):
        order = torch.randperm(data.count, generator=generator).to(data.device)
        losses: list[float] = []
        for start in range(0, data.count, settings.batch):
            if clock.spent():
                break
            rows = order[start : start + settings.batch]
            if per_step < len(trained):
                pick = torch.randperm(len(trained), generator=generator)[:per_step]
                seen = trained_t[pick.to(data.device)]
            else:
                seen = trained_t
            # Cosine decay over the phase, by steps or by time: the rate ends low whichever
            # cap ends the phase (a busy machine takes longer per step).
            done = max(
                (clock.step - first_step) / planned, (clock.seconds() - first_second) / seconds
            )
            schedule = 0.1 + 0.45 * (1 + math.cos(math.pi * min(done, 1)))
            for group in optimiser.param_groups:
                group["lr"] = settings.rate * group["rate"] * schedule
            codes = _codes(coder, inputs, rows)
            predicted = _decoded(decoder, codes, data.features[seen], data.shadows(rows, seen))
            loss = torch.mean((predicted - data.values[rows][:, seen]) ** 2)
            optimiser.zero_grad()
            loss.backward()  # type: ignore[no-untyped-call]
            optimiser.step()
            loss_value = float(loss.detach())
            losses.append(loss_value)
            clock.tick()
        if not losses:  # the caps ran out at the pass's start
            break
        # The pass's own losses are its training error: decoding the samples again under
        # every light cost more than the pass itself on a capture of few pixels and many
        # lights (the lion's 240: 1 s against 0.3 s a pass).
        held_error = _held_error(coder, decoder, inputs, data, held_t) if held.size else math.nan
        history.append(
            EpochRecord(phase, epoch, clock.seconds(), float(np.mean(losses)), held_error)
        )
        if held.size:
            if held_error < best_error:
                best_error, best_epoch = held_error, epoch
            elif epoch - best_epoch >= settings.patience:
                break
        if clock.spent():
            break
    return coder, decoder, loss_value, best_epoch


def _codes(
    coder: torch.nn.Sequential | torch.nn.Parameter, inputs: torch.Tensor, rows: torch.Tensor
) -> torch.Tensor:
    """Codes (B, k) of the samples ``rows`` (B,): encoded from their inputs, or their own."""
    import torch

    if isinstance(coder, torch.nn.Sequential):
        out: torch.Tensor = coder(inputs[rows])
        return out
    return coder[rows]


def _held_error(
    coder: torch.nn.Sequential | torch.nn.Parameter,
    decoder: torch.nn.Sequential,
    inputs: torch.Tensor,
    data: _Data,
    held: torch.Tensor,
) -> float:
    """Mean squared error (encoding) of the monitored samples on the held-out lights."""
    import torch

    with torch.no_grad():
        rows = data.monitor
        codes = _codes(coder, inputs, rows)
        out = _decoded(decoder, codes, data.features[held], data.shadows(rows, held))
        return float(torch.mean((out - data.values[rows][:, held]) ** 2))
