"""Error-diffusion halftoning: the sampler behind the paper's importance sampling.

Three methods share one kernel:

* ``tmed``: Zhou & Fang 2003, variable coefficients plus threshold modulation (the paper's [22]).
  Their coefficient and modulation tables are indexed by the pixel's *input* level, folded at
  mid-grey (L > 127 uses 255 - L). Where the modulation strength s (percent) is non-zero the
  threshold is ``128 + (rand() % 128) * s // 100``, else 127; ``rand()`` is the Microsoft C
  runtime generator the authors' program was built with (state = state * 214013 + 2531011,
  output bits 16..30), seeded with ``seed`` (their program used 0) and drawn only for pixels
  with s > 0, in scan order.
* ``ostromoukhov``: Ostromoukhov 2001, the author's own 256-level coefficient table, fixed
  threshold 127.5.
* ``floyd-steinberg``: weights 7, 3, 5, 1 / 16, fixed threshold 127.5.

Common to all, as in the TMED reference code: serpentine scan (even rows left to right, odd rows
mirrored), a dot where the working value is strictly above the threshold, and integer error
bookkeeping: each share is ``trunc(error * weight / sum)`` and the pixel below receives the
remainder, so no error is lost to rounding. Values are fixed-point integers with
``fraction_bits`` bits below one grey level: 0 reproduces the reference's arithmetic on 8-bit
images, 16 keeps the tiny per-pixel densities of importance sampling (K dots over ~10^6 pixels).

Where this departs from the reference programs, on purpose:

* Borders: the panorama is periodic in azimuth, so shares for the next row wrap around the seam;
  the forward share at the end of a row goes to the pixel below (the next row's first pixel in
  serpentine order). The TMED program instead writes off-image shares into pixel (0, 0), and
  Ostromoukhov's discards them. Only the last row's downward shares leave the image.
* A pixel whose input is zero never receives a dot (Ostromoukhov's code does the same), so a
  zero modulation forbids samples even next to bright light.
* Densities above one dot per pixel are allowed (a sun): the excess diffuses to the neighbours.
"""

from __future__ import annotations

from typing import Literal, get_args

import numba
import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from processing.halftone_tables import (
    FLOYD_STEINBERG_WEIGHTS,
    OSTROMOUKHOV_COEFFICIENTS,
    TMED_COEFFICIENTS,
    TMED_THRESHOLD_MODULATION,
)

__all__ = ["DIFFUSION_METHODS", "DiffusionMethod", "error_diffuse", "halftone"]

DiffusionMethod = Literal["tmed", "ostromoukhov", "floyd-steinberg"]
DIFFUSION_METHODS: tuple[DiffusionMethod, ...] = get_args(DiffusionMethod)

#: Fixed-point bits below one grey level used when diffusing sampling densities.
DENSITY_FRACTION_BITS = 16

_FLOAT_SAFE = 2**52  # see _trunc_div

_FOLDED = np.minimum(np.arange(256), 255 - np.arange(256))  # input level -> table row


