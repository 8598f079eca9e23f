"""Relighting through per-sample models: the engine, its settings and the model choice.

:class:`ModelRelighter` fits (or loads) a field's per-sample models, chooses a model per sample
and shades them under a panorama's lights from any view, with no interpolation of values:
exactly over a sampled or pre-filtered set of lights (:mod:`render.engines.model_shading`) or
through precomputed terms, interactive (:mod:`render.precomputed_lighting`).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, replace
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

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
    ParametricFit,
    SampleModels,
    choose_model,
    fit_sample_models,
    shadow_mark_errors,
    with_geometric_visibility,
)
from processing.sampling import SamplerName
from render.engines.interpolated import Predictor, RelitImage
from render.engines.model_shading import (
    ModelLighting,
    fill_sources,
    prepare_lighting,
    relight_models,
    shade_parametric,
    viewer_of,
)
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
    "ModelLightingMode",
    "ModelRelightSettings",
    "ModelRelighter",
    "Visibility",
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
            shade_parametric(
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
