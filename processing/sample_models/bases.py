"""Linear bases over the light direction (PTM, HSH) for pixel fields: evaluation and fit.

Their evaluation, and the least-squares fit of every pixel with its closed-form (hat-matrix)
leave-one-light-out error.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.special import factorial, lpmv

from core.errors import InputError, NotApplicable
from processing.sample_models.fits import BASIS_MODELS, BasisFit, BasisModelName
from processing.sample_models.loo import LooError

__all__ = ["BASIS_CHUNK", "evaluate_basis", "fit_basis"]


def evaluate_basis(name: str, directions: NDArray[np.floating]) -> NDArray[np.float64]:
    """Basis functions of ``name`` at light directions in the camera frame.

    Parameters
    ----------
    name : {"ptm", "hsh2", "hsh3"}
    directions : ndarray, shape (N, 3), unit vectors (x right, y up, z toward the camera);
        HSH is defined on z >= 0 (z is clipped there)

    Returns
    -------
    ndarray, shape (N, B), float64
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise InputError(f"basis directions must have shape (N, 3), got {d.shape}")
    lu, lv, lw = d[:, 0], d[:, 1], d[:, 2]
    if name == "ptm":
        return np.stack([lu * lu, lv * lv, lu * lv, lu, lv, np.ones_like(lu)], axis=1)
    order = {"hsh2": 2, "hsh3": 3}.get(name)
    if order is None:
        raise InputError(f"unknown basis model {name!r}; use one of {BASIS_MODELS}")
    # Hemispherical harmonics: the shifted associated Legendre P_l^|m|(2 cos theta - 1), the
    # hemisphere mapped onto the whole [-1, 1] of the spherical harmonics (orthonormal there).
    x = 2.0 * np.clip(lw, 0.0, 1.0) - 1.0
    phi = np.arctan2(lv, lu)
    columns = []
    for degree in range(order):
        for m in range(-degree, degree + 1):
            a = abs(m)
            norm = math.sqrt(
                (2 * degree + 1)
                * float(factorial(degree - a))
                / (2 * math.pi * float(factorial(degree + a)))
            )
            legendre = lpmv(a, degree, x)
            if m > 0:
                columns.append(math.sqrt(2.0) * norm * np.cos(m * phi) * legendre)
            elif m < 0:
                columns.append(math.sqrt(2.0) * norm * np.sin(a * phi) * legendre)
            else:
                columns.append(norm * legendre)
    return np.stack(columns, axis=1)


def _per_pixel_sum(values: NDArray[np.float64], t_count: int, count: int) -> NDArray[np.float64]:
    """Sum over lights and channels of ``values`` (T, n 3) squared: (n,), float64.

    Channels first, then lights one after the other: the same additions for a pixel whatever
    the number of pixels summed with it (a reduction over both axes at once groups its terms
    by the array's length, and a pixel's error would change in its last digit with its block).
    """
    squared = (values**2).reshape(t_count, count, 3)
    return np.add.reduce(squared[:, :, 0] + squared[:, :, 1] + squared[:, :, 2], axis=0)


#: Pixels fitted at once: the float64 temporaries (the values, residuals, held-out errors)
#: are a few times T x this x 3 x 8 bytes (47 MB each at 60 lights), whatever the pixels.
BASIS_CHUNK = 32768


def fit_basis(
    name: BasisModelName, values: NDArray[np.floating], camera_lights: NDArray[np.float64]
) -> BasisFit:
    """Least-squares basis coefficients of every pixel and their closed-form LOO error.

    The design (T, B) is shared by all pixels, so one pseudo-inverse fits them all and the hat
    matrix gives every LOO residual at once: e_i / (1 - h_ii). Pixels are fitted
    :data:`BASIS_CHUNK` at a time, so the memory is that of ``values`` and the coefficients
    whatever their number.

    Parameters
    ----------
    name : {"ptm", "hsh2", "hsh3"}
    values : ndarray, shape (T, P, 3), float32, one camera's slab (linear radiance; any
        strides: a block of samples transposed to light-major will do)
    camera_lights : ndarray, shape (T, 3), float64, the measured lights in the camera frame

    Returns
    -------
    BasisFit, coefficients (P, B, 3) float32 and the LOO error per pixel

    Raises
    ------
    NotApplicable
        The model has as many terms as the field has lights, or more.
    """
    t_count, p_count, _ = values.shape
    design = evaluate_basis(name, camera_lights)
    if t_count <= design.shape[1]:
        raise NotApplicable(
            f"model {name!r} has {design.shape[1]} terms; it needs more than that many lights, "
            f"the field has {t_count}"
        )
    pinv = np.linalg.pinv(design)  # (B, T)
    leverage = np.einsum("tb,bt->t", design, pinv)
    coefficients = np.empty((p_count, design.shape[1], 3), dtype=np.float32)
    squared = np.empty(p_count)
    energy = np.empty(p_count)
    for start in range(0, p_count, BASIS_CHUNK):
        part = slice(start, min(start + BASIS_CHUNK, p_count))
        count = part.stop - part.start
        flat = values[:, part].reshape(t_count, -1).astype(np.float64)
        # Every coefficient and residual a dot product of its own, in one order whatever the
        # chunk: BLAS's matrix product sums a column at a chunk's edge in another order than
        # one inside, so a pixel's fit would change in its last digit with its block.
        fitted = np.einsum("bt,tn->bn", pinv, flat, optimize=False)  # (B, n 3)
        residual = flat - np.einsum("tb,bn->tn", design, fitted, optimize=False)
        held_out = residual / np.maximum(1.0 - leverage, 1e-9)[:, None]
        squared[part] = _per_pixel_sum(held_out, t_count, count)
        energy[part] = _per_pixel_sum(flat, t_count, count)
        coefficients[part] = fitted.reshape(-1, count, 3).transpose(1, 0, 2)
    return BasisFit(name=name, coefficients=coefficients, loo=LooError(squared, energy))
