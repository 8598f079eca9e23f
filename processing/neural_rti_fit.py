"""Fitting OpenLIME's neural model (:class:`processing.neural_rti.NeuralRTI`) to a capture.

The decoder of exactly OpenLIME's shape and a code per pixel are trained together (PyTorch; on a
CUDA GPU when one is present, else the CPU) on the capture's 8-bit values, with the loss the
8-bit PSNR measures (mean squared error of value / 255); :func:`tune_decoder` then fits the
decoder to the codes as the export stores them, and :func:`fit_codes` codes pixels the fit did
not see.

The codes are either optimised per pixel directly (free codes, started at each pixel's
principal-component scores, as the learned rung's auto-decoder is), which fits best, or made
by an encoder network from the pixel's measured values (neural RTI's encoder: three dense
layers, ELU), which is what a capture with more pixels than can be trained on needs: the
encoder codes every pixel afterwards, a block at a time, in numpy.

Held-out lights (``holdout``) are left out of the targets and of what the codes are made
from, so the error at them is the model's, not a memory of the images.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
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
from processing.neural_rti import CODE_SIZE, HIDDEN, Layers, NeuralRTI

if TYPE_CHECKING:  # imported when fitting: decoding never needs it
    import torch

__all__ = ["ENCODER_WIDTH", "NeuralSettings", "fit_codes", "fit_neural_rti", "tune_decoder"]

#: Hidden units of each of the encoder's three layers (the codes of captures too large to
#: give every pixel its own code).
ENCODER_WIDTH = 64

#: Largest gradient norm of a step (of all the parameters trained together).
CLIP = 1.0


@dataclass(frozen=True)
class NeuralSettings:
    """How :func:`fit_neural_rti` fits.

    Attributes
    ----------
    hidden : int, units of each of the decoder's two hidden layers (``info.samples``)
    max_seconds : float, the fit stops after this long (s) even with steps left
    steps : int, most Adam steps
    batch : int, pixels per step
    lights_per_step : int or None, trained lights each step's pixels are fitted under (a
        random subset: a step's cost grows with pixels x lights, and the codes learn from
        how many steps see them); None: every trained light
    rate : float, initial learning rate of the networks (cosine decay to a tenth over the
        steps or the seconds, whichever runs out first)
    code_rate : float, initial learning rate of free codes (the same decay): each code is
        stepped only when its pixel is drawn, so it is given larger steps
    encoder_rate : float, initial learning rate of the encoder (the same decay)
    holdout : float, share of the lights held out (0 to 0.5; spread over the dome,
        :func:`processing.network_training.validation_lights`)
    encoder : bool, codes made by an encoder network from the pixel's 8-bit values (to code
        pixels not trained on) instead of optimised per pixel
    encoder_width : int, hidden units of each of the encoder's three layers
    seed : int
    threads : int or None, PyTorch CPU threads (None: the cores idle when the fit starts)
    device : "auto" (CUDA when available), "cpu" or "cuda"
    """

    hidden: int = HIDDEN
    max_seconds: float = 60.0
    steps: int = 1_000_000
    batch: int = 128
    lights_per_step: int | None = 64
    rate: float = 1e-2
    code_rate: float = 1e-1
    encoder_rate: float = 1e-2
    holdout: float = 0.0
    encoder: bool = False
    encoder_width: int = ENCODER_WIDTH
    seed: int = 0
    threads: int | None = None
    device: Device = "auto"

    def __post_init__(self) -> None:
        check_settings(
            self,
            model="neural",
            counts=("hidden", "steps", "batch", "encoder_width"),
            share="holdout",
            also=(
                (
                    math.isfinite(self.max_seconds) and self.max_seconds > 0,
                    f"time budget {self.max_seconds} s must be positive",
                ),
                (
                    self.rate > 0 and self.code_rate > 0 and self.encoder_rate > 0,
                    "the learning rates must be positive",
                ),
            ),
        )


def _checked(levels: NDArray[np.integer], lights: NDArray[np.floating]) -> NDArray[np.float32]:
    """The lights (T, 3) float32, once the values (T, N, 3) are checked against them."""
    directions = np.asarray(lights, dtype=np.float32)
    if directions.ndim != 2 or directions.shape[1] != 3 or len(directions) < 3:
        raise InputError(
            f"neural model: lights must have shape (T >= 3, 3), got {directions.shape}"
        )
    v = np.asarray(levels)
    if v.ndim != 3 or v.shape[0] != len(directions) or v.shape[2] != 3 or v.shape[1] < 1:
        raise InputError(
            f"neural model: 8-bit values must have shape ({len(directions)}, N >= 1, 3), "
            f"got {v.shape}"
        )
    if v.dtype != np.uint8:
        raise InputError(f"neural model: values must be 8-bit (uint8), got {v.dtype}")
    return directions


def fit_neural_rti(
    levels: NDArray[np.uint8],
    lights: NDArray[np.floating],
    settings: NeuralSettings = NeuralSettings(),
    progress: Callable[[int, int], None] | None = None,
) -> NeuralRTI:
    """Fit OpenLIME's decoder and the codes of N pixels to their 8-bit values.

    Parameters
    ----------
    levels : ndarray, shape (T, N, 3), uint8, each pixel's 8-bit sRGB values under T lights
    lights : ndarray, shape (T, 3), unit light directions, camera frame (x right, y up,
        z toward the camera): the decoder reads x and y
    settings : NeuralSettings
    progress : callable(step, planned), optional, called after each step

    Returns
    -------
    NeuralRTI

    Raises
    ------
    InputError
        Shapes that do not match, values not 8-bit, fewer than three lights, PyTorch missing,
        or a CUDA device asked for and not present.
    """
    directions = _checked(levels, lights)
    held = validation_lights(directions, settings.holdout, seed=settings.seed)
    trained = np.setdiff1d(np.arange(len(directions)), held)
    _require_torch()
    import torch

    device = training_device(settings.device)
    if device == "cpu":
        torch.set_num_threads(settings.threads or idle_cores())
    torch.manual_seed(settings.seed)
    values = np.ascontiguousarray(np.asarray(levels)[trained].transpose(1, 0, 2))  # (N, T', 3)
    coder: torch.nn.Sequential | torch.nn.Parameter
    if settings.encoder:
        width = settings.encoder_width
        coder = torch_mlp([3 * len(trained), width, width, width, CODE_SIZE]).to(device)
        parameters = list(coder.parameters())
    else:
        measured = values.transpose(1, 0, 2).astype(np.float32) * np.float32(1.0 / 255.0)
        start = principal_codes(measured, CODE_SIZE, settings.seed)
        coder = torch.nn.Parameter(torch.from_numpy(start).to(device))
        parameters = [coder]
    decoder = torch_mlp([CODE_SIZE + 2, settings.hidden, settings.hidden, 3]).to(device)
    own = settings.encoder_rate if isinstance(coder, torch.nn.Sequential) else settings.code_rate
    groups = [
        {"params": list(decoder.parameters()), "lr": settings.rate},
        {"params": parameters, "lr": own},
    ]
    loss, steps, seconds = _train(
        coder, decoder, groups, values, directions[trained], settings, device, progress
    )
    codes = None
    encoder: Layers = ()
    if isinstance(coder, torch.nn.Sequential):
        encoder = numpy_layers(coder)
    else:
        codes = coder.detach().cpu().numpy().astype(np.float32)
    return NeuralRTI(
        decoder=numpy_layers(decoder),
        encoder=encoder,
        codes=codes,
        lights=directions,
        held=held,
        seconds=seconds,
        steps=steps,
        loss=loss,
        device=device,
    )


def tune_decoder(
    model: NeuralRTI,
    codes: NDArray[np.floating],
    levels: NDArray[np.uint8],
    settings: NeuralSettings,
) -> NeuralRTI:
    """The model with its decoder trained further on fixed codes (the codes as stored).

    The export writes the codes as 8-bit planes (JPEG or PNG); the decoder, written last into
    ``info.json``, is then fitted to the codes the viewer will read, so most of what the
    quantisation and the compression moved is taken back. Held-out lights stay out.

    Parameters
    ----------
    model : NeuralRTI
    codes : ndarray, shape (N, 9), the codes of N pixels as the viewer reads them
    levels : ndarray, shape (T, N, 3), uint8, those pixels' 8-bit values
    settings : NeuralSettings, the budget (``max_seconds``, ``steps``), rate, device, threads

    Returns
    -------
    NeuralRTI, the same codes and encoder, the tuned decoder; ``seconds`` and ``steps`` add
    the tuning's
    """
    directions = _checked(levels, model.lights)
    c = np.asarray(codes, dtype=np.float32)
    if c.shape != (np.asarray(levels).shape[1], CODE_SIZE):
        raise InputError(f"neural model: codes must have shape (N, {CODE_SIZE}), got {c.shape}")
    _require_torch()
    import torch

    device = training_device(settings.device)
    if device == "cpu":
        torch.set_num_threads(settings.threads or idle_cores())
    torch.manual_seed(settings.seed)
    trained = model.trained
    decoder = _loaded_decoder(model).to(device)
    fixed = torch.from_numpy(c).to(device)
    values = np.ascontiguousarray(np.asarray(levels)[trained].transpose(1, 0, 2))
    groups = [{"params": list(decoder.parameters()), "lr": settings.rate}]
    loss, steps, seconds = _train(
        fixed, decoder, groups, values, directions[trained], settings, device
    )
    return NeuralRTI(
        decoder=numpy_layers(decoder),
        encoder=model.encoder,
        codes=model.codes,
        lights=model.lights,
        held=model.held,
        seconds=model.seconds + seconds,
        steps=model.steps + steps,
        loss=loss,
        device=device,
    )


def fit_codes(
    model: NeuralRTI,
    levels: NDArray[np.uint8],
    settings: NeuralSettings,
    start: NDArray[np.floating] | None = None,
) -> NDArray[np.float32]:
    """Codes (N, 9) float32 fitted to N pixels' 8-bit values (T, N, 3), the decoder fixed.

    What a pixel the model was not fitted on needs (the export's code of black, for pixels
    outside the object), with the budget and the ``code_rate`` of ``settings``; held-out
    lights stay out. ``start``: the codes to start from (default: the mean of the model's
    free codes, or zeros).
    """
    directions = _checked(levels, model.lights)
    count = np.asarray(levels).shape[1]
    if start is None:
        centre = model.codes.mean(axis=0) if model.codes is not None else np.zeros(CODE_SIZE)
        start = np.tile(centre, (count, 1))
    _require_torch()
    import torch

    device = training_device(settings.device)
    if device == "cpu":
        torch.set_num_threads(settings.threads or idle_cores())
    torch.manual_seed(settings.seed)
    decoder = _loaded_decoder(model).to(device)
    decoder.requires_grad_(False)
    codes = torch.nn.Parameter(torch.from_numpy(np.asarray(start, np.float32).copy()).to(device))
    trained = model.trained
    values = np.ascontiguousarray(np.asarray(levels)[trained].transpose(1, 0, 2))
    groups = [{"params": [codes], "lr": settings.code_rate}]
    _train(codes, decoder, groups, values, directions[trained], settings, device)
    return codes.detach().cpu().numpy().astype(np.float32)


def _loaded_decoder(model: NeuralRTI) -> torch.nn.Sequential:
    """The model's decoder as a PyTorch network (11 -> n -> n -> 3, ELU between)."""
    import torch

    decoder = torch_mlp([CODE_SIZE + 2, model.hidden, model.hidden, 3])
    with torch.no_grad():
        linear = [m for m in decoder if isinstance(m, torch.nn.Linear)]
        for module, (weight, bias) in zip(linear, model.decoder, strict=True):
            module.weight.copy_(torch.from_numpy(weight.T.copy()))
            module.bias.copy_(torch.from_numpy(bias))
    return decoder


