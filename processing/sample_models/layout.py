"""The per-sample arrays of a fit, block by block: :class:`FitLayout` and :data:`BlockFits`.

:func:`processing.sample_models.fitting.fit_blocks` fits a field block by block of samples; a
:class:`FitLayout` is what the fit is but for those arrays (the models, the field's frame and
lights), names every per-sample array (``MODEL__ARRAY``, as the saved fit names them:
:mod:`processing.sample_model_store`) and assembles the :class:`SampleModels` once they are
filled; each block's arrays are a :data:`BlockFits`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from processing.sample_models.fits import (
    BASIS_MODELS,
    BasisFit,
    Fit,
    ModelName,
    ParametricFit,
    SampleModels,
)
from processing.sample_models.loo import LooError

__all__ = ["BlockFits", "FitLayout"]


@dataclass(frozen=True, eq=False)
class FitLayout:
    """A field's fit but for its per-sample arrays: what :func:`fit_blocks` fills block by block.

    Attributes
    ----------
    kind, light_directions, camera_frame, view_direction, points, sample_count : as
        :class:`SampleModels` has them
    names : tuple of str, the models, in fitting order
    basis_terms : dict of str to int, the terms B of each basis model
    normals_fitted : bool, the parametric fits' normals were fitted (photometric stereo,
        refinement) rather than stored
    """

    kind: str
    light_directions: NDArray[np.float64]
    camera_frame: NDArray[np.float64]
    view_direction: NDArray[np.float64] | None
    points: NDArray[np.float64] | None
    sample_count: int
    names: tuple[ModelName, ...]
    basis_terms: dict[str, int]
    normals_fitted: bool

    def arrays(self) -> dict[str, tuple[np.dtype[Any], tuple[int, ...]]]:
        """Every per-sample array, ``MODEL__ARRAY``: its dtype and its shape after the sample.

        Parametric: ``normals`` (3,) float64, ``rho_d`` and ``f0`` (3,) float32, ``alpha``
        () float32, ``lit`` (T,) uint8, ``fitted`` () bool; basis: ``coefficients`` (B, 3)
        float32; both: ``loo_squared_error`` and ``loo_energy`` () float64. The names are
        those of the saved fit (:mod:`processing.sample_model_store`).
        """
        t_count = len(self.light_directions)
        out: dict[str, tuple[np.dtype[Any], tuple[int, ...]]] = {}
        for name in self.names:
            if name in BASIS_MODELS:
                out[f"{name}__coefficients"] = (np.dtype(np.float32), (self.basis_terms[name], 3))
            else:
                out |= {
                    f"{name}__normals": (np.dtype(np.float64), (3,)),
                    f"{name}__rho_d": (np.dtype(np.float32), (3,)),
                    f"{name}__f0": (np.dtype(np.float32), (3,)),
                    f"{name}__alpha": (np.dtype(np.float32), ()),
                    f"{name}__lit": (np.dtype(np.uint8), (t_count,)),
                    f"{name}__fitted": (np.dtype(np.bool_), ()),
                }
            out[f"{name}__loo_squared_error"] = (np.dtype(np.float64), ())
            out[f"{name}__loo_energy"] = (np.dtype(np.float64), ())
        return out

    def models(self, arrays: Mapping[str, NDArray[Any]]) -> SampleModels:
        """The :class:`SampleModels` of the arrays :meth:`arrays` names, filled."""
        fits: dict[str, Fit] = {}
        for name in self.names:
            loo = LooError(arrays[f"{name}__loo_squared_error"], arrays[f"{name}__loo_energy"])
            if name in BASIS_MODELS:
                fits[name] = BasisFit(name, arrays[f"{name}__coefficients"], loo)
                continue
            fits[name] = ParametricFit(
                name=name,
                normals=arrays[f"{name}__normals"],
                rho_d=arrays[f"{name}__rho_d"],
                f0=arrays[f"{name}__f0"],
                alpha=arrays[f"{name}__alpha"],
                lit=arrays[f"{name}__lit"],
                fitted=arrays[f"{name}__fitted"],
                loo=loo,
                normals_fitted=self.normals_fitted,
            )
        return SampleModels(
            kind=self.kind,
            light_directions=self.light_directions,
            camera_frame=self.camera_frame,
            view_direction=self.view_direction,
            points=self.points,
            fits=fits,
            sample_count=self.sample_count,
        )


#: One block's fitted arrays, by :meth:`FitLayout.arrays` name, rows the block's samples.
BlockFits = dict[str, NDArray[Any]]
