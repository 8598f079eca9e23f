"""OpenLIME's ``neural`` layer: a code of 9 values per pixel in three images, and a decoder.

Format facts, as OpenLIME's source defines them (cnr-isti-vclab/openlime
``src/LayerNeuralRTI.js``: the constructor, ``initialize``; ``src/ShaderNeural.js``:
``fragShaderSrc``, the uniforms; the layouts' ``imageUrl``):

- The planes: ``plane_1``, ``plane_2``, ``plane_3`` (the layer asks the layout for these
  three names; there is no ``plane_0``): ``plane_{j+1}`` holds code values 3j, 3j + 1,
  3j + 2 as its R, G and B. The ``image`` layout asks for ``plane_N.jpg``; ``deepzoom`` for
  ``plane_N.dzi`` (PNG planes load only as tiles; :mod:`render.web_export.tiles`).
- Dequantisation: ``code = byte / 255 * (max - min) + min`` per image and channel, with
  ``info.min`` and ``info.max`` three RGB triples (``[[r, g, b], ...]``, flattened by the
  layer), so each code value errs by ``(max - min) / 510`` at most (PNG).
- The network: input ``(code 0..8, light x, light y)``, padded with zeros to ``c = 12``;
  ``elu(W1 input + b1)``, ``elu(W2 . + b2)``, ``W3 . + b3``; ``n = info.samples`` hidden
  units, padded to a multiple of 4. The weights are uniforms of ``vec4``: ``info.weights[0]``
  is W1 row by row (``n`` rows of ``c`` values: weight ``[i][j]`` at ``c i + j``),
  ``info.weights[1]`` W2 (``n`` x ``n``), ``info.weights[2]`` W3 (3 x ``n``), each flat;
  ``info.biases`` b1 and b2 (``n`` values) and b3 (3). Padded rows and columns are 0, so
  the padded units are ``elu(0) = 0`` and nothing reads them.
- ``info.colorspace`` is a GLSL swizzle applied to the textures and to the output:
  ``"rgb"``. ``info.planes`` is 9. Other keys are not read (``type`` and ``format`` are
  written for a reader of the folder).
- The output is the colour, an 8-bit sRGB value over 255, rendered into an 8-bit RGBA
  texture (clamped, rounded) and drawn as an image.

The fit is :mod:`processing.neural_rti`'s. The codes are written first; the decoder is then
tuned to the codes as they read back from the written images (quantised, and compressed in
JPEG) and written last, in ``info.json``: what the viewer decodes is what was fitted to the
stored codes (measured: ``docs/web-export.md``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.atomic import write_json_atomic
from processing.neural_rti import CODE_SIZE, NeuralRTI
from processing.neural_rti_fit import NeuralSettings, fit_codes, fit_neural_rti, tune_decoder
from render.web_export.planes import PlaneStore, quantise
from render.web_export.result import Probe, WebModelExport, psnr_levels
from render.web_export.tiles import Layout, stored, write_plane

__all__ = [
    "FREE_CODE_PIXELS",
    "NEURAL_SAMPLES",
    "TUNE_SHARE",
    "Training",
    "shader_info",
    "write_neural",
]

#: Views of at most this many visible pixels give every pixel its own code (the best fit);
#: larger ones train an encoder on a sample of pixels and code every pixel with it.
FREE_CODE_PIXELS = 16384
#: Pixels an encoder is trained on (a random sample of the visible ones).
NEURAL_SAMPLES = 65536
#: Share of the neural time budget (and a quarter of the step cap) spent tuning the decoder
#: to the stored codes.
TUNE_SHARE = 0.2
#: The tuning's learning rate, relative to the fit's: the decoder starts trained.
TUNE_RATE = 0.1
#: Steps of the fit of the code of black alone (the pixels outside the object).
BLACK_STEPS = 300
#: Images of three code values (``plane_1`` .. ``plane_3``).
IMAGES = CODE_SIZE // 3


@dataclass(frozen=True)
class Training:
    """The pixels the neural model is fitted on.

    Attributes
    ----------
    pixels : ndarray (N,) int64, visible pixel indices (row-major), sorted
    levels : ndarray (T, N, 3) uint8, their 8-bit sRGB values
    encoder : bool, codes by an encoder (N is a sample of the visible pixels) rather than
        one free code per pixel (N is every visible pixel)
    """

    pixels: NDArray[np.int64]
    levels: NDArray[np.uint8]
    encoder: bool


def shader_info(
    model: NeuralRTI, low: NDArray[np.floating], span: NDArray[np.floating], layout: Layout
) -> dict[str, object]:
    """``info.json`` of a neural export: the decoder packed as ShaderNeural's uniforms.

    Parameters
    ----------
    model : NeuralRTI, its decoder (11 -> n -> n -> 3)
    low, span : ndarray (3, 3), each image's and channel's ``min`` and ``max - min``
    layout : Layout, the size and the planes' format
    """
    (w1, b1), (w2, b2), (w3, b3) = model.decoder
    n = model.hidden
    padded = -(-n // 4) * 4
    inputs = -(-(CODE_SIZE + 2) // 4) * 4

    def rows(weight: NDArray[np.float32], out: int, into: int) -> list[float]:
        """A (in, out) weight as ``out`` rows of ``into`` values, zeros where padded."""
        matrix = np.zeros((out, into), np.float64)
        matrix[: weight.shape[1], : weight.shape[0]] = weight.T
        return [float(v) for v in matrix.reshape(-1)]

    def padded_bias(bias: NDArray[np.float32], size: int) -> list[float]:
        out = np.zeros(size, np.float64)
        out[: len(bias)] = bias
        return [float(v) for v in out]

    high = np.asarray(low, np.float64) + span
    return {
        "type": "neural",
        "format": layout.image_format,
        "width": layout.width,
        "height": layout.height,
        "planes": CODE_SIZE,
        "samples": n,
        "colorspace": "rgb",
        "min": [[float(v) for v in row] for row in np.asarray(low, np.float64)],
        "max": [[float(v) for v in row] for row in high],
        "weights": [rows(w1, padded, inputs), rows(w2, padded, padded), rows(w3, 3, padded)],
        "biases": [padded_bias(b1, padded), padded_bias(b2, padded), [float(v) for v in b3]],
    }


def write_neural(
    folder: Path,
    training: Training,
    bands: Callable[[], Iterator[tuple[int, NDArray[np.uint8]]]],
    visible: NDArray[np.bool_],
    lights: NDArray[np.float64],
    layout: Layout,
    probe: Probe,
    settings: NeuralSettings,
    progress: Callable[[str], None] | None = None,
) -> WebModelExport:
    """Fit the neural model, write its code planes, tune its decoder to them, write info.json.

    Parameters
    ----------
    folder : Path, ``<output>/neural``
    training : Training, the pixels fitted and their values
    bands : callable, a new pass over the view: (first pixel, 8-bit values (T, n, 3)) per band
        (read again only when an encoder codes the pixels)
    visible : ndarray (P,) of bool; the other pixels get the code of black
    lights : ndarray (T, 3), the measured directions, camera frame
    layout : Layout
    probe : Probe, the pixels and values the errors are measured on
    settings : NeuralSettings, the budget (``max_seconds``, ``steps``) of the fit and the
        tuning together; ``encoder`` is set by ``training``
    progress : callable(message), optional
    """
    say = progress or (lambda _message: None)
    fit_settings = dataclasses.replace(
        settings, encoder=training.encoder, max_seconds=settings.max_seconds * (1 - TUNE_SHARE)
    )
    black = not bool(visible.all())
    levels = training.levels
    if black:  # one more sample: no light, black; its code is every other pixel's
        levels = np.concatenate([levels, np.zeros((len(lights), 1, 3), np.uint8)], axis=1)
    say(
        f"fitting the neural model: {training.levels.shape[1]} pixels, "
        f"{'an encoder' if training.encoder else 'a code per pixel'}, "
        f"up to {settings.max_seconds:.0f} s"
    )
    fitted = fit_neural_rti(levels, lights, fit_settings)
    code = None
    if black:
        # One sample among many is seldom stepped: its code is fitted again, alone.
        alone = dataclasses.replace(fit_settings, steps=BLACK_STEPS, batch=1, lights_per_step=None)
        code = fit_codes(fitted, levels[:, -1:], alone, start=_black_code(fitted)[None])[0]
    pixels = visible.size
    with PlaneStore(folder.parent, IMAGES, pixels) as store:
        _store_codes(store, fitted, training, bands, visible, code)
        low, span = store.ranges()
        exact = np.concatenate([store.image(j)[probe.pixels] for j in range(IMAGES)], axis=1)
        files = []
        for j in range(IMAGES):
            picture = quantise(store.image(j), low[j], span[j])
            files.append(
                write_plane(
                    folder,
                    f"plane_{j + 1}",
                    picture.reshape(layout.height, layout.width, 3),
                    layout,
                )
            )
    said = [stored(folder, f"plane_{j + 1}", layout).reshape(-1, 3) for j in range(IMAGES)]

    def read_back(indices: NDArray[np.int64]) -> NDArray[np.float32]:
        """Codes (k, 9) of pixels as the viewer reads them: byte / 255 * span + low."""
        return np.concatenate(
            [said[j][indices] / 255.0 * span[j] + low[j] for j in range(IMAGES)], axis=1
        ).astype(np.float32)

    tuned_codes = read_back(training.pixels)
    if code is not None:
        as_stored = np.concatenate(
            [quantise(code[3 * j : 3 * j + 3], low[j], span[j]) / 255.0 * span[j] + low[j]
             for j in range(IMAGES)]
        )  # fmt: skip
        tuned_codes = np.concatenate([tuned_codes, as_stored[None].astype(np.float32)])
    tune_settings = dataclasses.replace(
        fit_settings,
        max_seconds=settings.max_seconds * TUNE_SHARE,
        steps=max(1, settings.steps // 4),
        rate=settings.rate * TUNE_RATE,
    )
    say("tuning the neural decoder to the stored codes")
    model = tune_decoder(fitted, tuned_codes, levels, tune_settings)
    write_json_atomic(folder / "info.json", shader_info(model, low, span, layout))

    viewer = np.clip(model.decode(read_back(probe.pixels), lights), 0.0, 1.0) * 255.0
    before = np.clip(fitted.decode(exact, lights), 0.0, 1.0) * 255.0
    error = viewer - before
    shown, plain = np.rint(viewer), np.rint(before)  # the 8-bit texture the layer renders into
    trained, held = model.trained, model.held
    return WebModelExport(
        model="neural",
        folder=folder,
        planes=CODE_SIZE,
        files=tuple(files),
        levels=layout.levels,
        rms_error=float(np.sqrt(np.mean(error**2))) if error.size else 0.0,
        max_error=float(np.abs(error).max()) if error.size else 0.0,
        psnr=_psnr(shown, probe, trained),
        held_psnr=_psnr(shown, probe, held) if held.size else None,
        fit_psnr=_psnr(plain, probe, trained),
        fit_held_psnr=_psnr(plain, probe, held) if held.size else None,
        seconds=model.seconds,
        network=model,
    )


def _psnr(shown: NDArray[np.floating], probe: Probe, lights: NDArray[np.int64]) -> float:
    """PSNR of the shown values (T, S, 3) against the capture's, under some lights."""
    if not probe.pixels.size:
        return math.inf
    return psnr_levels(shown[lights], probe.levels[lights])


