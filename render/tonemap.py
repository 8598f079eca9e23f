"""Tone mapping of linear radiance for display (pure functions on arrays)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.colour import linear_to_srgb, luminance

__all__ = ["auto_exposure", "to_uint8", "tone_map"]

#: Scene key: the log-average luminance is mapped to this display value (Reinhard et al. 2002).
KEY = 0.18


#: Radiance above this is displayed as this (white): luminance sums stay finite in float32.
_BRIGHTEST = 1e30


def auto_exposure(rgb: NDArray[np.floating]) -> float:
    """Exposure scale that maps the log-average luminance of linear RGB (..., 3) to ``KEY``."""
    y = luminance(rgb).astype(np.float64)
    positive = y[(y > 0) & np.isfinite(y)]
    if positive.size == 0:
        return 1.0
    return float(KEY / np.exp(np.mean(np.log(positive))))


def tone_map(rgb: NDArray[np.floating], *, exposure: float | None = None) -> NDArray[np.float32]:
    """Map linear RGB (..., 3) to sRGB-encoded values in [0, 1].

    Scales by ``exposure`` (default: :func:`auto_exposure`), compresses highlights with
    Reinhard's global operator on luminance (hue kept), then sRGB-encodes. A picture is
    never NaN: NaN radiance shows black and infinite radiance white (the stores and the
    panorama reader refuse both; this guards a display of whatever reaches it).
    """
    scale = auto_exposure(rgb) if exposure is None else exposure
    finite = np.nan_to_num(np.asarray(rgb, dtype=np.float32), nan=0.0, posinf=_BRIGHTEST)
    exposed = np.clip(finite, 0.0, _BRIGHTEST) * np.float32(scale)
    y = luminance(exposed)
    compressed = y / (1.0 + y)
    ratio = np.divide(compressed, y, out=np.zeros_like(y), where=y > 0)
    return linear_to_srgb(exposed * ratio[..., None])


def to_uint8(encoded: NDArray[np.floating]) -> NDArray[np.uint8]:
    """Quantise display values in [0, 1] to 8-bit (NaN as 0)."""
    return np.round(np.clip(np.nan_to_num(encoded, nan=0.0), 0.0, 1.0) * 255.0).astype(np.uint8)
