"""OpenLIME's neural relighting model fitted to a capture: a 9-value code per pixel, a decoder.

OpenLIME's ``neural`` layer (cnr-isti-vclab/openlime ``src/LayerNeuralRTI.js`` ``initialize``
and ``src/ShaderNeural.js`` ``fragShaderSrc``) relights with a fixed network: its input is a
pixel's code of 9 values (three RGB textures) followed by the light's ``x`` and ``y`` (the
light control's two numbers: the direction's components in the image plane, x right, y up),
11 values; two hidden dense layers of ``n`` units (``info.samples``; the shader's own
comments size them 49), each followed by ``elu(a) = a if a > 0 else exp(a) - 1``; and a
dense output layer of 3, with no activation, that is the pixel's colour: the 8-bit sRGB
value over 255 (the shader writes it to an 8-bit RGBA texture, so it is clamped to 0..1 and
rounded to a level before it is shown).

No RTI tool fits this model today, and the project's learned rung
(:mod:`processing.learned_rti`) has another architecture (codes of 16, Fourier features of the
light, a decoder of three layers of 64, a perceptual encoding of linear radiance). So
:mod:`processing.neural_rti_fit` fits OpenLIME's own: the decoder of exactly that shape and a
code per pixel, trained together (PyTorch; on a CUDA GPU when one is present, else the CPU) on
the capture's 8-bit values, with the loss the 8-bit PSNR measures (mean squared error of
value / 255).

This module is the fitted model, :class:`NeuralRTI`: it decodes and encodes in numpy, so
exporting and relighting never import PyTorch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from processing.learned_rti import _elu, _mlp

__all__ = ["CODE_SIZE", "HIDDEN", "Layers", "NeuralRTI"]

#: Values of each pixel's code: OpenLIME's ``planes``, read from three RGB textures.
CODE_SIZE = 9
#: Default hidden units of each of the decoder's two layers (``info.samples``), the width
#: ShaderNeural's comments give (its uniforms pad it to a multiple of 4).
HIDDEN = 49

Layers = tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]


@dataclass(frozen=True)
class NeuralRTI:
    """A fitted decoder of OpenLIME's shape and its codes, as numpy arrays.

    Attributes
    ----------
    decoder : tuple of three (weight (in, out), bias (out,)) float32 pairs: (11, n), (n, n),
        (n, 3); ELU after the first two. Input: the code, then the light's x and y
    encoder : tuple of (weight, bias) pairs, or () for free codes: (3 T', w), (w, w), (w, w),
        (w, 9) with ELU between, reading the pixel's 8-bit values / 255 under the T' trained
        lights (light-major, RGB within a light)
    codes : ndarray (N, 9) float32 or None, the free codes of the N pixels fitted (None with
        an encoder)
    lights : ndarray (T, 3) float32, the measured directions (camera frame)
    held : ndarray of int64, indices of the held-out lights (sorted; empty: none)
    seconds : float, fitting time (s)
    steps : int, Adam steps taken
    loss : float, final mean squared error (value / 255) on the trained lights
    device : str, where it was fitted ("cpu" or "cuda")
    """

    decoder: Layers
    encoder: Layers
    codes: NDArray[np.float32] | None
    lights: NDArray[np.float32]
    held: NDArray[np.int64]
    seconds: float
    steps: int
    loss: float
    device: str = "cpu"

    @property
    def hidden(self) -> int:
        """Units of each hidden layer of the decoder."""
        return int(self.decoder[0][0].shape[1])

    @property
    def trained(self) -> NDArray[np.int64]:
        """Indices of the lights fitted (every light not held out)."""
        return np.setdiff1d(np.arange(len(self.lights)), self.held).astype(np.int64)

    def decode(
        self, codes: NDArray[np.floating], lights: NDArray[np.floating]
    ) -> NDArray[np.float32]:
        """Colours (Q, N, 3) float32 of N codes (N, 9) under Q lights (Q, 2 or 3).

        The network's raw output: 8-bit sRGB value / 255, not clamped (the viewer clamps).
        Only the lights' x and y are read.
        """
        c = np.asarray(codes, dtype=np.float32).reshape(-1, CODE_SIZE)
        xy = np.asarray(lights, dtype=np.float32).reshape(len(lights), -1)[:, :2]
        (w1, b1), second, third = self.decoder
        from_codes = c @ w1[:CODE_SIZE] + b1  # (N, n), shared by every light
        from_lights = xy @ w1[CODE_SIZE:]  # (Q, n)
        out = np.empty((len(xy), len(c), 3), dtype=np.float32)
        for q in range(len(xy)):
            out[q] = _mlp((second, third), _elu(from_codes + from_lights[q]))
        return out

    def encode(self, levels: NDArray[np.integer], chunk: int = 65536) -> NDArray[np.float32]:
        """Codes (N, 9) float32 of N pixels from their 8-bit values (T, N, 3), by the encoder.

        Raises
        ------
        InputError
            A model of free codes (it codes only the pixels it was fitted on), or values of
            another number of lights.
        """
        if not self.encoder:
            raise InputError(
                "neural model: fitted with free codes, which code only the pixels fitted; "
                "fit with an encoder to code others"
            )
        v = np.asarray(levels)
        if v.ndim != 3 or v.shape[0] != len(self.lights) or v.shape[2] != 3:
            raise InputError(
                f"neural model: values must have shape ({len(self.lights)}, N, 3), got {v.shape}"
            )
        trained = self.trained
        out = np.empty((v.shape[1], CODE_SIZE), dtype=np.float32)
        for start in range(0, v.shape[1], chunk):
            rows = _rows(v[trained, start : start + chunk])
            out[start : start + len(rows)] = _mlp(self.encoder, rows)
        return out


def _rows(levels: NDArray[np.integer]) -> NDArray[np.float32]:
    """(T, N, 3) 8-bit values -> (N, 3 T) float32 / 255, one pixel a row (the encoder's input)."""
    return np.ascontiguousarray(
        levels.transpose(1, 0, 2).reshape(levels.shape[1], -1), dtype=np.float32
    ) * np.float32(1.0 / 255.0)
