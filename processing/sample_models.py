"""Per-sample reflectance models fitted to a measured field, chosen by leave-one-light-out error.

Interpolating a reflectance field linearly between its T measured lights and S cameras (the
paper's eq. 1-3) blurs everything finer than the light spacing: a 30-light rig misses a GGX
lobe of roughness 0.2 by 13-20 %. Here every surface sample gets a small model fitted to all of
its measured values, and relighting goes through the model (:mod:`render.model_relight`). The
model of a field is chosen by its error on held-out measured lights (leave one light out,
"LOO"), never by ground truth, so the choice works on real captures too.

Models (``MODELS``)
-------------------
``lambert``
    f = rho_d / pi: RGB albedo. Point fields use the stored normal; pixel fields (one fixed
    view, RTI) a photometric-stereo normal.
``lambert+ggx``
    f = rho_d / pi + F0 D(h) G1(wi) G1(wo) / (4 cos(theta_i) cos(theta_o)): RGB albedo, RGB
    constant F0, GGX roughness alpha, separable Smith masking: the lobe of :mod:`core.brdf`,
    the simulator's model.
``ptm``, ``hsh2``, ``hsh3`` (pixel fields)
    Linear bases over the light direction in the camera frame: the 6-term biquadratic
    polynomial texture map (Malzbender et al. 2001) and hemispherical harmonics of order 2 and
    3 (4 and 9 terms, Gautron et al. 2004), one set of RGB coefficients per pixel.

Measured values are modelled as F[s, t, p] = f(l_t, v_sp) max(0, n_p . l_t) V[p, t]: l_t the
light, v_sp the direction from the sample toward camera s (the camera direction itself for a
pixel field, whose camera is distant), V the light's visibility (cast shadows).

Fitting the parametric models
-----------------------------
For a fixed alpha and normal the model is linear in (rho_d, F0), channel by channel, with the
same two basis values for R, G and B: a 2 x 2 non-negative least-squares problem per channel,
solved in closed form. Alpha is chosen by a log-spaced grid over ``ALPHA_RANGE`` then a golden
section search on log alpha around the best grid node. A lobe must be identified by the data:
some lit observation must see it at ``LOBE_PEAK`` of its peak or more (D(h) / D(n) >= 0.01:
a half vector within about 3 alpha of the normal; far in its tail D is proportional to
alpha^2, so only F0 alpha^2 would be fitted) and it must light at least ``MIN_LOBE_SUPPORT``
observations (the participation ratio of its basis values). Otherwise a needle lobe fits one
noisy value, or a tail fits noise with an arbitrary F0, and it shines wherever light comes
from directions no light was measured from. Measured on the glossy sphere (30 x 30) with 2 %
noise under the full courtyard, at a view between cameras: 12.8 % error without the peak
check, 0.89 / 0.43 / 0.35 / 0.49 / 0.71 % with LOBE_PEAK = 0.0003 / 0.003 / 0.01 / 0.1 / 0.5
(noise-free: 0.07 % at 0.01).

Everything runs per sample in one numba kernel, parallel over samples, over all its
observations (every camera that sees it, every light).

Shadows. A shadowed value is ~0 where the unshadowed model predicts light. After a fit, the
best scale of the model for light t over the cameras, k_t = sum b m / sum m^2, says whether t
reached the sample: k_t < ``SHADOW_RATIO`` marks it shadowed and it leaves the fit; fit and
marks alternate until the marks settle (at most ``SHADOW_ITERATIONS`` fits). The marks are
kept as ``lit`` (P, T): 1 lit, 0 shadowed, 1 where the measurements carry no information (the
light is behind the sample's normal, or no camera sees the sample: the attached shadow is the
model's max(0, n . l), not V). Relighting interpolates ``lit`` to new light directions.

Pixel fields: the normal is first found by photometric stereo on luminance over each pixel's
middle-ranked lights (the darkest ``PS_DARK`` and brightest ``PS_BRIGHT`` fractions, likely
shadows and highlights, left out); with ``refine_normals`` a pattern search then moves it to
the model's least-squares optimum (the linear parameters re-solved at every step, alpha
between rounds: a coordinate descent).

Visibility beyond the measured lights (point fields). The marks are known at the T measured
lights only. :func:`with_geometric_visibility` completes them with shadow maps of the field's
own point cloud (:func:`geometric_shadow_marks`) at directions where no light was measured (or
everywhere), and :func:`shadow_mark_errors` says, on held-out measured lights, whether the
geometry or the interpolation of the other lights' marks predicts the measured marks better.

Leave one light out
-------------------
For each light t the model is refitted without light t (all its cameras) and predicts light t's
measured values; ``LooError`` sums the squared errors over every observation of a visible
sample (shadowed ones included) and the measured energy over the same observations, so every
model of a field and the interpolation baselines (:func:`interpolation_loo`) are scored on the
same values. Linear bases: the closed form e_i / (1 - h_ii) of the hat matrix. Parametric
models: the exact refit of (rho_d, F0) by removing light t's normal-equation terms, at the
fitted alpha, normal and shadow marks (so slightly optimistic); the held-out light's
visibility is the barycentric interpolation of the other lights' marks (it cannot be
measured, as at any new light direction).

:func:`choose_model` picks, per field or per sample, the simplest model whose LOO error is
within a tolerance of the best (a parsimony rule: models that fit equally well tie within
noise, and the simpler one extrapolates more safely).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.special import factorial, lpmv
from tqdm import tqdm

from core.brdf import specular_lobe
from core.camera_model import rig_to_camera
from core.colour import REC709_LUMINANCE
from core.directions import fibonacci_sphere
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from core.point_spacing import median_neighbour_distance
from core.splat import depth_at_points, zbuffer
from processing.interpolation import interpolation_weights

__all__ = [
    "ALPHA_RANGE",
    "BASIS_MODELS",
    "MODELS",
    "PARAMETRIC_MODELS",
    "BasisFit",
    "LooError",
    "ModelChoice",
    "ModelScore",
    "ParametricFit",
    "SampleModels",
    "basis_size",
    "choose_model",
    "evaluate_basis",
    "fit_sample_models",
    "format_loo_table",
    "geometric_shadow_marks",
    "interpolation_loo",
    "leave_one_out_weights",
    "photometric_stereo",
    "shadow_mark_errors",
    "with_geometric_visibility",
]

PARAMETRIC_MODELS = ("lambert", "lambert+ggx")
BASIS_MODELS = ("ptm", "hsh2", "hsh3")
MODELS = PARAMETRIC_MODELS + BASIS_MODELS

#: GGX roughness searched (a lobe narrower than 0.02 is a mirror no rig samples).
ALPHA_RANGE = (0.02, 1.0)
#: Log-spaced alpha grid nodes, then golden-section steps between the best node's neighbours.
ALPHA_GRID = 16
GOLDEN_STEPS = 14
#: A GGX lobe is identified when some lit observation sees it at this fraction of its peak or
#: more (D(h) / D(n)) and it lights at least MIN_LOBE_SUPPORT observations (participation
#: ratio (sum a)^2 / sum a^2 of its basis values); otherwise the fit drops it at that alpha.
LOBE_PEAK, MIN_LOBE_SUPPORT = 0.01, 3.0
#: A light whose best model scale k_t is below this is shadowed for that sample.
SHADOW_RATIO = 0.5
#: Fits of the fit / shadow-mark alternation, at most.
SHADOW_ITERATIONS = 4
#: Photometric stereo leaves out each pixel's darkest and brightest lights (these fractions).
PS_DARK, PS_BRIGHT = 0.25, 0.10
#: Normal refinement: first step and smallest step (radians) of the pattern search.
REFINE_STEP, REFINE_MIN_STEP = 0.08, 0.002
#: Rounds of normal (at fixed alpha) then alpha refinement.
REFINE_ROUNDS = 3
#: Parsimony: a simpler model is chosen when its LOO relative RMSE is within
#: best x (1 + rel) + abs of the best model's.
PARSIMONY_RELATIVE, PARSIMONY_ABSOLUTE = 0.05, 1e-3
#: Bytes of radiance held in memory while fitting: the whole field in its storage dtype when it
#: fits (one pass over the store), else float32 chunks of samples (one pass per chunk).
FIT_MEMORY_BYTES = 6 << 30
#: Geometric shadow maps: cells per point spacing, splat radius (cells), depth bias (spacings),
#: largest map side (cells).
SHADOW_MAP_CELLS, SHADOW_SPLAT_CELLS, SHADOW_BIAS, SHADOW_MAP_MAX = 1.5, 1.5, 2.0, 4096
#: Directions (a Fibonacci sphere) of the geometric shadow marks that complete the measured ones.
GEOMETRY_DIRECTIONS = 512

_LUMA = REC709_LUMINANCE.astype(np.float64)


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


@dataclass(frozen=True)
class ParametricFit:
    """A ``lambert`` or ``lambert+ggx`` fit of every sample.

    Attributes
    ----------
    name : str, "lambert" or "lambert+ggx"
    normals : ndarray, shape (P, 3), float64, unit normals the model uses (stored, or fitted)
    rho_d : ndarray, shape (P, 3), float32, diffuse albedo per channel (f = rho_d / pi)
    f0 : ndarray, shape (P, 3), float32, specular reflectance (0 for ``lambert``)
    alpha : ndarray, shape (P,), float32, GGX roughness (1 for ``lambert``, unused)
    lit : ndarray, shape (P, T), float32, 1 lit (or unknown), 0 shadowed, per measured light
    fitted : ndarray, shape (P,), bool, samples with at least one usable observation
    loo : LooError
    normals_fitted : bool, the normals were fitted (photometric stereo, refinement)
    """

    name: str
    normals: NDArray[np.float64]
    rho_d: NDArray[np.float32]
    f0: NDArray[np.float32]
    alpha: NDArray[np.float32]
    lit: NDArray[np.float32]
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
    name : str
    coefficients : ndarray, shape (P, B, 3), float32
        value(l) = sum_k coefficients[p, k] basis_k(l), l in the camera frame.
    loo : LooError
    """

    name: str
    coefficients: NDArray[np.float32]
    loo: LooError

    @property
    def parameters(self) -> int:
        return int(self.coefficients.shape[1]) * 3


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
        the measured lights (:func:`with_geometric_visibility`: the T measured lights, then
        the geometric ones); None: the measured lights.
    """

    kind: str
    light_directions: NDArray[np.float64]
    camera_frame: NDArray[np.float64]
    view_direction: NDArray[np.float64] | None
    points: NDArray[np.float64] | None
    fits: Mapping[str, Fit]
    sample_count: int
    mark_directions: NDArray[np.float64] | None = None

    @property
    def visibility_directions(self) -> NDArray[np.float64]:
        """Directions of the ``lit`` columns, shape (M, 3): relighting interpolates over them."""
        return self.light_directions if self.mark_directions is None else self.mark_directions

    def fit(self, name: str) -> Fit:
        """The fit of model ``name``; InputError lists the fitted ones."""
        try:
            return self.fits[name]
        except KeyError:
            raise InputError(
                f"model {name!r} was not fitted; fitted models: {', '.join(self.fits)}"
            ) from None


@dataclass(frozen=True)
class ModelScore:
    """One row of the LOO table.

    Attributes
    ----------
    name : str, model (or interpolation scheme)
    loo_relative_rmse : float, over the whole field
    parameters : int, per sample
    chosen_share : float, share of samples that chose this model (per-sample choice), else 0/1
    """

    name: str
    loo_relative_rmse: float
    parameters: int
    chosen_share: float


@dataclass(frozen=True)
class ModelChoice:
    """The model(s) chosen by LOO error.

    Attributes
    ----------
    names : tuple of str, the candidate models, simplest first
    chosen : str, the model chosen for the whole field
    per_sample : ndarray, shape (P,), int8, or None
        Index into ``names`` of each sample's model (per-sample choice), None for one model.
    table : tuple of ModelScore, one per candidate, in ``names`` order
    """

    names: tuple[str, ...]
    chosen: str
    per_sample: NDArray[np.int8] | None
    table: tuple[ModelScore, ...]

    def sample_model(self, count: int) -> NDArray[np.int8]:
        """Index into ``names`` of each of ``count`` samples' model; shape (count,), int8."""
        if self.per_sample is not None:
            return self.per_sample
        return np.full(count, self.names.index(self.chosen), dtype=np.int8)


