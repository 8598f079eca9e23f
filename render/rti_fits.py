"""The RTI tools' own fits, reproduced: the normalised-Gaussian rbf and bases fitted to 8 bits.

The ``rbf`` method of the RTI tools (relight, OpenLIME) weighs every measured light by a
Gaussian of its distance to the light asked for, normalised, small weights dropped
(:func:`rbf_weights`), its width chosen here by leave-one-light-out error
(:func:`choose_rbf_sigma`); and the tools fit PTM and HSH to the images' 8-bit sRGB values
(:func:`eight_bit_levels`, :func:`fit_basis_8bit`), which the ``-8bit`` methods
(:mod:`render.prediction_methods`) and the web export (:mod:`render.web_export`) share.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.colour import linear_to_srgb
from core.errors import InputError
from core.field_store import ReflectanceField
from processing.sample_models.bases import fit_basis
from processing.sample_models.fits import BasisModelName

__all__ = [
    "RBF_DROP",
    "RBF_SIGMAS",
    "SIGMA_SAMPLES",
    "choose_rbf_sigma",
    "eight_bit_levels",
    "fit_basis_8bit",
    "rbf_weights",
    "sigma_subset",
]

#: Widths sigma the ``rbf`` kernel is chosen among (chord distance between unit vectors; the
#: RTI tools' default is 0.125 for about 100 lights).
RBF_SIGMAS = tuple(float(s) for s in np.geomspace(0.03, 1.0, 19))
#: Normalised weights below this are dropped (and the rest renormalised), as the RTI tools do.
RBF_DROP = 1e-3
#: Samples the leave-one-light-out choice of sigma reads (a random subset of a big field).
SIGMA_SAMPLES = 4096


def rbf_weights(
    measured: NDArray[np.floating], queries: NDArray[np.floating], sigma: float
) -> NDArray[np.float64]:
    """Normalised Gaussian weights (Q, T) of the measured directions for each query.

    w_i = exp(-|q - l_i|^2 / sigma^2), normalised to sum 1, weights below :data:`RBF_DROP`
    dropped and the rest renormalised (relight's ``lightWeightsRbf``). Taken relative to the
    nearest direction, so no row underflows to all zeros however small sigma is.
    """
    if not sigma > 0:
        raise InputError(f"the rbf width sigma must be positive, got {sigma}")
    m = np.asarray(measured, dtype=np.float64)
    q = np.asarray(queries, dtype=np.float64)
    squared = np.sum((q[:, None, :] - m[None, :, :]) ** 2, axis=2)
    return _normalised(np.exp(-(squared - squared.min(axis=1, keepdims=True)) / sigma**2))


def _normalised(kernel: NDArray[np.float64]) -> NDArray[np.float64]:
    weights = kernel / kernel.sum(axis=1, keepdims=True)
    weights[weights < RBF_DROP] = 0.0
    return weights / weights.sum(axis=1, keepdims=True)


def choose_rbf_sigma(
    directions: NDArray[np.floating],
    values: NDArray[np.floating],
    sigmas: tuple[float, ...] = RBF_SIGMAS,
) -> float:
    """The sigma of :data:`RBF_SIGMAS` whose leave-one-light-out prediction errs least.

    Parameters
    ----------
    directions : ndarray, shape (T, 3), the measured lights
    values : ndarray, shape (T, N, 3) or (T, N), what is interpolated (a subset of samples)

    Returns
    -------
    float, the chosen sigma (light j predicted from the others: its own weight removed)
    """
    d = np.asarray(directions, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).reshape(len(d), -1)
    squared = np.sum((d[:, None, :] - d[None, :, :]) ** 2, axis=2)
    np.fill_diagonal(squared, np.inf)
    best, best_error = sigmas[0], np.inf
    for sigma in sigmas:
        kernel = np.exp(-(squared - squared.min(axis=1, keepdims=True)) / sigma**2)
        error = float(np.sum((_normalised(kernel) @ v - v) ** 2))
        if error < best_error:
            best, best_error = sigma, error
    return best


def sigma_subset(field: ReflectanceField, seed: int = 0) -> NDArray[np.float32]:
    """(T, N, 3) radiance of up to :data:`SIGMA_SAMPLES` visible (camera, sample) pairs."""
    rng = np.random.default_rng(seed)
    s_count = field.shape[0]
    per_camera = max(1, SIGMA_SAMPLES // s_count)
    parts = []
    for s in range(s_count):
        seen = np.flatnonzero(field.visibility[s])
        if seen.size:
            pick = rng.choice(seen, size=min(per_camera, seen.size), replace=False)
            parts.append(field.camera_slab(s)[:, np.sort(pick)])
    if not parts:
        raise InputError(f"{field.path}: no camera sees any sample")
    return np.concatenate(parts, axis=1)


def eight_bit_levels(values: NDArray[np.floating], scale: float = 1.0) -> NDArray[np.float32]:
    """The 8-bit sRGB values, 0..255, that RTI tools fit: scaled, clipped, encoded, rounded.

    Parameters
    ----------
    values : ndarray, any shape, linear radiance
    scale : float, the linear value that 8-bit white stands for is 1 / ``scale``

    Returns
    -------
    ndarray, same shape, float32 whole numbers 0..255
    """
    encoded = linear_to_srgb(np.clip(np.asarray(values, dtype=np.float32) * scale, 0.0, 1.0))
    return np.round(encoded * 255.0).astype(np.float32)


def fit_basis_8bit(
    basis: BasisModelName,
    values: NDArray[np.floating],
    lights: NDArray[np.floating],
    scale: float = 1.0,
) -> NDArray[np.float32]:
    """Basis coefficients fitted as RTI tools fit them: to the 8-bit sRGB values, 0..255.

    The least-squares fit (:func:`processing.sample_models.bases.fit_basis`) of
    :func:`eight_bit_levels`; the ``-8bit`` predictors and :mod:`render.web_export` share it.

    Parameters
    ----------
    basis : {"ptm", "hsh2", "hsh3"}
    values : ndarray, shape (T, P, 3), linear radiance of P samples under T lights
    lights : ndarray, shape (T, 3), the lights in the frame the basis takes (a pixel field's
        camera frame)
    scale : float, the linear value that 8-bit white stands for is 1 / ``scale``

    Returns
    -------
    ndarray, shape (P, B, 3), float32: coefficients in 8-bit units (a basis sum of 255 is
    white)
    """
    levels = eight_bit_levels(values, scale)
    return fit_basis(basis, levels, np.asarray(lights, dtype=np.float64)).coefficients
