"""Leave-one-light-out error: its record, the prediction weights, the interpolation baselines.

The weights predict a light from the others; the interpolation baselines are scored on the
same observations as the models.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import NotApplicable
from core.field_store import ReflectanceField
from processing.interpolation import InterpolationMethod, interpolation_weights

__all__ = ["LooError", "interpolation_loo", "leave_one_out_barycentric", "leave_one_out_weights"]


@dataclass(frozen=True)
class LooError:
    """Leave-one-light-out prediction error of one model (or interpolation scheme).

    Attributes
    ----------
    squared_error : ndarray, shape (P,), float64
        Per sample, the sum over every held-out observation (visible camera x light x RGB) of
        (predicted - measured)^2, in squared field units.
    energy : ndarray, shape (P,), float64
        Per sample, the sum of measured^2 over the same observations.
    """

    squared_error: NDArray[np.float64]
    energy: NDArray[np.float64]

    @property
    def relative_rmse(self) -> float:
        """sqrt(sum of squared errors / sum of squared measured values) over the whole field."""
        total = float(self.energy.sum())
        return math.sqrt(float(self.squared_error.sum()) / total) if total > 0 else 0.0

    def per_sample(self) -> NDArray[np.float64]:
        """Relative RMSE of each sample; shape (P,), float64 (0 where nothing was measured)."""
        return np.sqrt(
            np.divide(
                self.squared_error,
                self.energy,
                out=np.zeros_like(self.squared_error),
                where=self.energy > 0,
            )
        )


def leave_one_out_weights(
    light_directions: NDArray[np.floating],
    method: InterpolationMethod = "barycentric",
    *,
    m: int = 3,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Weights that predict each measured light from the other T - 1.

    Parameters
    ----------
    light_directions : ndarray, shape (T, 3), T >= 2
    method : interpolation method of :func:`processing.interpolation.interpolation_weights`
        (outside the others' region: the ``clamp`` policy)
    m : neighbours of the ``paper`` method

    Returns
    -------
    indices : ndarray, shape (T, k), int64, into the full set (never the light itself)
    weights : ndarray, shape (T, k), float64, rows sum to 1
    """
    lights = np.asarray(light_directions, dtype=np.float64)
    t_count = lights.shape[0]
    if t_count < 2:
        raise NotApplicable(f"leaving one light out needs at least 2 lights, got {t_count}")
    rows_i, rows_w = [], []
    for t in range(t_count):
        others = np.delete(np.arange(t_count), t)
        w = interpolation_weights(lights[others], lights[t : t + 1], method, m=m)
        rows_i.append(others[w.indices[0]])
        rows_w.append(w.weights[0])
    width = max(len(r) for r in rows_i)
    indices = np.zeros((t_count, width), dtype=np.int64)
    weights = np.zeros((t_count, width), dtype=np.float64)
    for t, (i, w) in enumerate(zip(rows_i, rows_w, strict=True)):
        indices[t, : len(i)], weights[t, : len(w)] = i, w
        indices[t, len(i) :] = i[0]
    return indices, weights


def leave_one_out_barycentric(
    directions: NDArray[np.floating], values: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Each measured light's values predicted barycentrically from the others.

    Parameters
    ----------
    directions : ndarray, shape (T, 3), the measured lights
    values : ndarray, shape (T, ...), their values (images, marks, distances)

    Returns
    -------
    ndarray, shape (T, ...), float64: the honest leave-one-light-out prediction, the
    triangulation rebuilt without the light (:func:`leave_one_out_weights`)
    """
    v = np.asarray(values)
    indices, weights = leave_one_out_weights(directions)
    out = np.zeros(v.shape, dtype=np.float64)
    expand = (slice(None),) + (None,) * (v.ndim - 1)
    for j in range(indices.shape[1]):  # (T, ...) at a time: a (T, k, ...) gather is k fields
        out += weights[:, j][expand] * v[indices[:, j]]
    return out


def interpolation_loo(
    field: ReflectanceField, method: InterpolationMethod, *, m: int = 3
) -> LooError:
    """LOO error of interpolating over the measured lights (the linear relighting's predictor).

    Every measured light is predicted from the other T - 1 by ``method`` (at each camera, for
    every sample it sees) and compared with its measured values: the same observations and
    normalisation as the models' :class:`LooError`.

    Parameters
    ----------
    field : ReflectanceField, (S, T, P) with T >= 2
    method : interpolation method of :func:`processing.interpolation.interpolation_weights`
    m : neighbours of the ``paper`` method

    Returns
    -------
    LooError, per sample (P,), float64, in squared field units
    """
    s_count, t_count, p_count = field.shape
    indices, weights = leave_one_out_weights(field.light_directions, method, m=m)
    squared = np.zeros(p_count)
    energy = np.zeros(p_count)
    for s in range(s_count):
        slab = field.camera_slab(s).astype(np.float64)
        seen = field.visibility[s]
        for t in range(t_count):
            predicted = np.einsum("j,jpc->pc", weights[t], slab[indices[t]])
            squared += np.where(seen, ((predicted - slab[t]) ** 2).sum(axis=1), 0.0)
            energy += np.where(seen, (slab[t] ** 2).sum(axis=1), 0.0)
    return LooError(squared, energy)
