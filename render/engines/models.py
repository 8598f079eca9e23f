"""Over 500 lines because model lighting, its numba kernel and the engine are one relight path.

Relighting through per-sample models: any lighting, any view, no interpolation of values.

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

import copy
import math
import time
from dataclasses import dataclass, replace
from typing import Literal, get_args

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.brdf import cosine, shade_light, toward_eye
from core.camera_model import PinholeCamera
from core.colour import REC709_LUMINANCE
from core.directions import panorama_directions, panorama_pixel_index, rotate_directions_yaw
from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet
from core.point_spacing import point_spacing
from processing.environment import EnvironmentLighting, LightingControls
from processing.interpolation import interpolation_weights
from processing.panorama import Panorama
from processing.sample_model_store import models_for_field
from processing.sample_models import (
    BasisFit,
    ModelChoice,
    ParametricFit,
    SampleModels,
    choose_model,
    evaluate_basis,
    fit_sample_models,
    shadow_mark_errors,
    with_geometric_visibility,
)
from processing.sampling import SamplerName
from render.engines.interpolated import Predictor, RelitImage
from render.engines.panorama_lit import PanoramaLitEngine
from render.field_view import FieldView
from render.precomputed_lighting import (
    ALPHAS,
    BRIGHT_LIGHTS,
    PanoramaPrefilter,
    SampleTransfer,
    lobe_albedo,
    prefilter_panorama,
    rotate_sh_yaw,
    sample_transfer,
    sh_norms,
    shade_precomputed,
)

__all__ = [
    "LIGHTING_MODES",
    "VISIBILITY_MODES",
    "ModelLighting",
    "ModelLightingMode",
    "ModelRelightSettings",
    "ModelRelighter",
    "Visibility",
    "fill_sources",
    "prepare_lighting",
    "relight_models",
    "viewer_of",
]

# Choices as a Literal and its get_args tuple, as processing.environment's Lighting: the
# project's one idiom for a closed set of names (the type checks callers, the tuple inputs).
ModelLightingMode = Literal["sampled", "grid", "precomputed"]
#: How an environment lights the models: K sampled lights, a pre-filtered grid summed exactly,
#: or the grid's sum split into precomputed terms, interactive
#: (:mod:`render.precomputed_lighting`).
LIGHTING_MODES: tuple[ModelLightingMode, ...] = get_args(ModelLightingMode)
Visibility = Literal["auto", "measured", "geometry-outside", "geometry"]
#: Where the shadow marks come from (point fields): the measured ones only (clamped outside the
#: measured region), completed by geometric ones outside it, or everywhere; "auto" takes the
#: geometric ones everywhere when they predict held-out measured marks better.
VISIBILITY_MODES: tuple[Visibility, ...] = get_args(Visibility)
#: "auto" trusts the geometry when its mark error plus the floor is below this share of
#: interpolation's (the floor keeps unshadowed objects, where both are ~0, on measured marks).
GEOMETRY_MARGIN, GEOMETRY_FLOOR = 0.9, 1e-3
#: Rows of the map of the measured region that precomputed lighting reads the share of light
#: from outside it off (2 x as many columns; 1.4 degrees a pixel).
OUTSIDE_MAP_HEIGHT = 128


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
        _shade_kernel(
            samples, source, fit.normals, fit.rho_d, fit.f0, fit.alpha, fit.lit, points,
            eye, distant, name == "lambert+ggx", lights.directions, lights.rgb,
            lighting.visibility_indices, lighting.visibility_weights, lighting.reaches, out,
        )  # fmt: skip
    return out


# The fit's and the lights' arrays one by one on purpose, as shade_precomputed takes them:
# numba kernels take arrays and scalars, not a ParametricFit or a ModelLighting.
@numba.njit(cache=True, parallel=True)
def _shade_kernel(
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
    # One sample per iteration, every light: the fitted BRDF times the cosine
    # (core.brdf.shade_light), the interpolated shadow marks and the light, added to ``out``
    # (the precomputed lighting adds its brightest lights to the rest). The sample's own
    # normal, the parameters (and marks) of its source (itself unless it had no observation).
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


@dataclass(frozen=True)
class ModelRelightSettings:
    """How to relight through models.

    Attributes
    ----------
    model : str
        "auto" (the field's model chosen by LOO error), "auto-per-sample" (each sample's), or a
        fitted model's name.
    lighting : "sampled" (K lights of ``sampler``), "grid" (pre-filtered panorama blocks, summed
        exactly) or "precomputed" (the same grid through precomputed transfer, a pre-filtered
        panorama and a yaw that turns coefficients: a few dot products per sample and lighting,
        :mod:`render.precomputed_lighting`)
    k, sampler, seed : sampled lighting
    grid_height : rows of the grid lighting (2 x as many columns)
    visibility : one of ``VISIBILITY_MODES`` (pixel fields: always the measured marks)
    spacing : float, optional
        Point spacing for splats and shadow maps (default: the median nearest-neighbour
        distance, :func:`core.point_spacing.point_spacing`).
    bright_lights : int, precomputed lighting: the most luminous grid blocks summed exactly
    """

    model: str = "auto"
    lighting: ModelLightingMode = "sampled"
    k: int = 128
    sampler: SamplerName = "tmed"
    seed: int = 0
    grid_height: int = 32
    visibility: Visibility = "auto"
    spacing: float | None = None
    bright_lights: int = BRIGHT_LIGHTS

    #: Relights through the field's per-sample models.
    uses_models = True

    def __post_init__(self) -> None:
        if self.lighting not in LIGHTING_MODES:
            raise InputError(
                f"unknown lighting {self.lighting!r}; use one of {', '.join(LIGHTING_MODES)}"
            )
        if self.visibility not in VISIBILITY_MODES:
            raise InputError(
                f"unknown visibility {self.visibility!r}; use one of {', '.join(VISIBILITY_MODES)}"
            )
        if self.spacing is not None and not self.spacing > 0:
            raise InputError(f"point spacing must be positive, got {self.spacing}")
        if self.bright_lights < 0:
            raise InputError(f"bright lights must be 0 or more, got {self.bright_lights}")

    @property
    def sampled_k(self) -> int | None:
        """K of the sampled lighting, None for the grid."""
        return self.k if self.lighting == "sampled" else None

    def lighting_controls(
        self,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> LightingControls:
        """The lighting this mode takes from a panorama under the user's controls."""
        if self.lighting == "precomputed":
            # The engine turns and scales its pre-filtered panorama itself; the controls carry
            # the yaw and exposure for the panorama as shown.
            return LightingControls(
                lighting="panorama", modulation=modulation, yaw_deg=yaw_deg, exposure=exposure
            )
        if self.lighting == "grid":
            return LightingControls(
                lighting="grid",
                grid_height=self.grid_height,
                modulation=modulation,
                yaw_deg=yaw_deg,
                exposure=exposure,
            )
        return LightingControls(
            lighting="sampled",
            k=self.k,
            method=self.sampler,
            seed=self.seed,
            modulation=modulation,
            centroids=True,
            yaw_deg=yaw_deg,
            exposure=exposure,
        )

    def predictors(self) -> tuple[Predictor, Predictor]:
        """What predicts an unmeasured light, and an uncaptured view: the model itself."""
        return ("model", self.model, 0), ("model", self.model, 0)

    def exact_lighting(self, grid_height: int) -> ModelRelightSettings:
        """The same models under the panorama summed into a ``grid_height`` grid."""
        return replace(self, lighting="grid", grid_height=grid_height)

    def describe(self, models: SampleModels | None = None) -> str:
        """A short name for reports (the chosen model's name when the fit is given)."""
        name = self.model if models is None else choose_model(models).chosen
        lights = {"grid": f"grid {self.grid_height}", "precomputed": "precomputed"}.get(
            self.lighting, f"K={self.k}"
        )
        return f"model {name}, {lights}"

    def open(
        self, field_store: ReflectanceField, models: SampleModels | None = None
    ) -> ModelRelighter:
        """The engine of this mode on ``field_store``, relighting through ``models``.

        When ``models`` is None, fits the field (or reads its saved fit).
        """
        return ModelRelighter(
            field_store, self, models if models is not None else models_for_field(field_store)
        )


