"""Procedural textures of the Mitsuba worlds: checker, value noise and stripes as float images.

A texture is a square image of ``resolution`` texels whose texel (row r, column c) sits at
texture coordinates u = (c + 0.5) / resolution, v = (r + 0.5) / resolution (Mitsuba's
``bitmap`` texture reads row 0 at v = 0 and column 0 at u = 0, checked against Mitsuba 3.9).
``scale`` is the number of repeats per unit of u and v; it is a whole number, so the image tiles
under Mitsuba's ``repeat`` wrap and a shape whose u runs past 1 (the torus knot's) shows no
seam. Values run from ``low`` to ``high``: numbers give a grey texture (a roughness, a weight),
three-element lists a colour one (a base colour).

``checker``
    ``low`` and ``high`` in alternate cells, scale x scale cells per unit square; sampled
    with the ``nearest`` filter so the edges stay sharp.
``noise``
    Smooth value noise: uniform random values on a scale x scale periodic lattice (``seed``),
    interpolated with a smoothstep, stretched to span exactly low .. high; ``scale`` >= 2.
``stripes``
    0.5 + 0.5 sin(2 pi scale u) from ``low`` to ``high``: bands across u, constant along v.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

__all__ = ["TEXTURES", "TextureKind", "texture_filter", "texture_image"]

TextureKind = Literal["checker", "noise", "stripes"]
#: The procedural textures a world file may name.
TEXTURES: tuple[TextureKind, ...] = get_args(TextureKind)


def texture_filter(kind: TextureKind) -> Literal["nearest", "bilinear"]:
    """Mitsuba's ``filter_type`` for a texture: sharp cells for checkers, smooth otherwise."""
    return "nearest" if kind == "checker" else "bilinear"


def _pattern(kind: TextureKind, scale: int, resolution: int, seed: int) -> NDArray[np.float64]:
    """The pattern in [0, 1]; shape (resolution, resolution), rows along v."""
    centres = (np.arange(resolution) + 0.5) / resolution
    u, v = np.meshgrid(centres, centres, indexing="xy")
    if kind == "checker":
        return np.mod(np.floor(scale * u) + np.floor(scale * v), 2.0)
    if kind == "stripes":
        return 0.5 + 0.5 * np.sin(2.0 * np.pi * scale * u)
    lattice = np.random.default_rng(seed).random((scale, scale))
    x, y = scale * u, scale * v
    col, row = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - col, y - row
    sx, sy = fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy)
    # The lattice wraps (index modulo scale), so the noise tiles like the other patterns.
    c0, c1, r0, r1 = col % scale, (col + 1) % scale, row % scale, (row + 1) % scale
    top = (1.0 - sx) * lattice[r0, c0] + sx * lattice[r0, c1]
    bottom = (1.0 - sx) * lattice[r1, c0] + sx * lattice[r1, c1]
    noise = (1.0 - sy) * top + sy * bottom
    return (noise - noise.min()) / (noise.max() - noise.min())


def texture_image(
    kind: TextureKind,
    *,
    low: float | tuple[float, float, float],
    high: float | tuple[float, float, float],
    scale: int = 4,
    resolution: int = 256,
    seed: int = 0,
) -> NDArray[np.float32]:
    """A procedural texture as a linear float image (module docstring).

    Parameters
    ----------
    kind : {"checker", "noise", "stripes"}
    low, high : float, or (r, g, b); the values the pattern runs between
    scale : int, >= 1 (>= 2 for noise), repeats per unit of u and v
    resolution : int, >= 2, texels along each side
    seed : int, of the noise lattice (ignored by the other kinds)

    Returns
    -------
    ndarray, float32, shape (resolution, resolution) for numbers, (resolution, resolution, 3)
    when ``low`` or ``high`` is a colour

    Raises
    ------
    InputError
        An unknown kind or an out-of-range scale or resolution.
    """
    if kind not in TEXTURES:
        raise InputError(f"unknown texture {kind!r}; known textures: {', '.join(TEXTURES)}")
    if scale < (2 if kind == "noise" else 1):
        raise InputError(f"{kind} texture scale must be at least {2 if kind == 'noise' else 1}")
    if resolution < 2:
        raise InputError(f"texture resolution must be at least 2, got {resolution}")
    pattern = _pattern(kind, scale, resolution, seed)
    start, end = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    if start.ndim or end.ndim:
        pattern = pattern[..., None]
    return np.ascontiguousarray(start + (end - start) * pattern, dtype=np.float32)