def _require_torch() -> None:
    """Refuse clearly when PyTorch (the ``learned`` extra) is not installed."""
    try:
        import torch  # noqa: F401
    except ImportError as exc:
        raise InputError(
            "the neural export needs PyTorch: pip install -e '.[learned]' (make test does)"
        ) from exc


def _train(
    coder: torch.nn.Sequential | torch.Tensor,
    decoder: torch.nn.Sequential,
    groups: list[dict[str, Any]],
    values: NDArray[np.uint8],
    lights: NDArray[np.float32],
    settings: NeuralSettings,
    device: str,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[float, int, float]:
    """Adam on ``groups`` (parameters, initial ``lr``) until the steps or the seconds run out.

    Returns (the last step's loss, steps taken, seconds).

    ``coder``: an encoder (reads a pixel's row of values), or a tensor (N, 9) of codes, one
    per pixel (free codes when they are among ``groups``). ``values``: (N, T', 3) uint8 at
    the T' ``lights`` trained on.
    """
    import torch

    count = values.shape[0]
    targets = torch.from_numpy(values).to(device)  # 8-bit kept: a quarter of float32's memory
    xy = torch.from_numpy(np.ascontiguousarray(lights[:, :2])).to(device)
    optimiser = adam(groups)
    trainable = [p for group in groups for p in group["params"]]
    initial = [group["lr"] for group in optimiser.param_groups]
    generator = torch.Generator().manual_seed(settings.seed)
    first = decoder[0]
    assert isinstance(first, torch.nn.Linear)
    per_step = min(settings.lights_per_step or len(lights), len(lights))
    start = time.perf_counter()
    step, loss_value = 0, math.nan
    while step < settings.steps:
        order = torch.randperm(count, generator=generator).to(device)
        for begin in range(0, count, settings.batch):
            elapsed = time.perf_counter() - start
            if step >= settings.steps or elapsed >= settings.max_seconds:
                return loss_value, step, elapsed
            # Cosine decay by steps or by time, whichever is further along: the rate ends
            # low whichever cap ends the fit (a busy machine takes longer per step).
            done = min(1.0, max(step / settings.steps, elapsed / settings.max_seconds))
            for group, rate in zip(optimiser.param_groups, initial, strict=True):
                group["lr"] = rate * (0.1 + 0.45 * (1 + math.cos(math.pi * done)))
            rows = order[begin : begin + settings.batch]
            measured = targets[rows].to(torch.float32) / 255.0  # (B, T', 3)
            if isinstance(coder, torch.nn.Sequential):
                codes = coder(measured.reshape(len(rows), -1))
            else:
                codes = coder[rows]
            seen = torch.randperm(len(lights), generator=generator)[:per_step].to(device)
            target = measured[:, seen]
            # The first layer applied in two parts, codes and lights, then broadcast: the
            # same as first(cat(code, light)) for every pair, at a fraction of the cost.
            hidden = (codes @ first.weight[:, :CODE_SIZE].T + first.bias)[:, None, :] + (
                xy[seen] @ first.weight[:, CODE_SIZE:].T
            )[None, :, :]
            predicted = decoder[1:](hidden)
            loss = torch.mean((predicted - target) ** 2)
            optimiser.zero_grad()
            loss.backward()  # type: ignore[no-untyped-call]
            # A step larger than CLIP is cut to it: without, a rare step threw a fit that had
            # reached 28 dB back to a pixel's mean (measured on the bundled capture).
            torch.nn.utils.clip_grad_norm_(trainable, CLIP)
            optimiser.step()
            loss_value = float(loss.detach())
            step += 1
            if progress is not None:
                # The steps the time budget allows at the pace so far, if fewer than the cap.
                pace = step / max(time.perf_counter() - start, 1e-9)
                progress(step, max(step, min(settings.steps, int(pace * settings.max_seconds))))
    return loss_value, step, time.perf_counter() - start