class ModelRelighter(PanoramaLitEngine):
    """Relight one field through its fitted models under changing lightings and views.

    Parameters
    ----------
    field_store : ReflectanceField
    settings : ModelRelightSettings, optional
    models : SampleModels, optional; fitted here (:func:`fit_sample_models`) when None
    """

    settings: ModelRelightSettings

    def __init__(
        self,
        field_store: ReflectanceField,
        settings: ModelRelightSettings | None = None,
        models: SampleModels | None = None,
    ) -> None:
        self.field = field_store
        super().__init__(field_store)
        self.settings = settings or ModelRelightSettings()
        self.models = models if models is not None else fit_sample_models(field_store)
        if self.models.sample_count != field_store.shape[2]:
            raise InputError(
                f"the models are of {self.models.sample_count} samples, {field_store.path} has "
                f"{field_store.shape[2]}"
            )
        model = self.settings.model
        if model in ("auto", "auto-per-sample"):
            self.choice = choose_model(self.models, per_sample=model == "auto-per-sample")
        else:
            self.choice = choose_model(self.models, candidates=[model])
        self._spacing: float | None = self.settings.spacing
        self.mark_errors: dict[str, float] | None = None
        self.visibility = self._visibility_mode()
        if self.visibility != "measured":
            assert field_store.normals is not None
            if self._spacing is None:
                assert self.models.points is not None
                self._spacing = point_spacing(self.models.points)
            chosen = replace(self.models, fits={n: self.models.fits[n] for n in self.choice.names})
            self.models = with_geometric_visibility(
                chosen,
                field_store.normals,
                everywhere=self.visibility == "geometry",
                spacing=self._spacing,
            )
        self._sources = {
            name: fill_sources(self.models, name)
            for name in self.choice.names
            if isinstance(self.models.fits[name], ParametricFit)
        }
        unfitted = np.zeros(self.models.sample_count, dtype=bool)
        which = self.choice.sample_model(self.models.sample_count)
        for index, name in enumerate(self.choice.names):
            fit = self.models.fits[name]
            if isinstance(fit, ParametricFit):
                unfitted |= (which == index) & ~fit.fitted
        self._unfitted = unfitted
        self._lighting: ModelLighting | None = None
        self._environment: EnvironmentLighting | None = None
        self._view: FieldView | None = None
        # Precomputed lighting: the pre-filtered panorama (the last one, by identity), the yaw
        # and exposure in force and the samples' transfer (per model, made on first use).
        self._prefilter: tuple[Panorama, PanoramaPrefilter] | None = None
        self._precomputed: tuple[PanoramaPrefilter, float, float] | None = None
        self._transfers: dict[str, SampleTransfer] = {}
        self._bright: ModelLighting | None = None
        self._outside: NDArray[np.bool_] | None = None

    def _visibility_mode(self) -> Visibility:
        """The shadow marks to use: the setting, or for "auto" the better predictor."""
        mode = self.settings.visibility
        if self.models.kind == "pixels" or not any(
            isinstance(self.models.fits[n], ParametricFit) for n in self.choice.names
        ):
            if mode not in ("auto", "measured"):
                raise InputError(
                    f"visibility {mode!r} needs surface points and a parametric model; "
                    f"{self.field.path} relights through {', '.join(self.choice.names)}"
                )
            return "measured"
        if mode != "auto":
            return mode
        assert self.field.normals is not None
        errors = shadow_mark_errors(self.models, self.field.normals, spacing=self._spacing)
        self.mark_errors = errors
        better = errors["geometry"] + GEOMETRY_FLOOR < GEOMETRY_MARGIN * errors["interpolated"]
        return "geometry" if better else "measured"

    @property
    def environment(self) -> EnvironmentLighting | None:
        """The current lighting: the panorama as relit (yaw, exposure) and its lights.

        Under precomputed lighting, the adjusted panorama it was handed
        (:meth:`take_panorama`), whose yaw its terms turn to.
        """
        return self._environment

    def take_panorama(self, visible: Panorama, lighting: EnvironmentLighting) -> None:
        """Light with ``visible`` turned by ``lighting``'s controls, and show ``lighting``.

        The precomputed lighting turns its own pre-filter of ``visible`` (the panorama before
        the yaw and exposure) by the yaw and scales it by the exposure, on purpose: its
        harmonics, grid and bright lights turn about +z as they stand, where pre-filtering the
        adjusted panorama anew would cost about a second a yaw (the viewer's drag, a
        sequence's frames). The panorama shown is still the one the controls adjusted once
        (``lighting.panorama``), which the mode's choice and the guards judged. The other
        lightings take ``lighting``'s lights.
        """
        if self.settings.lighting == "precomputed":
            controls = lighting.controls
            self._precompute(self._prefiltered(visible), controls.yaw_deg, controls.exposure)
            self._environment = lighting
        else:
            self.set_environment(lighting)

    def set_environment(self, lighting: EnvironmentLighting) -> None:
        """Prepare the lights of a lighting (from :func:`light_environment`)."""
        if self.settings.lighting == "precomputed":
            self._precompute(self._prefiltered(lighting.panorama), 0.0, 1.0)
        else:
            self.set_lights(lighting.light_set())
        self._environment = lighting

    def _prefiltered(self, panorama: Panorama) -> PanoramaPrefilter:
        """The panorama pre-filtered (about a second), reused while the same one lights."""
        if self._prefilter is None or self._prefilter[0] is not panorama:
            prefilter = prefilter_panorama(panorama.rgb, self.settings.bright_lights)
            self._prefilter = (panorama, prefilter)
        return self._prefilter[1]

    def _precompute(self, prefilter: PanoramaPrefilter, yaw_deg: float, exposure: float) -> None:
        # The grid lights turned by the yaw are the exact grid of the turned panorama: the
        # linear bases sum over them (prepared in full only when a basis model is chosen), and
        # the share of light from outside the measured region is read off a map of the region.
        grid = prefilter.lights
        lights = LightSet(
            rotate_directions_yaw(grid.directions, yaw_deg),
            grid.rgb * exposure,
            grid.solid_angle_sr,
        )
        if any(isinstance(self.models.fits[n], BasisFit) for n in self.choice.names):
            self._lighting = prepare_lighting(self.models, lights)
        else:
            self._lighting = ModelLighting(
                lights=lights,
                visibility_indices=np.zeros((0, 3), np.int64),
                visibility_weights=np.zeros((0, 3)),
                reaches=np.ones(len(lights.directions), dtype=bool),
                basis={},
                outside_fraction=self._outside_share(lights),
            )
        bright = prefilter.bright
        self._bright = prepare_lighting(
            self.models,
            LightSet(rotate_directions_yaw(bright.directions, yaw_deg), bright.rgb * exposure),
        )
        self._precomputed = (prefilter, yaw_deg, exposure)

    def _outside_share(self, lights: LightSet) -> float:
        """Share of the lights' luminous energy from outside the measured region."""
        if self._outside is None:
            rows = OUTSIDE_MAP_HEIGHT
            directions = panorama_directions(rows, 2 * rows).reshape(-1, 3)
            weights = interpolation_weights(
                self.models.light_directions, directions, "barycentric", policy="clamp"
            )
            self._outside = weights.outside.reshape(rows, 2 * rows)
        rows_of, cols_of = panorama_pixel_index(lights.directions, *self._outside.shape)
        luma = lights.rgb @ REC709_LUMINANCE.astype(np.float64)
        total = float(luma.sum())
        return float(luma[self._outside[rows_of, cols_of]].sum()) / total if total > 0 else 0.0

    def with_lighting(self, settings: ModelRelightSettings) -> ModelRelighter:
        """A copy of this relighter with other lighting settings, sharing its prepared models.

        Comparing lightings (the advisor) then skips choosing the shadow marks again; the
        model, visibility and spacing settings must be the same.
        """
        mine = (self.settings.model, self.settings.visibility, self.settings.spacing)
        theirs = (settings.model, settings.visibility, settings.spacing)
        if mine != theirs:
            raise InputError(
                f"with_lighting changes the lighting only; model, visibility and spacing "
                f"{theirs} differ from {mine}"
            )
        other = copy.copy(self)
        other.settings = settings
        other._lighting = None
        other._environment, other._precomputed = None, None
        other._transfers = {}
        return other

    def set_lights(self, lights: LightSet) -> None:
        """Light with given directional lights instead of a panorama (hold-out tests).

        Summed exactly, whatever the lighting setting (there is no panorama to pre-filter).
        """
        self._lighting = prepare_lighting(self.models, lights)
        self._environment, self._precomputed = None, None

    def set_view(self, camera: PinholeCamera) -> float:
        """Plan the splats of a view (point fields); returns the seconds it took."""
        start = time.perf_counter()
        self._view = FieldView(self.field, camera, spacing=self._spacing)
        self._spacing = self._view.spacing or self._spacing
        return time.perf_counter() - start

    def _transfer(self, name: str, fit: ParametricFit) -> SampleTransfer:
        if name not in self._transfers:
            m = self.models
            marks = m.mark_directions if m.mark_directions is not None else m.light_directions
            self._transfers[name] = sample_transfer(
                fit.normals, self._sources[name], fit.lit, marks,
                m.camera_frame[2] if m.kind == "pixels" else None,
            )  # fmt: skip
        return self._transfers[name]

    def _relight_precomputed(
        self, lighting: ModelLighting, camera: PinholeCamera, needed: NDArray[np.bool_]
    ) -> NDArray[np.float32]:
        """:func:`relight_models` with the grid's sum split into precomputed terms."""
        assert self._precomputed is not None
        prefilter, yaw_deg, exposure = self._precomputed
        light_sh = rotate_sh_yaw(prefilter.sh, yaw_deg) * exposure
        p_count = self.models.sample_count
        which = self.choice.sample_model(p_count)
        out = np.zeros((p_count, 3), dtype=np.float32)
        eye, distant, points = viewer_of(self.models, camera)
        for index, name in enumerate(self.choice.names):
            samples = np.flatnonzero(needed & (which == index)).astype(np.int64)
            fit = self.models.fit(name)
            if samples.size == 0:
                continue
            if isinstance(fit, BasisFit):
                out[samples] = np.einsum(
                    "pbc,bc->pc", fit.coefficients[samples], lighting.basis[name]
                ).astype(np.float32)
                continue
            transfer = self._transfer(name, fit)
            assert self._bright is not None
            bright = self._bright
            shade_precomputed(
                samples, self._sources[name], fit.normals, fit.rho_d, fit.f0, fit.alpha,
                points, eye, distant, name == "lambert+ggx", transfer.diffuse,
                transfer.visibility, light_sh, prefilter.specular, np.asarray(ALPHAS),
                lobe_albedo(), sh_norms(), math.radians(yaw_deg), exposure, out,
            )  # fmt: skip
            _shade_kernel(
                samples, self._sources[name], fit.normals, fit.rho_d, fit.f0, fit.alpha, fit.lit,
                points, eye, distant, name == "lambert+ggx", bright.lights.directions,
                bright.lights.rgb, bright.visibility_indices, bright.visibility_weights,
                bright.reaches, out,
            )  # fmt: skip
        return out

    def render(self) -> RelitImage:
        """Relight the current view under the current lighting."""
        if self._lighting is None or self._view is None:
            raise InputError("set a lighting and a view before rendering")
        view = self._view
        camera, needed = view.camera, view.needed
        start = time.perf_counter()
        if self._precomputed is not None:
            radiance = self._relight_precomputed(self._lighting, camera, needed)
        else:
            radiance = relight_models(
                self.models, self.choice, self._lighting, camera, needed=needed,
                sources=self._sources,
            )  # fmt: skip
        relit = time.perf_counter()
        rgb = view.image(radiance)
        done = time.perf_counter()
        return RelitImage(
            rgb=rgb,
            coverage=view.coverage,
            radiance=radiance,
            needed=needed,
            holes=needed & self._unfitted,
            outside_fraction=self._lighting.outside_fraction,
            seconds={"relight": relit - start, "splat": done - relit},
        )
