"""A learned relightable model: a code per sample and one small decoder shared by the object.

The class of neural RTI (Dulecha, Fanni, Ponchio, Pellacini, Giachetti: "Neural reflectance
transformation imaging", The Visual Computer 2020): an encoder reads every measured value of a
sample (its T lights, RGB) into a short code; a decoder maps (code, light direction) to the
sample's colour under that light. Both are small fully connected networks, trained together on
the capture itself, so the decoder learns the object's own family of responses (its highlights,
shadows and interreflections) instead of assuming one.

Training uses PyTorch (on a CUDA GPU when one is present, else the CPU): automatic gradients
and Adam on small dense layers are what it is built for, and its CPU build is the one
machine-learning library this machine carries. Inference is plain numpy (a few matrix
products), so relighting never imports PyTorch and a trained model is a handful of arrays.

What limited the rung, measured by ``bench/learned_study.py`` and scratch runs on path-traced
RTI domes (49 lights, 8-bit sRGB JPEG) and the bundled real capture:

- optimisation: 2,000 steps of 256 samples x 32 lights stop far short of convergence (train
  error close to the held-out error, both falling): every step now trains on all T lights
  of its samples and training runs for passes over the samples (``epochs``);
- the encoder: mapping 3T measured values to a code is what the network learns slowest. By
  default each trained sample's code is optimised directly (an "auto-decoder", as the model
  only relights its own capture), started at the sample's principal-component scores;
  training error then falls 4-10 times lower for the same steps and the held-out error
  follows (``encoder=True`` restores neural RTI's encoder);
- the light encoding: Fourier features of the direction (``d``, ``sin``/``cos`` of
  ``2^f pi d``) let the small decoder follow sharp shadow edges and highlights;
- capacity (decoder 128 wide, codes of 16) changed little with an encoder.

Held-out lights (``validation``) can choose the number of passes: a spread share of the
lights is removed from the codes' input and the targets, the held-out error is recorded per
pass, training stops when it has not improved for ``patience`` passes, and the model is
trained again on every light for the chosen passes. It is off by default: a held-out light
of the dome leaves a gap about twice as wide as the ones relighting fills, and its error
turned up while the test error was still falling (stopping there cost about 1 dB).

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
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

if TYPE_CHECKING:  # imported when training: relighting never needs it
    import torch

__all__ = [
    "CODE_SIZE",
    "DECODER_LAYERS",
    "DECODER_WIDTH",
    "ENCODER_WIDTH",
    "GAMMA",
    "LIGHT_FREQUENCIES",
    "EpochRecord",
    "LearnedRTI",
    "TrainingSettings",
    "light_features",
    "train_learned_rti",
    "validation_lights",
]

#: Default length of each sample's code (neural RTI used 9); a model's own is ``model.code_size``.
CODE_SIZE = 16
#: Hidden units of the encoder's three layers and of each of the decoder's layers.
ENCODER_WIDTH = 150
DECODER_WIDTH = 64
#: Hidden layers of the decoder.
DECODER_LAYERS = 3
#: Octaves of Fourier features of the light direction the decoder reads (0: the raw ``d``).
LIGHT_FREQUENCIES = 2
#: Exponent of the perceptual encoding the networks read and write.
GAMMA = 2.2
#: Percentile of the measured values that maps to 1 in the encoding.
SCALE_PERCENTILE = 99.5
#: Samples the per-pass errors are measured on (a fixed random subset: cheap and stable).
MONITOR_SAMPLES = 4096

Device = Literal["auto", "cpu", "cuda"]


@dataclass(frozen=True)
class TrainingSettings:
    """How a :class:`LearnedRTI` is trained.

    Attributes
    ----------
    steps : int, most Adam steps in all (both phases): a hard cap
    batch : int, samples per step
    lights_per_step : int or None, lights the decoder is trained on per step (a random
        subset); None: all of them
    rate : float, initial learning rate (cosine decay to ``rate / 10`` over each phase, by
        its planned steps or its share of ``max_seconds``, whichever runs out first)
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
    lights_per_step: int | None = None
    rate: float = 1e-2
    max_samples: int = 200_000
    max_seconds: float = 170.0
    seed: int = 0
    epochs: int = 100
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
        for name in (
            "steps",
            "batch",
            "max_samples",
            "epochs",
            "patience",
            "code_size",
            "encoder_width",
            "decoder_width",
            "decoder_layers",
        ):
            if getattr(self, name) < 1:
                raise InputError(f"learned model: {name} must be at least 1")
        for name in ("lights_per_step", "threads"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise InputError(f"learned model: {name} must be at least 1 (or None)")
        if self.light_frequencies < 0:
            raise InputError("learned model: light_frequencies must be 0 or more")
        if not self.rate > 0 or not self.max_seconds > 0:
            raise InputError("learned model: rate and max_seconds must be positive")
        if not 0.0 <= self.validation < 0.5:
            raise InputError(
                f"learned model: validation is the share of lights held out, in [0, 0.5); "
                f"got {self.validation}"
            )
        if self.device not in ("auto", "cpu", "cuda"):
            raise InputError(f"learned model: device must be auto, cpu or cuda, not {self.device}")


@dataclass(frozen=True)
class EpochRecord:
    """One pass over the samples.

    Attributes
    ----------
    phase : "choose" (lights held out) or "final" (every light)
    epoch : int, passes so far in this phase
    seconds : float, since training began
    train_error : float, mean squared error in the encoding on the lights trained on
    validation_error : float, the same on the held-out lights (NaN in the final phase)
    """

    phase: str
    epoch: int
    seconds: float
    train_error: float
    validation_error: float


@dataclass(frozen=True)
class LearnedRTI:
    """A trained encoder and decoder, as numpy arrays.

    Attributes
    ----------
    lights : ndarray, shape (T, 3), the measured light directions the encoder reads, in the
        frame the model was trained in (camera frame for pixels, rig frame for points)
    encoder, decoder : tuple of (weight (in, out), bias (out,)) float32 pairs; ELU between
        layers, none after the last. The decoder reads the code, then the light's features
        (:func:`light_features`). No encoder layers: the codes are ``codes``
    scale : float, the linear value encoded as 1
    seconds : float, training time (both phases)
    steps : int, steps taken (both phases)
    loss : float, final training loss (mean squared error in the encoding)
    light_frequencies : int, octaves of the light features the decoder reads
    history : tuple of EpochRecord, the per-pass errors of both phases
    epochs : int, passes of the final fit (chosen on held-out lights when there were any)
    device : str, where it was trained ("cpu" or "cuda")
    codes : ndarray (M, code_size) float32 or None, the optimised codes of the M samples
        trained on (a model without an encoder)
    coded : ndarray (M, 3T) float32 or None, those samples' encoded values, one row each
        (how :meth:`encode` finds a sample's code)
    """

    lights: NDArray[np.float32]
    encoder: tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]
    decoder: tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]
    scale: float
    seconds: float
    steps: int
    loss: float
    light_frequencies: int = 0
    history: tuple[EpochRecord, ...] = ()
    epochs: int = 0
    device: str = "cpu"
    codes: NDArray[np.float32] | None = None
    coded: NDArray[np.float32] | None = None

    @property
    def code_size(self) -> int:
        """Length of each sample's code."""
        if self.codes is not None:
            return int(self.codes.shape[1])
        return int(self.encoder[-1][0].shape[1])

    @property
    def validation_error(self) -> float:
        """Best held-out error of the choice (NaN without held-out lights)."""
        errors = [r.validation_error for r in self.history if r.phase == "choose"]
        return min(errors) if errors else math.nan

    def encode(self, values: NDArray[np.floating], chunk: int = 65536) -> NDArray[np.float32]:
        """Codes (N, ``code_size``) float32 of N samples' measured values (T, N, 3), linear.

        Without an encoder, a sample trained on gets its own optimised code (found by its
        values); any other gets the code of the trained sample whose encoded values are
        nearest (least squares), as a sample left out of training (``max_samples``) would
        be relit like its most similar neighbour.
        """
        values = _checked_values(values, len(self.lights))
        codes = np.empty((values.shape[1], self.code_size), dtype=np.float32)
        if self.codes is not None and self.coded is not None:
            own = {row.tobytes(): i for i, row in enumerate(self.coded)}
            norms = np.einsum("ij,ij->i", self.coded, self.coded)
        for start in range(0, values.shape[1], chunk):
            block = _encoder_input(_encoded(values[:, start : start + chunk], self.scale))
            if self.codes is None or self.coded is None:
                codes[start : start + chunk] = _mlp(self.encoder, block)
                continue
            found = np.array([own.get(row.tobytes(), -1) for row in block], dtype=np.int64)
            missing = np.flatnonzero(found < 0)
            for part in np.array_split(missing, max(1, -(-missing.size // 1024))):
                if part.size:
                    distance = norms[None, :] - 2.0 * block[part] @ self.coded.T
                    found[part] = np.argmin(distance, axis=1)
            codes[start : start + chunk] = self.codes[found]
        return codes

    def decode(
        self, codes: NDArray[np.floating], directions: NDArray[np.floating]
    ) -> NDArray[np.float32]:
        """Linear values (Q, N, 3) float32 of N coded samples (N, code) under Q lights (Q, 3)."""
        codes = np.asarray(codes, dtype=np.float32)
        k = self.code_size
        if codes.ndim != 2 or codes.shape[1] != k:
            raise InputError(f"learned model: codes must have shape (N, {k}), got {codes.shape}")
        d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
        features = light_features(d, self.light_frequencies)
        (weight, bias), rest = self.decoder[0], self.decoder[1:]
        # The first layer is linear in (code, features): the code's part is computed once.
        from_codes = codes @ weight[:k] + bias
        from_lights = features @ weight[k:]
        out = np.empty((len(d), len(codes), 3), dtype=np.float32)
        for q in range(len(d)):
            hidden = from_codes + from_lights[q]
            y = _mlp(rest, _elu(hidden)) if rest else hidden
            out[q] = self.scale * np.maximum(y, 0.0) ** GAMMA
        return out


def light_features(directions: NDArray[np.floating], frequencies: int) -> NDArray[np.float32]:
    """What the decoder reads of light directions (Q, 3): (Q, 3 + 6 ``frequencies``) float32.

    ``d`` itself, then ``sin(2^f pi d)`` and ``cos(2^f pi d)`` for f = 0 .. frequencies - 1
    (per component).
    """
    d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    parts = [d]
    for f in range(frequencies):
        angle = np.float32(math.pi * 2.0**f) * d
        parts += [np.sin(angle), np.cos(angle)]
    return np.ascontiguousarray(np.concatenate(parts, axis=1), dtype=np.float32)


def validation_lights(
    directions: NDArray[np.floating], share: float, *, seed: int = 0
) -> NDArray[np.int64]:
    """Indices (sorted, int64) of about ``share`` of the T lights (T, 3), spread over the dome.

    Farthest-point picks: no two held-out lights are neighbours, so each leaves a gap about
    one light spacing wide, like the gaps between measured lights that relighting fills. At
    least 2 lights stay in and, when ``share`` > 0, at least 1 is held out.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    count = min(len(d) - 2, max(1, round(share * len(d)))) if share > 0 else 0
    if count <= 0:
        return np.zeros(0, dtype=np.int64)
    first = int(np.random.default_rng(seed).integers(len(d)))
    chosen = [first]
    distance = np.linalg.norm(d - d[first], axis=1)
    while len(chosen) < count:
        nxt = int(np.argmax(distance))
        chosen.append(nxt)
        distance = np.minimum(distance, np.linalg.norm(d - d[nxt], axis=1))
    return np.sort(np.asarray(chosen, dtype=np.int64))


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

    Raises
    ------
    InputError
        Shapes that do not match, fewer than two lights, no bright value, PyTorch missing, or
        a CUDA device asked for and not present.
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
    device = _device(settings.device)
    if device == "cpu":
        torch.set_num_threads(settings.threads or _idle_cores())

    rng = np.random.default_rng(settings.seed)
    n = v.shape[1]
    chosen = np.sort(rng.choice(n, size=min(n, settings.max_samples), replace=False))
    data = _Data(_encoded(v[:, chosen], scale), directions, settings, device)
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
        encoder, codes, coded = _numpy_layers(coder), None, None
    else:
        encoder = ()
        codes = coder.detach().cpu().numpy().astype(np.float32)
        coded = _encoder_input(_encoded(v[:, chosen], scale))
    return LearnedRTI(
        lights=directions,
        encoder=encoder,
        decoder=_numpy_layers(decoder),
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
    )


def _idle_cores() -> int:
    """Cores no other process keeps busy (1-minute load average), at least 1.

    PyTorch's CPU threads wait for each other at every layer: on cores other processes also
    use, two threads measured 6 to 9 times slower than one, while on idle cores one thread
    is at most twice as slow as two.
    """
    cores = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except OSError:  # not reported on this system
        return 1
    return max(1, min(cores, math.floor(cores - load)))


def _device(asked: Device) -> str:
    import torch

    available = torch.cuda.is_available()
    if asked == "cuda" and not available:
        raise InputError("learned model: device 'cuda' asked for, but PyTorch sees no CUDA GPU")
    return "cuda" if asked == "cuda" or (asked == "auto" and available) else "cpu"


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
        self.start_codes = _principal_codes(encoded, settings.code_size, settings.seed)
        monitor = np.random.default_rng(settings.seed + 1).permutation(self.count)
        self.monitor = torch.from_numpy(np.sort(monitor[:MONITOR_SAMPLES])).to(device)


def _networks(
    settings: TrainingSettings, lights: int, start_codes: NDArray[np.float32]
) -> tuple[torch.nn.Sequential | torch.nn.Parameter, torch.nn.Sequential]:
    """The coder (an encoder network, or free codes starting at ``start_codes``) and decoder."""
    import torch

    k = settings.code_size
    features = 3 + 6 * settings.light_frequencies
    coder: torch.nn.Sequential | torch.nn.Parameter
    if settings.encoder:
        coder = _torch_mlp([3 * lights, *[settings.encoder_width] * 3, k])
    else:
        coder = torch.nn.Parameter(torch.from_numpy(start_codes))
    decoder = _torch_mlp([k + features, *[settings.decoder_width] * settings.decoder_layers, 3])
    return coder, decoder


def _principal_codes(encoded: NDArray[np.float32], k: int, seed: int) -> NDArray[np.float32]:
    """Starting free codes (N, k) float32: each sample's first k principal-component scores.

    Free codes move about one learning rate per pass, so from small random values they need
    a hundred passes to spread; the principal scores (of the encoded values, scaled to a
    standard deviation of 0.5 along the first component) already tell samples apart.
    """
    rows = _encoder_input(encoded).astype(np.float64)
    rng = np.random.default_rng(seed)
    basis_rows = rows[rng.permutation(len(rows))[:20000]]
    mean = basis_rows.mean(axis=0)
    _, _, vt = np.linalg.svd(basis_rows - mean, full_matrices=False)
    scores = np.zeros((len(rows), k))
    used = min(k, vt.shape[0])
    scores[:, :used] = (rows - mean) @ vt[:used].T
    spread = float(np.std(scores[:, 0])) if len(rows) > 1 else 0.0
    scores *= 0.5 / spread if spread > 0 else 1.0
    return scores.astype(np.float32)


def _decoded(
    decoder: torch.nn.Sequential, codes: torch.Tensor, features: torch.Tensor
) -> torch.Tensor:
    """Decoder outputs (B, Q, 3) of codes (B, k) under light features (Q, F)."""
    import torch

    first = decoder[0]
    assert isinstance(first, torch.nn.Linear)
    k = codes.shape[1]
    # Same as first(cat(code, feature)) for every pair, at a fraction of the cost.
    hidden = (codes @ first.weight[:, :k].T + first.bias)[:, None, :] + (
        features @ first.weight[:, k:].T
    )[None, :, :]
    out: torch.Tensor = decoder[1:](hidden)
    return out


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
    coder, decoder = _networks(settings, data.lights, data.start_codes)
    decoder.to(data.device)
    if isinstance(coder, torch.nn.Sequential):
        coder.to(data.device)
        parameters = [*coder.parameters(), *decoder.parameters()]
    else:
        coder = torch.nn.Parameter(coder.detach().to(data.device))
        parameters = [coder, *decoder.parameters()]
    optimiser = torch.optim.Adam(parameters, lr=settings.rate)
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
            for group in optimiser.param_groups:
                group["lr"] = settings.rate * (0.1 + 0.45 * (1 + math.cos(math.pi * min(done, 1))))
            codes = _codes(coder, inputs, rows)
            predicted = _decoded(decoder, codes, data.features[seen])
            loss = torch.mean((predicted - data.values[rows][:, seen]) ** 2)
            optimiser.zero_grad()
            loss.backward()  # type: ignore[no-untyped-call]
            optimiser.step()
            loss_value = float(loss.detach())
            clock.tick()
        train_error, held_error = _errors(coder, decoder, inputs, data, trained_t, held_t)
        history.append(EpochRecord(phase, epoch, clock.seconds(), train_error, held_error))
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


def _errors(
    coder: torch.nn.Sequential | torch.nn.Parameter,
    decoder: torch.nn.Sequential,
    inputs: torch.Tensor,
    data: _Data,
    trained: torch.Tensor,
    held: torch.Tensor,
) -> tuple[float, float]:
    """Mean squared errors (encoding) of the monitored samples on trained and held lights."""
    import torch

    with torch.no_grad():
        rows = data.monitor
        codes = _codes(coder, inputs, rows)
        target = data.values[rows]
        train = float(
            torch.mean((_decoded(decoder, codes, data.features[trained]) - target[:, trained]) ** 2)
        )
        if held.numel() == 0:
            return train, math.nan
        out = _decoded(decoder, codes, data.features[held])
        return train, float(torch.mean((out - target[:, held]) ** 2))


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
            np.ascontiguousarray(module.weight.detach().cpu().numpy().T, dtype=np.float32),
            module.bias.detach().cpu().numpy().astype(np.float32),
        )
        for module in network
        if isinstance(module, torch.nn.Linear)
    )
