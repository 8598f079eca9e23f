"""Colour transfer functions and luminance (pure functions on arrays).

Domain and range: linear values are scene-referred float (any non-negative range); encoded values
are display-referred in [0, 1]. Luminance is Rec. 709 / sRGB Y.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["REC709_LUMINANCE", "REC709_WEIGHTS", "linear_to_srgb", "luminance", "srgb_to_linear"]

#: Rec. 709 luminance weights of linear R, G, B (ITU-R BT.709-6, item 3.2).
REC709_WEIGHTS = (0.2126, 0.7152, 0.0722)
REC709_LUMINANCE = np.array(REC709_WEIGHTS, dtype=np.float32)


def srgb_to_linear(encoded: NDArray[np.floating]) -> NDArray[np.float32]:
    """Decode sRGB values in [0, 1] to linear (IEC 61966-2-1 piecewise curve); same shape."""
    v = np.asarray(encoded, dtype=np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(linear: NDArray[np.floating]) -> NDArray[np.float32]:
    """Encode linear values to sRGB in [0, 1] (clipped first); same shape."""
    v = np.clip(np.asarray(linear, dtype=np.float32), 0.0, 1.0)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055).astype(np.float32)


def luminance(rgb: NDArray[np.floating]) -> NDArray[np.float32]:
    """Rec. 709 luminance of linear RGB; shape (..., 3) -> (...), float32.

    A weighted sum rather than a matrix product: numpy 2.4's matmul goes through BLAS, which
    raises "invalid value" on infinite radiance (then refused by the callers, not warned of).
    """
    v = np.asarray(rgb, dtype=np.float32)
    r, g, b = (np.float32(w) for w in REC709_LUMINANCE)
    return v[..., 0] * r + v[..., 1] * g + v[..., 2] * b