# --------------------------------------------------------------------------------------------
# Linear bases (pixel fields)


def basis_size(name: str) -> int:
    """Number of basis functions of a linear-basis model."""
    sizes = {"ptm": 6, "hsh2": 4, "hsh3": 9}
    if name not in sizes:
        raise InputError(f"{name!r} is not a linear-basis model; use one of {BASIS_MODELS}")
    return sizes[name]


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


def _fit_basis(
    name: str, values: NDArray[np.float32], camera_lights: NDArray[np.float64]
) -> BasisFit:
    """Least-squares basis coefficients of every pixel and their closed-form LOO error.

    ``values`` (T, P, 3) are one camera's slab; the design (T, B) is shared by all pixels, so
    one pseudo-inverse fits them all and the hat matrix gives every LOO residual at once.
    """
    t_count, p_count, _ = values.shape
    design = evaluate_basis(name, camera_lights)
    if t_count <= design.shape[1]:
        raise InputError(
            f"model {name!r} has {design.shape[1]} terms; it needs more than that many lights, "
            f"the field has {t_count}"
        )
    pinv = np.linalg.pinv(design)  # (B, T)
    flat = values.reshape(t_count, -1).astype(np.float64)
    coefficients = pinv @ flat  # (B, P 3)
    leverage = np.einsum("tb,bt->t", design, pinv)
    residual = flat - design @ coefficients
    held_out = residual / np.maximum(1.0 - leverage, 1e-9)[:, None]
    squared = (held_out**2).reshape(t_count, p_count, 3).sum(axis=(0, 2))
    energy = (flat**2).reshape(t_count, p_count, 3).sum(axis=(0, 2))
    return BasisFit(
        name=name,
        coefficients=coefficients.reshape(-1, p_count, 3).transpose(1, 0, 2).astype(np.float32),
        loo=LooError(squared, energy),
    )


