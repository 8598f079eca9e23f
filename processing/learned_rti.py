"""A learned relightable model: a code per sample and one small decoder shared by the object.

The class of neural RTI (Dulecha, Fanni, Ponchio, Pellacini, Giachetti: "Neural reflectance
transformation imaging", The Visual Computer 2020): an encoder reads every measured value of a
sample (its T lights, RGB) into a short code; a decoder maps (code, light direction) to the
sample's colour under that light. Both are small fully connected networks, trained together on
the capture itself (:func:`processing.learned_rti_training.train_learned_rti`), so the decoder
learns the object's own family of responses (its highlights, shadows and interreflections)
instead of assuming one.

This module is the trained model, :class:`LearnedRTI`: its inference is plain numpy (a few
matrix products), so relighting never imports PyTorch and a trained model is a handful of
arrays.

A model may be told each sample's visibility of each light (``shadowed``): the decoder then
gives two colours, the sample lit and in shadow, mixed by the visibility, so the network does
not have to learn where a cast shadow falls between the measured lights, only what it looks
like; the visibility comes from elsewhere (a relief's shadows, :mod:`render.prediction_methods`).

Values are learned in a perceptual encoding, ``(x / scale) ** (1 / GAMMA)``, as RTI tools learn
8-bit images: the loss then weighs dark and bright regions as the PSNR on 8-bit sRGB does, and
a highlight cannot own the fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

__all__ = [
    "CODE_SIZE",
    "DECODER_LAYERS",
    "DECODER_WIDTH",
    "ENCODER_WIDTH",
    "GAMMA",
    "LIGHT_FREQUENCIES",
    "EpochRecord",
    "LearnedRTI",
    "light_features",
    "shaded",
]

ArrayT = TypeVar("ArrayT", bound=Any)

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


@dataclass(frozen=True)
class EpochRecord:
    """One pass over the samples.

    Attributes
    ----------
    phase : "choose" (lights held out) or "final" (every light)
    epoch : int, passes so far in this phase
    seconds : float, since training began
    train_error : float, mean squared error in the encoding of the pass's steps (each on the
        lights it trained on, as the pass went)
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
    shadowed : bool, the decoder gives the colour lit and in shadow (six outputs), mixed by
        the visibility :meth:`decode` is given
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
    shadowed: bool = False

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
        self,
        codes: NDArray[np.floating],
        directions: NDArray[np.floating],
        visibility: NDArray[np.floating] | None = None,
    ) -> NDArray[np.float32]:
        """Linear values (Q, N, 3) float32 of N coded samples (N, code) under Q lights (Q, 3).

        ``visibility`` (Q, N), 1 lit and 0 in shadow: required by a ``shadowed`` model only.
        """
        codes = np.asarray(codes, dtype=np.float32)
        k = self.code_size
        if codes.ndim != 2 or codes.shape[1] != k:
            raise InputError(f"learned model: codes must have shape (N, {k}), got {codes.shape}")
        d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
        if self.shadowed != (visibility is not None):
            raise InputError(
                "learned model: a visibility goes with a model trained with one, and only then"
            )
        v = None if visibility is None else np.asarray(visibility, dtype=np.float32)
        if v is not None and v.shape != (len(d), len(codes)):
            raise InputError(
                f"learned model: visibility must have shape ({len(d)}, {len(codes)}), got {v.shape}"
            )
        features = light_features(d, self.light_frequencies)
        (weight, bias), rest = self.decoder[0], self.decoder[1:]
        # The first layer is linear in (code, features): the code's part is computed once.
        from_codes = codes @ weight[:k] + bias
        from_lights = features @ weight[k:]
        out = np.empty((len(d), len(codes), 3), dtype=np.float32)
        for q in range(len(d)):
            hidden = from_codes + from_lights[q]
            y = _mlp(rest, _elu(hidden)) if rest else hidden
            if v is not None:
                y = shaded(y, v[q])
            out[q] = self.scale * np.maximum(y, 0.0) ** GAMMA
        return out


def shaded(outputs: ArrayT, visibility: ArrayT) -> ArrayT:
    """A shadowed decoder's colour (..., 3) from its outputs (..., 6) and visibility (...).

    The first three outputs are the colour lit, the last three in shadow; numpy arrays or
    PyTorch tensors (training uses the same mixing).
    """
    v = visibility[..., None]
    mixed: ArrayT = v * outputs[..., :3] + (1 - v) * outputs[..., 3:]
    return mixed


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
