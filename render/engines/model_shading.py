"""Shading per-sample models under an environment's lights: any lighting, any view.

The models of :mod:`processing.sample_models` are evaluated against an environment's lights:

    L_p = sum_d f_p(w_d, v_p) max(0, n_p . w_d) V_p(w_d) E_d                 (parametric)
    L_p = sum_k c_pk sum_d B_k(w_d') E_d                                      (linear bases)

with E_d the light of direction w_d (radiance x sr): either K sampled lights of the panorama
(TMED or another sampler, Voronoi-gathered: :class:`processing.lights.LightSet`) or a
pre-filtered grid (the panorama summed exactly into h x 2h blocks, each a light at its
energy-weighted centroid, as the simulator's ground truth does). v_p is the direction from each
sample toward the wanted camera (the camera direction for a pixel field), so highlights move
with the view as the fitted BRDF says, instead of blending the captured views.

Where the light comes from outside the measured lights' region (below the lowest ring, or below
the horizon, where a rig has no lights):

- parametric models evaluate the fitted BRDF there physically, with max(0, n . w); only the
  shadow marks V must be extrapolated. ``measured``: the barycentric interpolation of the
  measured marks with the ``clamp`` policy (V of the nearest boundary edge of the measured
  region); unshadowed samples have V = 1 at every measured light, so they are exact whatever
  the direction, cast shadows from below are guessed from the lowest lights. ``geometry``:
  marks from shadow maps of the field's own point cloud complete the measured ones (outside
  the region, or everywhere), :func:`processing.sample_models.with_geometric_visibility`;
  ``auto`` takes them when they predict held-out measured marks better than interpolation
  does (:func:`processing.sample_models.shadow_mark_errors`), so the choice is made on
  measurements, never on ground truth.
- linear bases are evaluated at the direction clamped to the measured region (the point of its
  nearest boundary edge, as the interpolation's ``clamp`` policy): a polynomial extrapolated
  far beyond its data is unbounded.
- pixel fields (RTI: a flat object on its support, camera straight above) receive no light from
  behind the object plane (camera-frame z <= 0), whatever the model.

Samples without any usable observation (no camera sees them lit) take the parameters of the
nearest fitted sample and are reported as holes (:class:`render.engines.interpolated.RelitImage`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.brdf import cosine, shade_light, toward_eye
from core.camera_model import PinholeCamera
from core.colour import REC709_LUMINANCE
from core.errors import InputError
from core.light_set import LightSet
from processing.interpolation import interpolation_weights
from processing.sample_models import (
    BasisFit,
    ModelChoice,
    ParametricFit,
    SampleModels,
    evaluate_basis,
)

__all__ = [
    "ModelLighting",
    "fill_sources",
    "prepare_lighting",
    "relight_models",
    "shade_parametric",
    "viewer_of",
]


@dataclass(frozen=True)
class ModelLighting:
    """An environment's lights prepared for one field's models.

    Attributes
    ----------
    lights : LightSet, the D lights that carry light
    visibility_indices, visibility_weights : ndarray, shape (D, 3), int64 / float64
        Barycentric weights (``clamp`` policy) of each light over the directions of the shadow
        marks (``SampleModels.mark_directions`` when the marks were completed by geometric ones,
        else the measured lights): V_p(w_d) = sum_j weights[d, j] lit[p, indices[d, j]].
    reaches : ndarray, shape (D,), bool, lights that may reach the samples (pixel fields: in
        front of the object plane; point fields: all)
    basis : dict of model name to ndarray (B, 3), float64
        Linear-basis models: sum_d B_k(w_d') E_d over the lights that reach the object.
    outside_fraction : float
        Share of the lights' luminous energy from outside the measured region.
    """

    lights: LightSet
    visibility_indices: NDArray[np.int64]
    visibility_weights: NDArray[np.float64]
    reaches: NDArray[np.bool_]
    basis: dict[str, NDArray[np.float64]]
    outside_fraction: float


def prepare_lighting(models: SampleModels, lights: LightSet) -> ModelLighting:
    """Interpolation weights and basis integrals of ``lights`` for ``models``."""
    lights = lights.nonempty()
    measured = models.light_directions
    weights = interpolation_weights(measured, lights.directions, "barycentric", policy="clamp")
    marks = weights
    if models.mark_directions is not None:
        # Shadow marks completed beyond the measured lights: interpolate over all of them.
        marks = interpolation_weights(
            models.mark_directions, lights.directions, "barycentric", policy="clamp"
        )
    if models.kind == "pixels":
        # A flat RTI object lies on its support: no light from behind the object plane.
        reaches = lights.directions @ models.camera_frame[2] > 0.0
    else:
        reaches = np.ones(len(lights.directions), dtype=bool)
    basis: dict[str, NDArray[np.float64]] = {}
    if any(isinstance(f, BasisFit) for f in models.fits.values()):
        # Bases are evaluated at the direction clamped to the measured region (the chord point
        # the barycentric clamp weights describe), never extrapolated.
        clamped = np.einsum("dj,djk->dk", weights.weights, measured[weights.indices])
        clamped /= np.linalg.norm(clamped, axis=1, keepdims=True)
        inside = np.where(weights.outside[:, None], clamped, lights.directions)
        camera_directions = inside @ models.camera_frame.T
        light = lights.rgb * reaches[:, None]
        for name, fit in models.fits.items():
            if isinstance(fit, BasisFit):
                basis[name] = evaluate_basis(name, camera_directions).T @ light
    luma = lights.rgb @ REC709_LUMINANCE.astype(np.float64)
    total = float(luma.sum())
    outside = float(luma[weights.outside].sum()) / total if total > 0 else 0.0
    return ModelLighting(
        lights=lights,
        visibility_indices=np.ascontiguousarray(marks.indices),
        visibility_weights=np.ascontiguousarray(marks.weights),
        reaches=reaches,
        basis=basis,
        outside_fraction=outside,
    )


def fill_sources(models: SampleModels, name: str) -> NDArray[np.int64]:
    """The sample whose parameters each sample uses: itself, or the nearest fitted sample.

    Returns
    -------
    ndarray, shape (P,), int64 (pixel fields and fully fitted fields: the identity)
    """
    fit = models.fit(name)
    identity = np.arange(models.sample_count, dtype=np.int64)
    if not isinstance(fit, ParametricFit) or fit.fitted.all() or not fit.fitted.any():
        return identity
    if models.points is None:
        return identity  # pixels without signal relight to 0 (their fit is all zeros)
    fitted = np.flatnonzero(fit.fitted)
    _, nearest = cKDTree(models.points[fitted]).query(models.points[~fit.fitted])
    identity[~fit.fitted] = fitted[np.asarray(nearest, dtype=np.int64)]
    return identity


def viewer_of(
    models: SampleModels, camera: PinholeCamera
) -> tuple[NDArray[np.float64], bool, NDArray[np.float64]]:
    """Where the samples are seen from: (eye, distant, points) for the shading kernels.

    A pixel field is seen from its camera's direction (distant); points from the camera's
    position, each sample toward it.
    """
    points = models.points if models.points is not None else np.zeros((1, 3))
    if models.kind == "pixels":
        assert models.view_direction is not None
        return np.asarray(models.view_direction, dtype=np.float64), True, points
    return np.asarray(camera.position, dtype=np.float64), False, points


def relight_models(
    models: SampleModels,
    choice: ModelChoice,
    lighting: ModelLighting,
    camera: PinholeCamera,
    *,
    needed: NDArray[np.bool_] | None = None,
    sources: dict[str, NDArray[np.int64]] | None = None,
) -> NDArray[np.float32]:
    """Radiance (P, 3), float32, of every needed sample for ``camera`` under ``lighting``.

    Parameters
    ----------
    models : SampleModels
    choice : ModelChoice, which model each sample uses
    lighting : ModelLighting of these models
    camera : PinholeCamera, the view (a pixel field's own camera)
    needed : ndarray, shape (P,), bool, optional; samples to relight (others are 0)
    sources : per model, :func:`fill_sources` (computed here when None)
    """
    p_count = models.sample_count
    mask = np.ones(p_count, dtype=bool) if needed is None else np.asarray(needed, dtype=bool)
    if mask.shape != (p_count,):
        raise InputError(f"needed must have shape ({p_count},), got {mask.shape}")
    which = choice.sample_model(p_count)
    out = np.zeros((p_count, 3), dtype=np.float32)
    lights = lighting.lights
    eye, distant, points = viewer_of(models, camera)
    for index, name in enumerate(choice.names):
        samples = np.flatnonzero(mask & (which == index)).astype(np.int64)
        if samples.size == 0:
            continue
        fit = models.fit(name)
        if isinstance(fit, BasisFit):
            out[samples] = np.einsum(
                "pbc,bc->pc", fit.coefficients[samples], lighting.basis[name]
            ).astype(np.float32)
            continue
        source = fill_sources(models, name) if sources is None else sources[name]
        shade_parametric(
            samples, source, fit.normals, fit.rho_d, fit.f0, fit.alpha, fit.lit, points,
            eye, distant, name == "lambert+ggx", lights.directions, lights.rgb,
            lighting.visibility_indices, lighting.visibility_weights, lighting.reaches, out,
        )  # fmt: skip
    return out


# The fit's and the lights' arrays one by one on purpose, as shade_precomputed takes them:
# numba kernels take arrays and scalars, not a ParametricFit or a ModelLighting.
@numba.njit(cache=True, parallel=True)
def shade_parametric(
    samples: NDArray[np.int64],
    source: NDArray[np.int64],
    normals: NDArray[np.float64],
    rho_d: NDArray[np.float32],
    f0: NDArray[np.float32],
    alpha: NDArray[np.float32],
    lit: NDArray[np.uint8],
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    distant: bool,
    with_lobe: bool,
    directions: NDArray[np.float64],
    rgb: NDArray[np.float64],
    vis_indices: NDArray[np.int64],
    vis_weights: NDArray[np.float64],
    reaches: NDArray[np.bool_],
    out: NDArray[np.float32],
) -> None:
    """Add each listed sample's parametric shading under the lights to ``out`` (P, 3).

    Per sample, every light: the fitted BRDF times the cosine (:func:`core.brdf.shade_light`),
    the interpolated shadow marks and the light's rgb (D, 3), added to ``out`` (the
    precomputed lighting adds its brightest lights to its own sum this way). The sample's own
    normal, the parameters and marks of its ``source`` (itself unless it had no observation);
    the arrays are those of :class:`processing.sample_models.ParametricFit` and
    :class:`ModelLighting`, the viewer that of :func:`viewer_of`.
    """
    for j in numba.prange(samples.shape[0]):
        p = samples[j]
        q = source[p]
        normal = (normals[p, 0], normals[p, 1], normals[p, 2])
        view = toward_eye(points, p, eye, distant)
        if cosine(normal, view) <= 0.0:
            continue
        rho = (rho_d[q, 0], rho_d[q, 1], rho_d[q, 2])
        f = (f0[q, 0], f0[q, 1], f0[q, 2])
        a = alpha[q]
        r = g = b = 0.0
        for d in range(directions.shape[0]):
            if not reaches[d]:
                continue
            light = (directions[d, 0], directions[d, 1], directions[d, 2])
            if cosine(normal, light) <= 0.0:
                continue  # behind the surface: no need of its shadow marks
            visible = 0.0
            for k in range(vis_indices.shape[1]):
                visible += vis_weights[d, k] * lit[q, vis_indices[d, k]]
            if visible <= 0.0:
                continue
            shade = shade_light(normal, light, view, rho, f, a, with_lobe)
            r += shade[0] * visible * rgb[d, 0]
            g += shade[1] * visible * rgb[d, 1]
            b += shade[2] * visible * rgb[d, 2]
        out[p, 0] += r
        out[p, 1] += g
        out[p, 2] += b