# --------------------------------------------------------------------------------------------
# Photometric stereo (pixel fields)


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


# --------------------------------------------------------------------------------------------
# Leave-one-light-out visibility weights and the interpolation baselines


def leave_one_out_weights(
    light_directions: NDArray[np.floating], method: str = "barycentric", *, m: int = 3
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
        raise InputError(f"leaving one light out needs at least 2 lights, got {t_count}")
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


def interpolation_loo(field: ReflectanceField, method: str, *, m: int = 3) -> LooError:
    """LOO error of interpolating over the measured lights (the linear relighting's predictor).

    Every measured light is predicted from the other T - 1 by ``method`` (at each camera, for
    every sample it sees) and compared with its measured values: the same observations and
    normalisation as the models' :class:`LooError`.
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


# --------------------------------------------------------------------------------------------
# Parametric fits: the numba kernel


@numba.njit(cache=True)
def _solve_pair(
    s11: float, s12: float, s22: float, r1: float, r2: float
) -> tuple[float, float, float]:
    # min x^T S x - 2 x . r over x >= 0 (2 unknowns): the interior optimum if feasible, else the
    # best one-variable optimum, else 0. Returns x1, x2 and the objective (<= 0).
    x1 = x2 = best = 0.0
    if s11 > 0.0 and r1 > 0.0 and -r1 * r1 / s11 < best:
        x1, x2, best = r1 / s11, 0.0, -r1 * r1 / s11
    if s22 > 0.0 and r2 > 0.0 and -r2 * r2 / s22 < best:
        x1, x2, best = 0.0, r2 / s22, -r2 * r2 / s22
    det = s11 * s22 - s12 * s12
    if det > 1e-12 * s11 * s22 and det > 0.0:
        y1 = (s22 * r1 - s12 * r2) / det
        y2 = (s11 * r2 - s12 * r1) / det
        if y1 >= 0.0 and y2 >= 0.0 and -(y1 * r1 + y2 * r2) < best:
            x1, x2, best = y1, y2, -(y1 * r1 + y2 * r2)
    return x1, x2, best


@numba.njit(cache=True)
def _geometry(
    normal: NDArray[np.float64],
    light_of: NDArray[np.int64],
    view_of: NDArray[np.int64],
    lights: NDArray[np.float64],
    views: NDArray[np.float64],
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
) -> None:
    # Cosines of every observation for one normal; cos_i = 0 marks an observation the model
    # predicts 0 (light or view behind the surface).
    for k in range(light_of.shape[0]):
        t, s = light_of[k], view_of[k]
        ci = normal[0] * lights[t, 0] + normal[1] * lights[t, 1] + normal[2] * lights[t, 2]
        co = normal[0] * views[s, 0] + normal[1] * views[s, 1] + normal[2] * views[s, 2]
        if ci <= 0.0 or co <= 0.0:
            cos_i[k] = cos_o[k] = cos_h[k] = 0.0
            continue
        hx, hy, hz = (
            lights[t, 0] + views[s, 0],
            lights[t, 1] + views[s, 1],
            lights[t, 2] + views[s, 2],
        )
        length = math.sqrt(hx * hx + hy * hy + hz * hz)
        cos_i[k], cos_o[k] = ci, co
        cos_h[k] = (normal[0] * hx + normal[1] * hy + normal[2] * hz) / max(length, 1e-300)


@numba.njit(cache=True)
def _objective(
    alpha: float,
    with_lobe: bool,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> float:
    # Least-squares objective (minus the constant sum of b^2) over the lit observations at one
    # alpha; writes the per-channel solution (albedo in x1, F0 in x2).
    s11 = s12 = s22 = s2 = 0.0
    peak = 0.0
    a4 = alpha**4
    r1 = np.zeros(3)
    r2 = np.zeros(3)
    for k in range(cos_i.shape[0]):
        ci = cos_i[k]
        if ci <= 0.0 or lit[light_of[k]] <= 0.0:
            continue
        a1 = ci / math.pi
        a2 = 0.0
        if with_lobe:
            a2 = specular_lobe(ci, cos_o[k], cos_h[k], alpha) * ci
            d = cos_h[k] * cos_h[k] * (alpha * alpha - 1.0) + 1.0
            peak = max(peak, a4 / (d * d))  # D(h) / D(n)
        s11 += a1 * a1
        s12 += a1 * a2
        s22 += a2 * a2
        s2 += a2
        for c in range(3):
            r1[c] += a1 * values[k, c]
            r2[c] += a2 * values[k, c]
    if with_lobe and (peak < LOBE_PEAK or s2 * s2 < MIN_LOBE_SUPPORT * s22):
        # A lobe whose peak no observation sees (its far tail fixes only F0 alpha^2), or that
        # lights fewer than MIN_LOBE_SUPPORT observations (participation ratio), is not
        # identified: it would fit noise and shine wherever no light was measured from.
        s12 = s22 = 0.0
        r2[:] = 0.0
    total = 0.0
    for c in range(3):
        y1, y2, best = _solve_pair(s11, s12, s22, r1[c], r2[c])
        x1[c], x2[c] = y1, y2
        total += best
    return total


@numba.njit(cache=True)
def _best_alpha(
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> tuple[float, float]:
    # Alpha minimising the objective: the best node of the log grid, then golden section on
    # log alpha between its neighbours. Leaves x1, x2 at the returned alpha's solution.
    if not with_lobe:
        return 1.0, _objective(1.0, False, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    best, best_index = np.inf, 0
    for g in range(grid.shape[0]):
        value = _objective(grid[g], True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
        if value < best:
            best, best_index = value, g
    lo = math.log(grid[max(best_index - 1, 0)])
    hi = math.log(grid[min(best_index + 1, grid.shape[0] - 1)])
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a = hi - ratio * (hi - lo)
    b = lo + ratio * (hi - lo)
    fa = _objective(math.exp(a), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    fb = _objective(math.exp(b), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    for _ in range(golden_steps):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - ratio * (hi - lo)
            fa = _objective(math.exp(a), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
        else:
            lo, a, fa = a, b, fb
            b = lo + ratio * (hi - lo)
            fb = _objective(math.exp(b), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    alpha = grid[best_index]
    if min(fa, fb) < best:
        alpha = math.exp(a) if fa < fb else math.exp(b)
    value = _objective(alpha, True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    return alpha, value


@numba.njit(cache=True)
def _light_sums(
    alpha: float,
    with_lobe: bool,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    sums: NDArray[np.float64],
) -> None:
    # Per light t, over its observations: a1^2, a1 a2, a2^2 (columns 0-2), a1 b_c (3-5),
    # a2 b_c (6-8) over the observations the model lights, b_c^2 (9-11) over all of them.
    sums[:] = 0.0
    for k in range(cos_i.shape[0]):
        t = light_of[k]
        for c in range(3):
            sums[t, 9 + c] += values[k, c] * values[k, c]
        ci = cos_i[k]
        if ci <= 0.0:
            continue
        a1 = ci / math.pi
        a2 = specular_lobe(ci, cos_o[k], cos_h[k], alpha) * ci if with_lobe else 0.0
        sums[t, 0] += a1 * a1
        sums[t, 1] += a1 * a2
        sums[t, 2] += a2 * a2
        for c in range(3):
            sums[t, 3 + c] += a1 * values[k, c]
            sums[t, 6 + c] += a2 * values[k, c]


@numba.njit(cache=True, inline="always")
def _predicted_terms(
    sums: NDArray[np.float64], t: int, x1: NDArray[np.float64], x2: NDArray[np.float64]
) -> tuple[float, float]:
    # sum b m and sum m^2 of light t for the model x (m = x1 a1 + x2 a2), over RGB.
    cross = square = 0.0
    for c in range(3):
        cross += x1[c] * sums[t, 3 + c] + x2[c] * sums[t, 6 + c]
        square += (
            x1[c] * x1[c] * sums[t, 0]
            + 2.0 * x1[c] * x2[c] * sums[t, 1]
            + x2[c] * x2[c] * sums[t, 2]
        )
    return cross, square


@numba.njit(cache=True)
def _shadow_marks(
    sums: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
    ratio: float,
    lit: NDArray[np.float64],
) -> bool:
    # Mark light t shadowed when the model's best scale for it is below ``ratio``; lights
    # where the model predicts (almost) nothing carry no information and stay lit. Returns
    # whether any mark changed.
    t_count = sums.shape[0]
    largest = 0.0
    for t in range(t_count):
        largest = max(largest, _predicted_terms(sums, t, x1, x2)[1])
    changed = False
    for t in range(t_count):
        cross, square = _predicted_terms(sums, t, x1, x2)
        mark = 1.0
        if square > 1e-6 * largest and square > 0.0 and cross < ratio * square:
            mark = 0.0
        if mark != lit[t]:
            changed = True
        lit[t] = mark
    return changed


@numba.njit(cache=True)
def _fit_with_shadows(
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    ratio: float,
    iterations: int,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    sums: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> tuple[float, float]:
    # Alternate fit and shadow marks until the marks settle; the result is the fit of the
    # final marks (``sums`` at its alpha).
    alpha, value = 1.0, 0.0
    for _ in range(iterations):
        alpha, value = _best_alpha(
            grid, golden_steps, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2
        )
        _light_sums(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, sums)
        if not _shadow_marks(sums, x1, x2, ratio, lit):
            return alpha, value
    alpha, value = _best_alpha(
        grid, golden_steps, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2
    )
    _light_sums(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, sums)
    return alpha, value


@numba.njit(cache=True)
def _refine_normal(
    normal: NDArray[np.float64],
    alpha: float,
    with_lobe: bool,
    light_of: NDArray[np.int64],
    view_of: NDArray[np.int64],
    lights: NDArray[np.float64],
    views: NDArray[np.float64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    first_step: float,
    min_step: float,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> None:
    # Pattern search on the normal (two tangent directions, halving steps) at fixed alpha and
    # shadow marks, the linear parameters re-solved at every candidate. Leaves ``normal`` and
    # the geometry at the best normal found.
    _geometry(normal, light_of, view_of, lights, views, cos_i, cos_o, cos_h)
    best = _objective(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    step = first_step
    trial = np.empty(3)
    for _ in range(200):
        if step < min_step:
            break
        helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = np.cross(normal, helper)
        u /= math.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2)
        w = np.cross(normal, u)
        improved = False
        for move in range(4):
            sign = 1.0 if move % 2 == 0 else -1.0
            axis = u if move < 2 else w
            for c in range(3):
                trial[c] = normal[c] + sign * step * axis[c]
            trial /= math.sqrt(trial[0] ** 2 + trial[1] ** 2 + trial[2] ** 2)
            _geometry(trial, light_of, view_of, lights, views, cos_i, cos_o, cos_h)
            value = _objective(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
            if value < best - 1e-12 * abs(best):
                best = value
                normal[:] = trial
                improved = True
                break
        if not improved:
            step *= 0.5
    _geometry(normal, light_of, view_of, lights, views, cos_i, cos_o, cos_h)


@numba.njit(cache=True)
def _leave_one_out(
    sums: NDArray[np.float64],
    lit: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
    loo_indices: NDArray[np.int64],
    loo_weights: NDArray[np.float64],
) -> tuple[float, float]:
    # Leave one light out: remove light t's terms from the normal equations, re-solve, predict
    # light t with the visibility interpolated from the other lights' marks. Returns the sum
    # of squared prediction errors and of squared measured values.
    s11 = s12 = s22 = 0.0
    r1 = np.zeros(3)
    r2 = np.zeros(3)
    t_count = sums.shape[0]
    for t in range(t_count):
        if lit[t] > 0.0:
            s11 += sums[t, 0]
            s12 += sums[t, 1]
            s22 += sums[t, 2]
            for c in range(3):
                r1[c] += sums[t, 3 + c]
                r2[c] += sums[t, 6 + c]
    y1 = np.zeros(3)
    y2 = np.zeros(3)
    loo = 0.0
    energy = 0.0
    for t in range(t_count):
        for c in range(3):
            if lit[t] > 0.0:
                y1[c], y2[c], _ = _solve_pair(
                    s11 - sums[t, 0],
                    s12 - sums[t, 1],
                    s22 - sums[t, 2],
                    r1[c] - sums[t, 3 + c],
                    r2[c] - sums[t, 6 + c],
                )
            else:
                y1[c], y2[c] = x1[c], x2[c]
        visible = 0.0
        for j in range(loo_indices.shape[1]):
            visible += loo_weights[t, j] * lit[loo_indices[t, j]]
        cross, square = _predicted_terms(sums, t, y1, y2)
        measured = sums[t, 9] + sums[t, 10] + sums[t, 11]
        loo += max(measured - 2.0 * visible * cross + visible * visible * square, 0.0)
        energy += measured
    return loo, energy


@numba.njit(cache=True)
def _fit_sample(
    p: int,
    radiance: NDArray[np.float32],
    seen: NDArray[np.bool_],
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    eyes: NDArray[np.float64],
    distant: bool,
    lights: NDArray[np.float64],
    loo_indices: NDArray[np.int64],
    loo_weights: NDArray[np.float64],
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    refine: bool,
    ratio: float,
    iterations: int,
    refine_steps: NDArray[np.float64],
    out_normal: NDArray[np.float64],
    out_x1: NDArray[np.float64],
    out_x2: NDArray[np.float64],
    out_alpha: NDArray[np.float64],
    out_lit: NDArray[np.float32],
    out_loo: NDArray[np.float64],
    out_energy: NDArray[np.float64],
    out_fitted: NDArray[np.bool_],
) -> None:
    # Everything for sample p: gather its observations, fit with shadow marks, refine the
    # normal, leave each light out; writes row p of the outputs.
    s_count, t_count = radiance.shape[1], radiance.shape[2]
    # Observations of this sample: every (camera that sees it) x (light).
    n_obs = 0
    for s in range(s_count):
        if seen[p, s]:
            n_obs += t_count
    light_of = np.empty(n_obs, dtype=np.int64)
    view_of = np.empty(n_obs, dtype=np.int64)
    values = np.empty((n_obs, 3))
    views = np.zeros((s_count, 3))
    k = 0
    for s in range(s_count):
        if not seen[p, s]:
            continue
        if distant:
            views[s] = eyes[s]
        else:
            vx = eyes[s, 0] - points[p, 0]
            vy = eyes[s, 1] - points[p, 1]
            vz = eyes[s, 2] - points[p, 2]
            length = math.sqrt(vx * vx + vy * vy + vz * vz)
            views[s, 0], views[s, 1], views[s, 2] = vx / length, vy / length, vz / length
        for t in range(t_count):
            light_of[k], view_of[k] = t, s
            for c in range(3):
                values[k, c] = radiance[p, s, t, c]
            k += 1
    normal = normals[p].copy()
    cos_i = np.zeros(n_obs)
    cos_o = np.zeros(n_obs)
    cos_h = np.zeros(n_obs)
    _geometry(normal, light_of, view_of, lights, views, cos_i, cos_o, cos_h)
    lit = np.ones(t_count)
    sums = np.zeros((t_count, 12))
    x1 = np.zeros(3)
    x2 = np.zeros(3)
    usable = False
    for j in range(n_obs):
        if cos_i[j] > 0.0:
            usable = True
            break
    out_fitted[p] = usable
    if not usable:
        out_normal[p] = normal
        out_lit[p, :] = 1.0
        energy = 0.0
        for j in range(n_obs):
            for c in range(3):
                energy += values[j, c] * values[j, c]
        out_loo[p] = energy  # predicted 0
        out_energy[p] = energy
        return
    alpha, _ = _fit_with_shadows(
        grid, golden_steps, with_lobe, ratio, iterations,
        cos_i, cos_o, cos_h, light_of, values, lit, sums, x1, x2,
    )  # fmt: skip
    if refine:
        # Coordinate descent: the normal at fixed alpha, then alpha at the new normal
        # (searching alpha at every trial normal costs 30 times more for the same optimum).
        for rounds in range(REFINE_ROUNDS):
            _refine_normal(
                normal, alpha, with_lobe, light_of, view_of, lights, views, values, lit,
                refine_steps[0] * 0.5**rounds, refine_steps[1],
                cos_i, cos_o, cos_h, x1, x2,
            )  # fmt: skip
            alpha, _ = _best_alpha(
                grid, golden_steps, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit,
                x1, x2,
            )  # fmt: skip
        alpha, _ = _fit_with_shadows(
            grid, golden_steps, with_lobe, ratio, iterations,
            cos_i, cos_o, cos_h, light_of, values, lit, sums, x1, x2,
        )  # fmt: skip
    loo, energy = _leave_one_out(sums, lit, x1, x2, loo_indices, loo_weights)
    out_normal[p] = normal
    out_alpha[p] = alpha
    for c in range(3):
        out_x1[p, c], out_x2[p, c] = x1[c], x2[c]
    for t in range(t_count):
        out_lit[p, t] = lit[t]
    out_loo[p] = loo
    out_energy[p] = energy


@numba.njit(cache=True, parallel=True)
def _fit_kernel(
    radiance: NDArray[np.float32],
    seen: NDArray[np.bool_],
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    eyes: NDArray[np.float64],
    distant: bool,
    lights: NDArray[np.float64],
    loo_indices: NDArray[np.int64],
    loo_weights: NDArray[np.float64],
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    refine: bool,
    ratio: float,
    iterations: int,
    refine_steps: NDArray[np.float64],
    out_normal: NDArray[np.float64],
    out_x1: NDArray[np.float64],
    out_x2: NDArray[np.float64],
    out_alpha: NDArray[np.float64],
    out_lit: NDArray[np.float32],
    out_loo: NDArray[np.float64],
    out_energy: NDArray[np.float64],
    out_fitted: NDArray[np.bool_],
) -> None:
    # The per-sample work lives in _fit_sample: a small parallel loop compiles far faster.
    for p in numba.prange(radiance.shape[0]):
        _fit_sample(
            p, radiance, seen, points, normals, eyes, distant, lights, loo_indices, loo_weights,
            grid, golden_steps, with_lobe, refine, ratio, iterations, refine_steps, out_normal,
            out_x1, out_x2, out_alpha, out_lit, out_loo, out_energy, out_fitted,
        )  # fmt: skip


# --------------------------------------------------------------------------------------------
# Fitting a field


def _check_models(field: ReflectanceField, models: Sequence[str] | None) -> tuple[str, ...]:
    if models is None:
        return PARAMETRIC_MODELS if field.sample_kind == "points" else MODELS
    names = tuple(models)
    if not names:
        raise InputError("no models to fit; name at least one of " + ", ".join(MODELS))
    for name in names:
        if name not in MODELS:
            raise InputError(f"unknown model {name!r}; use one of {', '.join(MODELS)}")
        if name in BASIS_MODELS and field.sample_kind == "points":
            raise InputError(
                f"model {name!r} is a basis over the light direction at one fixed view; "
                f"{field.path} holds surface points seen from {field.shape[0]} cameras: use "
                f"{' or '.join(PARAMETRIC_MODELS)}"
            )
    if len(set(names)) != len(names):
        raise InputError(f"models are named more than once: {names}")
    return names


def _sample_major(field: ReflectanceField, memory_bytes: int) -> NDArray[Any] | None:
    """The whole radiance as (P, S, T, 3) in its storage dtype, read in one pass over the
    cameras, or None when it exceeds ``memory_bytes`` (then chunks are read one by one)."""
    s_count, t_count, p_count = field.shape
    if s_count * t_count * p_count * 3 * field.dtype.itemsize > memory_bytes:
        return None
    out = np.empty((p_count, s_count, t_count, 3), dtype=field.dtype)
    for s in range(s_count):
        out[:, s] = np.asarray(field.radiance[s]).transpose(1, 0, 2)
    return out


def _read_chunk(
    field: ReflectanceField, start: int, stop: int, whole: NDArray[Any] | None
) -> NDArray[np.float32]:
    """Radiance of samples start..stop as (Pc, S, T, 3), float32 (one sample's values together).

    From ``whole`` (:func:`_sample_major`) when it is in memory; else read from the store,
    which decompresses every (camera, light) chunk for each sample range.
    """
    if whole is not None:
        return np.ascontiguousarray(whole[start:stop], dtype=np.float32)
    s_count, t_count, _ = field.shape
    out = np.empty((stop - start, s_count, t_count, 3), dtype=np.float32)
    for s in range(s_count):
        slab = np.asarray(field.radiance[s, :, start:stop, :], dtype=np.float32)
        out[:, s] = slab.transpose(1, 0, 2)
    return out


def _alpha_grid(alpha_range: tuple[float, float]) -> NDArray[np.float64]:
    low, high = alpha_range
    if not 0.0 < low < high <= 1.0:
        raise InputError(f"alpha range must satisfy 0 < low < high <= 1, got {alpha_range}")
    return np.geomspace(low, high, ALPHA_GRID)


def fit_sample_models(
    field: ReflectanceField,
    models: Sequence[str] | None = None,
    *,
    alpha_range: tuple[float, float] = ALPHA_RANGE,
    shadow_ratio: float = SHADOW_RATIO,
    refine_normals: bool | None = None,
    memory_bytes: int = FIT_MEMORY_BYTES,
    progress: bool = False,
) -> SampleModels:
    """Fit per-sample models to every sample of a field and score them by leave-one-light-out.

    Parameters
    ----------
    field : ReflectanceField
        Points (S cameras, stored normals) or the pixels of one view (RTI).
    models : sequence of str, optional
        Models to fit (``MODELS``); default ``lambert`` and ``lambert+ggx`` for points, every
        model for pixels. Basis models apply to pixel fields only.
    alpha_range : (low, high), GGX roughness searched
    shadow_ratio : float in (0, 1), see the module docstring
    refine_normals : bool, optional
        Move each normal to the parametric model's optimum (pattern search). Default: on for
        pixel fields (their normals come from photometric stereo), off for point fields.
    memory_bytes : int, radiance held in memory at once (see ``FIT_MEMORY_BYTES``)
    progress : bool, show a progress bar over the chunks

    Returns
    -------
    SampleModels

    Raises
    ------
    InputError
        An unknown model, a basis model for a point field, bad ranges, too few lights.
    DatasetError
        A point field without normals.
    """
    names = _check_models(field, models)
    if not 0.0 < shadow_ratio < 1.0:
        raise InputError(f"shadow ratio must be in (0, 1), got {shadow_ratio}")
    grid = _alpha_grid(alpha_range)
    if field.shape[1] < 2:
        raise InputError(f"{field.path}: fitting needs at least 2 lights, the field has 1")
    lights = np.ascontiguousarray(field.light_directions, dtype=np.float64)
    frame, view, eyes, points = _viewing(field)
    fits: dict[str, Fit] = {}
    if field.sample_kind == "pixels":
        assert view is not None
        slab = field.camera_slab(0)
        for name in names:
            if name in BASIS_MODELS:
                fits[name] = _fit_basis(name, slab, lights @ frame.T)
        start_normals = (
            field.normals.astype(np.float64)
            if field.normals is not None
            else photometric_stereo(slab, lights, view)
        )
    else:
        assert field.normals is not None
        start_normals = field.normals.astype(np.float64)
    parametric = [n for n in names if n in PARAMETRIC_MODELS]
    if parametric:
        refine = field.sample_kind == "pixels" if refine_normals is None else refine_normals
        fitted = _fit_parametric(
            field, parametric, start_normals, eyes, points, grid,
            refine=refine, shadow_ratio=shadow_ratio, memory_bytes=memory_bytes, progress=progress,
        )  # fmt: skip
        fits.update(fitted)
    return SampleModels(
        kind=field.sample_kind,
        light_directions=lights,
        camera_frame=frame,
        view_direction=view,
        points=points,
        fits={name: fits[name] for name in names},
        sample_count=field.shape[2],
    )


def _viewing(
    field: ReflectanceField,
) -> tuple[
    NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64], NDArray[np.float64] | None
]:
    """Camera frame (3, 3), distant view (3,) or None, eyes (S, 3) and points (P, 3) or None.

    Pixel fields: the rows of ``frame`` are the camera's x, y, z in the rig frame, the view is
    the camera direction and the one "eye" is that direction (the camera is distant). Point
    fields: identity frame, no view, the camera positions, the sample points.
    """
    camera = field.cameras[0]
    if field.sample_kind == "pixels":
        if field.shape[0] != 1:
            raise DatasetError(
                f"{field.path}: a pixel field has one camera, found {field.shape[0]}"
            )
        frame = np.ascontiguousarray(rig_to_camera(np.eye(3), camera).T)
        view = np.asarray(camera.direction, dtype=np.float64)
        return frame, view, view[None, :].copy(), None
    if field.points is None or field.normals is None:
        raise DatasetError(f"{field.path}: a point field needs points and normals to fit")
    eyes = np.stack([c.position for c in field.cameras]).astype(np.float64)
    return np.eye(3), None, eyes, field.points.astype(np.float64)


def _fit_parametric(
    field: ReflectanceField,
    names: list[str],
    start_normals: NDArray[np.float64],
    eyes: NDArray[np.float64],
    points: NDArray[np.float64] | None,
    grid: NDArray[np.float64],
    *,
    refine: bool,
    shadow_ratio: float,
    memory_bytes: int,
    progress: bool,
) -> dict[str, ParametricFit]:
    """The parametric fits ``names``, chunk by chunk of samples (see fit_sample_models)."""
    s_count, t_count, p_count = field.shape
    pixels = field.sample_kind == "pixels"
    lights = np.ascontiguousarray(field.light_directions, dtype=np.float64)
    loo_indices, loo_weights = leave_one_out_weights(lights)
    whole = _sample_major(field, memory_bytes)
    # float32 chunks beside the stored copy: half the budget when the copy is in memory.
    budget = memory_bytes // 2 if whole is not None else memory_bytes
    chunk = max(1, min(p_count, int(budget // (s_count * t_count * 3 * 4))))
    outputs: dict[str, dict[str, NDArray[Any]]] = {
        name: {
            "normal": np.zeros((p_count, 3)),
            "x1": np.zeros((p_count, 3)),
            "x2": np.zeros((p_count, 3)),
            "alpha": np.ones(p_count),
            "lit": np.ones((p_count, t_count), dtype=np.float32),
            "loo": np.zeros(p_count),
            "energy": np.zeros(p_count),
            "fitted": np.zeros(p_count, dtype=bool),
        }
        for name in names
    }
    steps = np.array([REFINE_STEP, REFINE_MIN_STEP])
    for start in tqdm(range(0, p_count, chunk), desc="fit", unit="chunk", disable=not progress):
        stop = min(start + chunk, p_count)
        radiance = _read_chunk(field, start, stop, whole)
        seen = np.ascontiguousarray(field.visibility[:, start:stop].T)
        part = slice(start, stop)
        chunk_points = np.zeros((stop - start, 3)) if points is None else points[part].copy()
        for name in names:
            o = outputs[name]
            _fit_kernel(
                radiance, seen, chunk_points, np.ascontiguousarray(start_normals[part]), eyes,
                pixels, lights, loo_indices, loo_weights, grid, GOLDEN_STEPS,
                name == "lambert+ggx", refine, shadow_ratio, SHADOW_ITERATIONS, steps,
                o["normal"][part], o["x1"][part], o["x2"][part], o["alpha"][part],
                o["lit"][part], o["loo"][part], o["energy"][part], o["fitted"][part],
            )  # fmt: skip
    fits = {}
    for name in names:
        o = outputs[name]
        lobe = name == "lambert+ggx"
        fits[name] = ParametricFit(
            name=name,
            normals=o["normal"],
            rho_d=o["x1"].astype(np.float32),
            f0=(o["x2"] if lobe else np.zeros_like(o["x2"])).astype(np.float32),
            alpha=(o["alpha"] if lobe else np.ones(p_count)).astype(np.float32),
            lit=o["lit"],
            fitted=o["fitted"],
            loo=LooError(o["loo"], o["energy"]),
            normals_fitted=refine or (pixels and field.normals is None),
        )
    return fits


# --------------------------------------------------------------------------------------------
# Geometric shadow marks: completing the measured ones


def geometric_shadow_marks(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    directions: NDArray[np.floating],
    spacing: float | None = None,
) -> NDArray[np.float32]:
    """Shadow marks of every point for directional lights, from the point cloud's own geometry.

    One orthographic shadow map per direction: the points as disks one spacing wide in a
    z-buffer seen from the light (``core.splat``), a point lit when it is no deeper than the
    front surface plus a slope-scaled bias. Marks follow the fitted ones' convention: 1 lit
    or facing away (the attached shadow is the model's cosine), 0 shadowed.

    Parameters
    ----------
    points, normals : ndarray, shape (P, 3), rig frame (normals unit, outward)
    directions : ndarray, shape (G, 3), unit vectors toward the lights
    spacing : float, optional, surface distance between neighbouring points (default: the
        median nearest-neighbour distance)

    Returns
    -------
    ndarray, shape (P, G), float32
    """
    cloud = np.asarray(points, dtype=np.float64)
    normal = np.asarray(normals, dtype=np.float64)
    toward = np.asarray(directions, dtype=np.float64)
    if cloud.ndim != 2 or cloud.shape[1] != 3 or normal.shape != cloud.shape or len(cloud) < 2:
        raise InputError(
            f"points and normals must be (P, 3) with P >= 2, got {cloud.shape}, {normal.shape}"
        )
    if toward.ndim != 2 or toward.shape[1] != 3:
        raise InputError(f"shadow directions must be (G, 3), got {toward.shape}")
    gap = median_neighbour_distance(cloud, 20_000) if spacing is None else float(spacing)
    if not gap > 0:
        raise InputError(f"point spacing must be positive, got {gap}")
    marks = np.ones((len(cloud), len(toward)), dtype=np.float32)
    for g, direction in enumerate(toward / np.linalg.norm(toward, axis=1, keepdims=True)):
        helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0, 1.0, 0])
        a = np.cross(direction, helper)
        a /= np.linalg.norm(a)
        b = np.cross(direction, a)
        depth = -(cloud @ direction)  # distance along the light, up to a constant
        depth -= depth.min() - 1.0
        cols = (cloud @ a - (cloud @ a).min()) / gap * SHADOW_MAP_CELLS + 2.0
        rows = (cloud @ b - (cloud @ b).min()) / gap * SHADOW_MAP_CELLS + 2.0
        radius = np.full(len(cloud), SHADOW_SPLAT_CELLS)
        width, height = int(np.ceil(cols.max())) + 3, int(np.ceil(rows.max())) + 3
        if max(width, height) > SHADOW_MAP_MAX:
            shrink = SHADOW_MAP_MAX / max(width, height)
            cols, rows = cols * shrink, rows * shrink
            radius = np.maximum(radius * shrink, 0.75)
            width, height = int(width * shrink) + 1, int(height * shrink) + 1
        front = depth_at_points(cols, rows, zbuffer(cols, rows, depth, radius, height, width))
        cosine = normal @ direction
        # A neighbour one spacing away on the same tilted surface is spacing x tan(theta)
        # nearer the light: the bias grows with the slope.
        clipped = np.clip(cosine, 0.05, 1.0)
        slope = np.sqrt(1.0 - clipped**2) / clipped
        lit = depth <= front + SHADOW_BIAS * gap * (1.0 + slope)
        marks[:, g] = np.where(cosine > 0, lit, True)
    return marks


def with_geometric_visibility(
    models: SampleModels,
    normals: NDArray[np.floating],
    *,
    count: int = GEOMETRY_DIRECTIONS,
    everywhere: bool = False,
    spacing: float | None = None,
) -> SampleModels:
    """Complete the fitted shadow marks with geometric ones where no light was measured.

    The measured marks know the shadows only at the T measured lights; relighting interpolates
    them, and beyond the measured region (below the lowest ring, below the horizon) it could
    only clamp. This adds the marks of :func:`geometric_shadow_marks` at the directions of a
    ``count``-point Fibonacci sphere outside the measured region (``everywhere``: all of them,
    sharpening shadow edges between the measured lights too), so the marks cover the whole
    sphere. Measured marks keep their place at the measured lights.

    Parameters
    ----------
    models : SampleModels of a point field
    normals : ndarray, shape (P, 3), the field's stored normals (the shadow maps' slope bias)
    count : int, directions of the Fibonacci sphere
    everywhere : bool, also inside the measured region
    spacing : float, optional, point spacing (default: median nearest-neighbour distance)

    Returns
    -------
    SampleModels, with ``mark_directions`` (T + G, 3) and every parametric fit's ``lit``
    (P, T + G)
    """
    if models.points is None:
        raise InputError("geometric shadow marks need surface points; a pixel field has none")
    if models.mark_directions is not None:
        raise InputError("the models' shadow marks are completed already")
    if count < 1:
        raise InputError(f"geometric directions must be at least 1, got {count}")
    measured = models.light_directions
    candidates = fibonacci_sphere(count)
    if not everywhere:
        outside = interpolation_weights(measured, candidates, "nearest").outside
        candidates = candidates[outside]
    # Directions that (nearly) coincide with a measured light add nothing and would be refused
    # as duplicates by the triangulation.
    apart = np.min(np.arccos(np.clip(candidates @ measured.T, -1.0, 1.0)), axis=1) > 1e-3
    candidates = candidates[apart]
    marks = geometric_shadow_marks(models.points, normals, candidates, spacing)
    fits: dict[str, Fit] = {}
    for name, fit in models.fits.items():
        if isinstance(fit, ParametricFit):
            fit = replace(fit, lit=np.ascontiguousarray(np.concatenate([fit.lit, marks], axis=1)))
        fits[name] = fit
    return replace(
        models, fits=fits, mark_directions=np.concatenate([measured, candidates], axis=0)
    )


def shadow_mark_errors(
    models: SampleModels,
    normals: NDArray[np.floating],
    *,
    name: str | None = None,
    spacing: float | None = None,
) -> dict[str, float]:
    """How well each visibility predictor recovers the measured shadow marks of held-out lights.

    For every fitted sample and measured light in front of it, the measured mark is predicted
    (a) by interpolating the other lights' marks (barycentric, leave one light out: what
    relighting does between measured lights) and (b) by the geometric shadow map of
    :func:`geometric_shadow_marks`. The score is the mean absolute difference from the
    measured mark; the better predictor is the one to trust where nothing was measured.

    Parameters
    ----------
    models : SampleModels of a point field
    normals : ndarray, shape (P, 3), the stored normals
    name : parametric model whose marks are the reference (default: the richest fitted)
    spacing : float, optional, point spacing of the shadow maps

    Returns
    -------
    dict with "interpolated" and "geometry" (mean absolute mark error, 0..1) and "compared"
    (the number of sample-light pairs)
    """
    if models.points is None:
        raise InputError("shadow marks of a pixel field have no geometry to compare with")
    parametric = [n for n, f in models.fits.items() if isinstance(f, ParametricFit)]
    if not parametric:
        raise InputError("no parametric model was fitted: there are no shadow marks")
    fit = models.fit(name if name is not None else parametric[-1])
    assert isinstance(fit, ParametricFit)
    lights = models.light_directions
    t_count = len(lights)
    measured = fit.lit[:, :t_count]
    indices, weights = leave_one_out_weights(lights)
    interpolated = np.einsum("tj,ptj->pt", weights, measured[:, indices])
    geometry = geometric_shadow_marks(models.points, normals, lights, spacing)
    facing = (np.asarray(normals, dtype=np.float64) @ lights.T > 0) & fit.fitted[:, None]
    compared = int(facing.sum())
    if compared == 0:
        return {"interpolated": 0.0, "geometry": 0.0, "compared": 0.0}
    return {
        "interpolated": float(np.abs(interpolated - measured)[facing].mean()),
        "geometry": float(np.abs(geometry - measured)[facing].mean()),
        "compared": float(compared),
    }


# --------------------------------------------------------------------------------------------
# Choosing


def choose_model(
    models: SampleModels,
    *,
    per_sample: bool = False,
    candidates: Sequence[str] | None = None,
    relative: float = PARSIMONY_RELATIVE,
    absolute: float = PARSIMONY_ABSOLUTE,
) -> ModelChoice:
    """Pick the model(s) by leave-one-light-out error, the simplest within a tolerance.

    A model is acceptable when its LOO relative RMSE is at most best x (1 + ``relative``) +
    ``absolute``; the acceptable one with the fewest parameters is chosen. Per sample, the same
    rule applies to each sample's own LOO errors (squared: e <= (sqrt(e_best) (1 + relative) +
    absolute sqrt(energy))^2).

    Parameters
    ----------
    models : SampleModels
    per_sample : bool, choose for each sample (else one model for the whole field)
    candidates : model names to choose among (default: every fitted model)
    relative, absolute : float, the parsimony tolerance
    """
    names = tuple(models.fits) if candidates is None else tuple(candidates)
    if not names:
        raise InputError("no candidate models to choose among")
    for name in names:
        models.fit(name)
    if relative < 0 or absolute < 0:
        raise InputError(f"parsimony tolerances must be >= 0, got {relative}, {absolute}")
    order = tuple(sorted(names, key=lambda n: (models.fits[n].parameters, names.index(n))))
    errors = {n: models.fits[n].loo.relative_rmse for n in order}
    best = min(errors.values())
    chosen = next(n for n in order if errors[n] <= best * (1.0 + relative) + absolute)
    choice: NDArray[np.int8] | None = None
    shares = {n: float(n == chosen) for n in order}
    if per_sample:
        squared = np.stack([models.fits[n].loo.squared_error for n in order])  # (M, P)
        energy = models.fits[order[0]].loo.energy
        limit = (np.sqrt(squared.min(axis=0)) * (1.0 + relative) + absolute * np.sqrt(energy)) ** 2
        choice = np.argmax(squared <= limit * (1.0 + 1e-12), axis=0).astype(np.int8)
        shares = {n: float(np.mean(choice == i)) for i, n in enumerate(order)}
    table = tuple(ModelScore(n, errors[n], models.fits[n].parameters, shares[n]) for n in order)
    return ModelChoice(names=order, chosen=chosen, per_sample=choice, table=table)


def format_loo_table(rows: Sequence[ModelScore], extra: Mapping[str, float] | None = None) -> str:
    """A Markdown table of LOO relative RMSE (models, then any ``extra`` named errors)."""
    lines = [
        "| model | parameters / sample | LOO relative RMSE | chosen share |",
        "|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row.name} | {row.parameters} | {100 * row.loo_relative_rmse:.2f} % | "
            f"{100 * row.chosen_share:.0f} % |"
        )
    for name, value in (extra or {}).items():
        lines.append(f"| {name} | - | {100 * value:.2f} % | - |")
    return "\n".join(lines)
