"""What a fit is: the model names (a Literal table) and the fitted models of a field as data."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from processing.sample_models.loo import LooError

__all__ = [
    "BASIS_MODELS",
    "MODELS",
    "PARAMETRIC_MODELS",
    "BasisFit",
    "BasisModelName",
    "Fit",
    "ModelName",
    "ParametricFit",
    "ParametricModelName",
    "SampleModels",
]

# The tuples are read from the Literal types (as processing.sampling does for its samplers), so
# the names a signature accepts and the names the code iterates over cannot drift apart.
ParametricModelName = Literal["lambert", "lambert+ggx"]
BasisModelName = Literal["ptm", "hsh2", "hsh3"]
#: Every model, parametric first: ``Literal["lambert", "lambert+ggx", "ptm", "hsh2", "hsh3"]``.
ModelName = Literal[ParametricModelName, BasisModelName]
PARAMETRIC_MODELS: tuple[ParametricModelName, ...] = get_args(ParametricModelName)
BASIS_MODELS: tuple[BasisModelName, ...] = get_args(BasisModelName)
MODELS: tuple[ModelName, ...] = get_args(ModelName)


@dataclass(frozen=True)
class ParametricFit:
    """A ``lambert`` or ``lambert+ggx`` fit of every sample.

    Attributes
    ----------
    name : str, "lambert" or "lambert+ggx" (a ``ParametricModelName``; typed str because
        saved fits are read back under the names stored in their file)
    normals : ndarray, shape (P, 3), float64, unit normals the model uses (stored, or fitted)
    rho_d : ndarray, shape (P, 3), float32, diffuse albedo per channel (f = rho_d / pi)
    f0 : ndarray, shape (P, 3), float32, specular reflectance (0 for ``lambert``)
    alpha : ndarray, shape (P,), float32, GGX roughness (1 for ``lambert``, unused)
    lit : ndarray, shape (P, T), uint8, 1 lit (or unknown), 0 shadowed, per measured light
        (marks are 0 or 1: a byte each, a quarter of float32's memory at millions of samples)
    fitted : ndarray, shape (P,), bool, samples with at least one usable observation
    loo : LooError
    normals_fitted : bool, the normals were fitted (photometric stereo, refinement)
    """

    name: str
    normals: NDArray[np.float64]
    rho_d: NDArray[np.float32]
    f0: NDArray[np.float32]
    alpha: NDArray[np.float32]
    lit: NDArray[np.uint8]
    fitted: NDArray[np.bool_]
    loo: LooError
    normals_fitted: bool = False

    @property
    def parameters(self) -> int:
        """Parameters per sample the model fits (a fitted normal counts two)."""
        return (3 if self.name == "lambert" else 7) + (2 if self.normals_fitted else 0)


@dataclass(frozen=True)
class BasisFit:
    """A linear-basis fit (``ptm``, ``hsh2``, ``hsh3``) of every pixel.

    Attributes
    ----------
    name : str, "ptm", "hsh2" or "hsh3" (a ``BasisModelName``)
    coefficients : ndarray, shape (P, B, 3), float32
        value(l) = sum_k coefficients[p, k] basis_k(l), l in the camera frame.
    loo : LooError
    """

    name: str
    coefficients: NDArray[np.float32]
    loo: LooError

    @property
    def parameters(self) -> int:
        """Parameters per pixel the model fits: B coefficients for each of R, G, B."""
        return int(self.coefficients.shape[1]) * 3


#: Either kind of fit; ``isinstance`` tells them apart.
Fit = ParametricFit | BasisFit


@dataclass(frozen=True)
class SampleModels:
    """Every fitted model of one field, with what relighting needs to evaluate them.

    Attributes
    ----------
    kind : str, "points" or "pixels" (the field's sample kind)
    light_directions : ndarray, shape (T, 3), float64, the measured lights (rig frame)
    camera_frame : ndarray, shape (3, 3), float64
        Pixel fields: rows are the camera's x (right), y (up), z (toward the camera) in the rig
        frame, the frame of the basis models' light directions; identity for point fields.
    view_direction : ndarray, shape (3,), float64, or None
        Pixel fields: the distant camera's direction (the view of every pixel); None for points.
    points : ndarray, shape (P, 3), float64, or None (pixel fields)
    fits : mapping of model name to ParametricFit or BasisFit, in fitting order
    sample_count : int, P
    mark_directions : ndarray, shape (M, 3), float64, or None
        Directions of the columns of the parametric fits' ``lit`` marks when they go beyond
        the measured lights (:func:`processing.sample_models.with_geometric_visibility`: the
        T measured lights, then the geometric ones); None: the measured lights.
    """

    kind: str
    light_directions: NDArray[np.float64]
    camera_frame: NDArray[np.float64]
    view_direction: NDArray[np.float64] | None
    points: NDArray[np.float64] | None
    fits: Mapping[str, Fit]
    sample_count: int
    mark_directions: NDArray[np.float64] | None = None

    def fit(self, name: str) -> Fit:
        """The fit of model ``name``; InputError lists the fitted ones."""
        try:
            return self.fits[name]
        except KeyError:
            raise InputError(
                f"model {name!r} was not fitted; fitted models: {', '.join(self.fits)}"
            ) from None
