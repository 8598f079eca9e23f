"""What :func:`render.web_export.export.export_web` wrote, and what it measured of it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from processing.neural_rti import NeuralRTI
from render.web_export.names import WebModel

__all__ = ["Probe", "WebExport", "WebModelExport", "psnr_levels"]


@dataclass(frozen=True)
class Probe:
    """The pixels the export's errors are measured on, and the capture's values there.

    Attributes
    ----------
    pixels : ndarray (S,) int64, visible pixel indices (row-major), sorted
    levels : ndarray (T, S, 3) uint8, the capture's 8-bit sRGB values at them, every light
    """

    pixels: NDArray[np.int64]
    levels: NDArray[np.uint8]


@dataclass(frozen=True)
class WebModelExport:
    """One model as written.

    Attributes
    ----------
    model : WebModel
    folder : Path holding ``info.json`` and the planes
    planes : int, quantised planes (``nplanes``, or 9 for ``neural``; three per image)
    files : tuple of Path, the planes' images (``plane_j.jpg``) or, tiled, their ``.dzi``
    levels : int, deep-zoom levels (0: not tiled)
    rms_error, max_error : float
        The written planes, read back and rendered as the viewer renders them, against the
        model before quantisation (the fitted coefficients; the fitted codes and decoder),
        under the field's measured lights on up to ``ERROR_SAMPLES`` visible pixels, in 8-bit
        levels: what the quantisation and the JPEG compression cost.
    psnr : float, dB, the written model as the viewer renders it (clamped, 8-bit) against
        the capture's 8-bit values, under the lights fitted, on the same pixels
    held_psnr : float or None, dB, the same under the lights held out of the fit (``neural``
        with a holdout; else None)
    fit_psnr, fit_held_psnr : float or None, dB, ``neural``: the fitted model before its
        codes were quantised, under the lights fitted and held out
    seconds : float, time spent fitting this model (the neural fit and tuning; the bases are
        fitted together, and report their shared time)
    network : NeuralRTI or None, ``neural``: the model as written (the decoder tuned to the
        stored codes)
    """

    model: WebModel
    folder: Path
    planes: int
    files: tuple[Path, ...]
    levels: int
    rms_error: float
    max_error: float
    psnr: float
    held_psnr: float | None = None
    fit_psnr: float | None = None
    fit_held_psnr: float | None = None
    seconds: float = 0.0
    network: NeuralRTI | None = None


@dataclass(frozen=True)
class WebExport:
    """What :func:`render.web_export.export.export_web` wrote.

    Attributes
    ----------
    output : Path, the export's folder
    camera : int, the view exported
    width, height : int, the image size (pixels)
    scale : float, the radiance written as 8-bit white is 1 / ``scale``
    models : tuple of WebModelExport, one folder per model (``output/<model>``)
    normals_png : Path, 16-bit normal map, ``round((n + 1) / 2 * 65535)``
    normals_exr : Path, float32 normals (RGB) and the visible pixels (A)
    tile_size : int, deep-zoom tile side (0: not tiled)
    notes : tuple of str, choices made for the caller (a tile size, PNG planes tiled, ...)
    """

    output: Path
    camera: int
    width: int
    height: int
    scale: float
    models: tuple[WebModelExport, ...]
    normals_png: Path
    normals_exr: Path
    tile_size: int = 0
    notes: tuple[str, ...] = ()


def psnr_levels(shown: NDArray[np.floating], reference: NDArray[np.integer]) -> float:
    """PSNR (dB) of 8-bit values against 8-bit values (inf when equal)."""
    error = np.mean((np.asarray(shown, dtype=np.float64) - reference) ** 2)
    return float(10.0 * np.log10(255.0**2 / error)) if error > 0 else float("inf")
