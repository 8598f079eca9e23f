"""Photometric stereo: the starting normals of a pixel field.

They come from luminance over each pixel's middle-ranked lights.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.colour import REC709_LUMINANCE
from core.errors import InputError, NotApplicable

__all__ = ["STEREO_CHUNK", "check_stereo_lights", "photometric_stereo"]

#: Photometric stereo leaves out each pixel's darkest and brightest lights (these fractions).
PS_DARK, PS_BRIGHT = 0.25, 0.10

_LUMA = REC709_LUMINANCE.astype(np.float64)


def check_stereo_lights(
    t_count: int, dark: float = PS_DARK, bright: float = PS_BRIGHT
) -> tuple[int, int]:
    """The ranks ``lo..hi`` of each pixel's lights photometric stereo keeps, checked.

    Raises
    ------
    InputError
        Fractions out of range.
    NotApplicable
        Fewer than 3 lights left between them.
    """
    if not (0.0 <= dark < 1.0 and 0.0 <= bright < 1.0 and dark + bright < 1.0):
        raise InputError(f"photometric stereo fractions dark={dark}, bright={bright} are invalid")
    lo, hi = round(dark * t_count), t_count - round(bright * t_count)
    if hi - lo < 3:
        raise NotApplicable(
            f"photometric stereo needs at least 3 lights between the quantiles, got {hi - lo} "
            f"of {t_count}"
        )
    return lo, hi


#: Pixels solved at once: the float64 temporaries (luminance, ranks, kept lights) are a few
#: times T x this x 8 bytes (15 MB each at 60 lights), whatever the number of pixels.
STEREO_CHUNK = 32768


def photometric_stereo(
    values: NDArray[np.floating],
    light_directions: NDArray[np.floating],
    view_direction: NDArray[np.floating],
    *,
    dark: float = PS_DARK,
    bright: float = PS_BRIGHT,
) -> NDArray[np.float64]:
    """Lambertian normals of every pixel from its values under T lights.

    Least squares of luminance = g . l over the lights between the ``dark`` and ``1 - bright``
    quantiles of each pixel's luminance (shadows and highlights left out); n = g / |g|.
    Pixels are solved :data:`STEREO_CHUNK` at a time, so the memory is that of ``values`` and
    the normals whatever their number (each pixel's normal is its own: the chunks change
    nothing).

    Parameters
    ----------
    values : ndarray, shape (T, P, 3), linear radiance
    light_directions : ndarray, shape (T, 3), unit vectors (rig frame)
    view_direction : ndarray, shape (3,), the camera direction
    dark, bright : float, fractions of each pixel's lights left out at each end

    Returns
    -------
    ndarray, shape (P, 3), float64, unit normals; pixels with no signal, or whose normal would
    face away from the camera, get the view direction
    """
    lights = np.asarray(light_directions, dtype=np.float64)
    lo, hi = check_stereo_lights(lights.shape[0], dark, bright)
    view = np.asarray(view_direction, dtype=np.float64)
    count = values.shape[1]
    normals = np.empty((count, 3))
    for start in range(0, count, STEREO_CHUNK):
        part = slice(start, min(start + STEREO_CHUNK, count))
        normals[part] = _stereo_chunk(values[:, part], lights, view, lo, hi)
    return normals


def _stereo_chunk(
    values: NDArray[np.floating],
    lights: NDArray[np.float64],
    view: NDArray[np.float64],
    lo: int,
    hi: int,
) -> NDArray[np.float64]:
    """:func:`photometric_stereo` of a few pixels, values (T, n, 3): normals (n, 3)."""
    luma = np.asarray(values, dtype=np.float64) @ _LUMA  # (T, n)
    rank = np.argsort(np.argsort(luma, axis=0, kind="stable"), axis=0, kind="stable")
    keep = ((rank >= lo) & (rank < hi)).astype(np.float64)  # (T, n)
    normal_matrix = np.einsum("tp,ti,tj->pij", keep, lights, lights)
    rhs = np.einsum("tp,tp,ti->pi", keep, luma, lights)
    solvable = np.linalg.det(normal_matrix) > 1e-12
    g = np.zeros_like(rhs)
    g[solvable] = np.linalg.solve(normal_matrix[solvable], rhs[solvable][:, :, None])[:, :, 0]
    length = np.linalg.norm(g, axis=1)
    normals = np.where(length[:, None] > 0, g / np.maximum(length, 1e-300)[:, None], view)
    facing = normals @ view > 0.05
    normals[~facing] = view
    return normals
