"""Photometric stereo: the starting normals of a pixel field.

They come from luminance over each pixel's middle-ranked lights.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.colour import REC709_LUMINANCE
from core.errors import InputError

__all__ = ["photometric_stereo"]

#: Photometric stereo leaves out each pixel's darkest and brightest lights (these fractions).
PS_DARK, PS_BRIGHT = 0.25, 0.10

_LUMA = REC709_LUMINANCE.astype(np.float64)


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
    t_count = lights.shape[0]
    if not (0.0 <= dark < 1.0 and 0.0 <= bright < 1.0 and dark + bright < 1.0):
        raise InputError(f"photometric stereo fractions dark={dark}, bright={bright} are invalid")
    lo, hi = round(dark * t_count), t_count - round(bright * t_count)
    if hi - lo < 3:
        raise InputError(
            f"photometric stereo needs at least 3 lights between the quantiles, got {hi - lo} "
            f"of {t_count}"
        )
    luma = np.asarray(values, dtype=np.float64) @ _LUMA  # (T, P)
    rank = np.argsort(np.argsort(luma, axis=0, kind="stable"), axis=0, kind="stable")
    keep = ((rank >= lo) & (rank < hi)).astype(np.float64)  # (T, P)
    normal_matrix = np.einsum("tp,ti,tj->pij", keep, lights, lights)
    rhs = np.einsum("tp,tp,ti->pi", keep, luma, lights)
    view = np.asarray(view_direction, dtype=np.float64)
    solvable = np.linalg.det(normal_matrix) > 1e-12
    g = np.zeros_like(rhs)
    g[solvable] = np.linalg.solve(normal_matrix[solvable], rhs[solvable][:, :, None])[:, :, 0]
    length = np.linalg.norm(g, axis=1)
    normals = np.where(length[:, None] > 0, g / np.maximum(length, 1e-300)[:, None], view)
    facing = normals @ view > 0.05
    normals[~facing] = view
    return normals
