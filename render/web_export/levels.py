"""The 8-bit sRGB values the RTI tools fit, by table: :func:`eight_bit_levels`, exactly, faster.

:func:`render.rti_fits.eight_bit_levels` (scale, clip to 0..1, sRGB-encode, round)
defines the values. It raises every value to the power 1/2.4, which on a 24-megapixel view of
60 lights is minutes; the export reads the view once or twice. So the levels are taken from
the float's bits instead: a float32 in 0..1 is, by its top 20 bits, in one of 2^18 buckets of
2^12 consecutive floats (a relative width of 2^-11 or less), and no bucket holds more than one
level boundary (neighbouring boundaries are relatively much further apart). The table holds each
bucket's level at its start and the first float of the next level within it, both found with
:func:`eight_bit_levels` itself (bisection over the bit patterns), so the two agree on every
float32 (the test checks boundaries and 10^8 floats).
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from render.rti_fits import eight_bit_levels

__all__ = ["eight_bit"]

#: Low bits of a float32 ignored by the bucket index.
_SHIFT = 12


@functools.cache
def _table() -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
    """(level at each bucket's start, first float of the next level in it or inf)."""
    one = int(np.float32(1.0).view(np.uint32))
    starts = np.arange((one >> _SHIFT) + 1, dtype=np.uint32) << _SHIFT
    ends = np.minimum(starts + (1 << _SHIFT) - 1, one).astype(np.uint32)
    first = eight_bit_levels(starts.view(np.float32))
    last = eight_bit_levels(ends.view(np.float32))
    if not ((last - first) <= 1).all():  # a bucket with two boundaries: the shift is wrong
        raise AssertionError("8-bit level table: a bucket spans two level boundaries")
    crossing = np.flatnonzero(last > first)
    low = starts[crossing].astype(np.int64)  # its level is first[crossing]
    high = ends[crossing].astype(np.int64)  # one level up
    while (high - low > 1).any():
        middle = (low + high) // 2
        up = eight_bit_levels(middle.astype(np.uint32).view(np.float32)) > first[crossing]
        high, low = np.where(up, middle, high), np.where(up, low, middle)
    edges = np.full(len(starts), np.inf, dtype=np.float32)
    edges[crossing] = high.astype(np.uint32).view(np.float32)
    return first.astype(np.uint8), edges


def eight_bit(values: NDArray[np.floating], scale: float = 1.0) -> NDArray[np.uint8]:
    """The 8-bit sRGB values 0..255 of linear values: ``eight_bit_levels(values, scale)``.

    Parameters
    ----------
    values : ndarray, any shape, linear radiance (finite)
    scale : float, the linear value that 8-bit white stands for is 1 / ``scale``

    Returns
    -------
    ndarray, same shape, uint8
    """
    x = np.asarray(values, dtype=np.float32) * scale
    x = np.clip(x, 0.0, 1.0, dtype=np.float32)
    x += np.float32(0.0)  # -0.0 (its sign bit) becomes 0.0
    bucket = x.view(np.uint32) >> _SHIFT
    base, edges = _table()
    return base[bucket] + (x >= edges[bucket]).astype(np.uint8)