def _method_tables(method: str) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per input level 0..255: weights (right, down_left, down, down_right, sum); modulation."""
    weights = np.zeros((256, 5), dtype=np.int64)
    modulation = np.zeros(256, dtype=np.int64)
    if method == "tmed":
        table = np.array(TMED_COEFFICIENTS, dtype=np.int64)[_FOLDED]
        weights[:, [0, 1, 2, 4]] = table
        modulation[:] = np.array(TMED_THRESHOLD_MODULATION, dtype=np.int64)[_FOLDED]
    elif method == "ostromoukhov":
        weights[:, [0, 1, 2, 4]] = np.array(OSTROMOUKHOV_COEFFICIENTS, dtype=np.int64)
    elif method == "floyd-steinberg":
        weights[:] = np.array(FLOYD_STEINBERG_WEIGHTS, dtype=np.int64)
    else:
        raise InputError(
            f"unknown error-diffusion method {method!r}; choose one of {DIFFUSION_METHODS}"
        )
    return weights, modulation


def error_diffuse(
    density: NDArray[np.floating],
    *,
    method: DiffusionMethod | str = "tmed",
    seed: int = 0,
    fraction_bits: int = DENSITY_FRACTION_BITS,
) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
    """Halftone a density map: about ``density.sum()`` dots, placed by error diffusion.

    Parameters
    ----------
    density : ndarray, shape (H, W), non-negative
        Dots per pixel (1.0 = one dot = grey level 255).
    method : {"tmed", "ostromoukhov", "floyd-steinberg"}
    seed : int
        Seed of the threshold modulation's generator (``tmed`` only).
    fraction_bits : int
        Fixed-point precision below one grey level (0..20).

    Returns
    -------
    fired : ndarray, shape (H, W), bool
        The dots.
    margin : ndarray, shape (H, W), float32
        Working value minus threshold when each pixel was decided, in grey levels: how far a
        pixel was from flipping (used to settle an exact count).
    """
    d = np.asarray(density, dtype=np.float64)
    if d.ndim != 2 or d.size == 0:
        raise InputError(f"density must be a non-empty (H, W) array, got shape {d.shape}")
    if not np.all(np.isfinite(d)) or float(d.min()) < 0:
        raise InputError("density must be finite and non-negative")
    if not 0 <= fraction_bits <= 20:
        raise InputError(f"fraction_bits must be in 0..20, got {fraction_bits}")
    # A working value never exceeds all the mass plus one pixel's input, and value x weight
    # (weights < 2**21) must fit in int64.
    if (float(d.sum()) + float(d.max())) * 255.0 * 2.0**fraction_bits >= 2.0**41:
        raise InputError(
            f"density too large for exact integer error diffusion ({d.sum():.4g} dots in all); "
            "lower it or use fewer fraction bits"
        )
    weights, modulation = _method_tables(method)
    # TMED's unmodulated threshold is 127 (strict >); the fixed-threshold methods split at
    # 127.5, which is 127 again in whole levels and exactly 127.5 in fixed point.
    threshold = 127 << fraction_bits if method == "tmed" else (255 << fraction_bits) // 2
    fired = np.zeros(d.shape, dtype=np.bool_)
    margin = np.empty(d.shape, dtype=np.float32)
    _diffuse(
        np.ascontiguousarray(d),
        fraction_bits,
        weights,
        modulation,
        threshold,
        seed & 0xFFFFFFFF,
        fired,
        margin,
    )
    return fired, margin


def halftone(
    levels: NDArray[np.integer], *, method: DiffusionMethod | str = "tmed", seed: int = 0
) -> NDArray[np.bool_]:
    """Halftone an 8-bit grey image (H, W) exactly as the integer reference programs do.

    Returns the dots (H, W) bool: True where the output is white (255).
    """
    grey = np.asarray(levels)
    if grey.ndim != 2 or not np.issubdtype(grey.dtype, np.integer):
        raise InputError(f"levels must be an (H, W) integer image, got {grey.dtype} {grey.shape}")
    if grey.size and (int(grey.min()) < 0 or int(grey.max()) > 255):
        raise InputError("levels must lie in 0..255")
    fired, _ = error_diffuse(
        grey.astype(np.float64) / 255.0, method=method, seed=seed, fraction_bits=0
    )
    return fired


@numba.njit(cache=True, inline="always")
def _trunc_div(a: int, b: int) -> int:
    # C integer division (toward zero), as the reference code does. For |a| < 2**52 and
    # 0 < b <= 2**21 (table sums are below 2e6) a and b are exact doubles, and a quotient that is
    # not an integer stays at least 1/b below the next integer, more than half an ulp there, so
    # the truncated float quotient is the integer one; it is several times faster.
    if -_FLOAT_SAFE < a < _FLOAT_SAFE:
        return int(a / b)
    q = abs(a) // b
    return q if a >= 0 else -q


@numba.njit(cache=True)
def _diffuse(
    density: NDArray[np.float64],
    fraction_bits: int,
    weights: NDArray[np.int64],
    modulation: NDArray[np.int64],
    base_threshold: int,
    seed: int,
    fired: NDArray[np.bool_],
    margin: NDArray[np.float32],
) -> None:
    height, width = density.shape
    scale = 255.0 * (1 << fraction_bits)
    one_dot = np.int64(255) << fraction_bits
    to_levels = 1.0 / (1 << fraction_bits)
    current = np.zeros(width, dtype=np.int64)
    below = np.zeros(width, dtype=np.int64)
    state = np.uint32(seed)
    for i in range(height):
        forward = 1 if i % 2 == 0 else -1
        start = 0 if forward == 1 else width - 1
        last_row = i == height - 1
        for step in range(width):
            j = start + forward * step
            given = int(density[i, j] * scale + 0.5)
            value = given + current[j]
            level = min(given >> fraction_bits, 255)
            strength = modulation[level]
            if strength == 0:
                threshold = np.int64(base_threshold)
            else:
                state = np.uint32(state * np.uint32(214013) + np.uint32(2531011))
                draw = np.int64((state >> np.uint32(16)) & np.uint32(0x7FFF))
                threshold = np.int64(128 + ((draw % 128) * strength) // 100) << fraction_bits
            margin[i, j] = (value - threshold) * to_levels
            if given > 0 and value > threshold:
                fired[i, j] = True
                error = value - one_dot
            else:
                error = value
            total = weights[level, 4]
            to_right = _trunc_div(error * weights[level, 0], total)
            to_down_left = _trunc_div(error * weights[level, 1], total)
            to_down_right = _trunc_div(error * weights[level, 3], total)
            to_down = error - to_right - to_down_left - to_down_right
            ahead = j + forward
            if 0 <= ahead < width:
                current[ahead] += to_right
            else:
                to_down += to_right
            if not last_row:
                behind = j - forward
                if behind < 0:
                    behind += width
                elif behind >= width:
                    behind -= width
                if ahead < 0:
                    ahead += width
                elif ahead >= width:
                    ahead -= width
                below[behind] += to_down_left
                below[j] += to_down
                below[ahead] += to_down_right
        current, below = below, current
        below[:] = 0