def _black_code(model: NeuralRTI) -> NDArray[np.float32]:
    """The code (9,) of a pixel outside the object: the last free code, or the encoder's."""
    if model.codes is not None:
        return model.codes[-1]
    return model.encode(np.zeros((len(model.lights), 1, 3), np.uint8))[0]


def _store_codes(
    store: PlaneStore,
    model: NeuralRTI,
    training: Training,
    bands: Callable[[], Iterator[tuple[int, NDArray[np.uint8]]]],
    visible: NDArray[np.bool_],
    black: NDArray[np.float32] | None,
) -> None:
    """Every pixel's code into the store (3 images of 3 values), a band at a time.

    ``black``: the code of the pixels that are not visible (None: every pixel is).
    """
    if model.codes is not None:  # free codes: the visible pixels are the ones trained
        step = 1 << 20
        for start in range(0, visible.size, step):
            stop = min(start + step, visible.size)
            codes = np.empty((stop - start, CODE_SIZE), np.float32)
            if black is not None:
                codes[:] = black
            lo, hi = np.searchsorted(training.pixels, [start, stop])
            codes[training.pixels[lo:hi] - start] = model.codes[lo:hi]
            store.write(start, codes.reshape(-1, IMAGES, 3))
        return
    for start, levels in bands():
        codes = model.encode(levels)
        shown = visible[start : start + levels.shape[1]]
        if black is not None:
            codes[~shown] = black
        store.write(start, codes.reshape(-1, IMAGES, 3))
