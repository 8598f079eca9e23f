"""Environment relighting through any light predictor: each grid light of the panorama predicted.

The linear schemes (:mod:`render.engines.interpolated`) weight the measured images; the model engine
(:mod:`render.engines.models`) shades fitted BRDFs. This engine relights through any
:class:`render.prediction_methods.LightPredictor` (the learned rung, a model plus its residual,
the adaptive mixture, PTM/HSH): the panorama is summed exactly into grid blocks, one light at
each block's energy-weighted centroid (:func:`core.light_set.grid_lights`), and the field's
radiance under the environment is

    L(p) = sum_g E_g * P_p(w_g)

with E_g the block's radiance x solid angle and P_p(w) the predicted radiance of sample p under
a directional light of unit irradiance from w. A sun stays at its own direction (its block's
centroid), where the light-stage sum moves it to the nearest measured light; a predictor that
carries the residual at the measured lights (``<model>+residual``, ``adaptive``) reproduces
every measured image, so what it adds is only where the lights were not measured.

With ``split`` the predictor relights only the light the light-stage sum gathers badly (light
concentrated within a measured light's cell, and light outside the measured region,
:func:`processing.light_split.split_light`), and the sum relights the rest: under a broad sky
this is the sum itself, whose errors cancel between neighbouring cells; under a sun, the sun is
predicted at its direction.

Fields of pixels (one fixed view, RTI captures) only: a field of points relights through its
models (:mod:`render.engines.models`) or the linear schemes, which blend cameras for new views.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet, grid_lights
from processing.environment import EnvironmentLighting, LightingControls
from processing.light_split import LightSplitter
from processing.measured_region import MeasuredRegion
from processing.sample_models import SampleModels
from render.engines.interpolated import Predictor, RelitImage
from render.engines.panorama_lit import PanoramaLitEngine
from render.field_view import FieldView
from render.light_prediction import PREDICTORS, environment_radiance, make_predictor
from render.prediction_methods import LightPredictor

__all__ = ["INTERPOLATING", "PredictorRelightSettings", "PredictorRelighter"]

#: Predictors that only weight the measured images (no model of the reflectance).
INTERPOLATING = ("nearest", "barycentric", "rbf")


@dataclass(frozen=True)
class PredictorRelightSettings:
    """Relight a field of pixels through a light predictor; a relighting mode.

    Attributes
    ----------
    method : str, a :data:`render.light_prediction.PREDICTORS` entry
    grid_height : int, the panorama summed into ``grid_height`` x 2 ``grid_height`` blocks
        (the blocks below a blocked horizon carry no light and are skipped)
    split : bool, predict only the sharp light and give the smooth light to the light-stage
        sum (the module)
    """

    method: str
    grid_height: int = 32
    split: bool = False

    def __post_init__(self) -> None:
        if self.method not in PREDICTORS:
            raise InputError(f"unknown method {self.method!r}; use one of {', '.join(PREDICTORS)}")
        if self.grid_height < 1:
            raise InputError(f"grid height must be at least 1, got {self.grid_height}")

    @property
    def uses_models(self) -> bool:
        """Whether the predictor models the reflectance (else it weights measured images)."""
        return self.method not in INTERPOLATING

    @property
    def sampled_k(self) -> int | None:
        """None: every block of the panorama lights."""
        return None

    def lighting_controls(
        self,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> LightingControls:
        """The panorama's grid lights under the user's controls."""
        return LightingControls(
            lighting="grid",
            grid_height=self.grid_height,
            modulation=modulation,
            yaw_deg=yaw_deg,
            exposure=exposure,
        )

    def predictors(self) -> tuple[Predictor, Predictor]:
        """The predictor for unmeasured lights; a pixel field has no other view to predict."""
        return ("model", self.method, 0), ("interpolation", "nearest", 0)

    def exact_lighting(self, grid_height: int) -> PredictorRelightSettings:
        """The same predictor over a finer grid."""
        return replace(self, grid_height=grid_height)

    def describe(self, models: SampleModels | None = None) -> str:
        """A short name for reports."""
        del models
        grid = f"grid {self.grid_height}x{2 * self.grid_height}"
        if self.split:
            return f"{self.method} for the sharp light ({grid}), the light-stage sum for the rest"
        return f"{self.method}, {grid}"

    def open(
        self, field_store: ReflectanceField, models: SampleModels | None = None
    ) -> PredictorRelighter:
        """The engine of this mode (``models``: a fit of the field the predictor may use)."""
        return PredictorRelighter(field_store, self, models)


class PredictorRelighter(PanoramaLitEngine):
    """Relight one field of pixels through a light predictor under changing panoramas."""

    settings: PredictorRelightSettings

    def __init__(
        self,
        field_store: ReflectanceField,
        settings: PredictorRelightSettings,
        models: SampleModels | None = None,
    ) -> None:
        if field_store.image_shape is None:
            raise InputError(
                f"{field_store.path} is a field of points: relight it through its models "
                f"(--scheme model) or a linear scheme; {settings.method} relights fields of "
                "pixels (one fixed view)"
            )
        self.field = field_store
        super().__init__(field_store)
        self.settings = settings
        self.predictor: LightPredictor = make_predictor(field_store, settings.method, models=models)
        self._environment: EnvironmentLighting | None = None
        self._lights: LightSet | None = None
        self._radiance: NDArray[np.float32] | None = None
        self._view: FieldView | None = None
        self._outside = 0.0
        # The split: the smooth light's weight per measured light (T, 3), and its splitter.
        self._sum_weights: NDArray[np.float64] | None = None
        self._splitter: LightSplitter | None = None

    @property
    def environment(self) -> EnvironmentLighting | None:
        """The current lighting: the panorama as relit and its grid lights."""
        return self._environment

    def set_environment(self, lighting: EnvironmentLighting) -> None:
        """Take the grid lights of a lighting (from :func:`light_environment`)."""
        lights = lighting.light_set().nonempty()
        energy = lights.rgb.sum(axis=1)
        total = float(energy.sum())
        region = MeasuredRegion.build(self.field.light_directions)
        outside = region.outside(lights.directions)
        self._outside = float(energy[outside].sum() / total) if total > 0 else 0.0
        self._sum_weights = None
        if self.settings.split:
            rgb = lighting.panorama.rgb
            if self._splitter is None or self._splitter.shape != rgb.shape[:2]:
                self._splitter = LightSplitter(self.field.light_directions, rgb.shape[0])
            parts = self._splitter.split(rgb)
            self._sum_weights = parts.smooth_cells
            lights = grid_lights(parts.sharp, self.settings.grid_height).nonempty()
        self._environment, self._lights, self._radiance = lighting, lights, None

    def set_view(self, camera: PinholeCamera) -> float:
        """Accept the field's own view (a field of pixels has no other)."""
        own = self.field.cameras[0]
        if (camera.width, camera.height) != (own.width, own.height):
            raise InputError(
                f"{self.field.path} holds one fixed view of {own.width}x{own.height} pixels; "
                f"it cannot be rendered at {camera.width}x{camera.height}"
            )
        self._view = FieldView(self.field, camera)
        return 0.0

    def render(self) -> RelitImage:
        """The field's view under the current lighting (predicted once per lighting)."""
        if self._lights is None:
            raise InputError("set a lighting before rendering")
        view = self._view or FieldView(self.field, self.field.cameras[0])
        start = time.perf_counter()
        if self._radiance is None:
            radiance = np.zeros((self.field.shape[2], 3))
            if self._lights.k:
                radiance = environment_radiance(
                    self.predictor, 0, self._lights, self.field.shape[2]
                ).astype(np.float64)
            if self._sum_weights is not None:
                radiance += np.einsum(
                    "tc,tpc->pc", self._sum_weights, self.field.camera_slab(0), dtype=np.float64
                )
            # A mask's other pixels are no samples: black, as every engine leaves them.
            self._radiance = np.where(view.needed[:, None], radiance, 0.0).astype(np.float32)
        return RelitImage(
            rgb=view.image(self._radiance),
            coverage=view.coverage,
            radiance=self._radiance,
            needed=view.needed.copy(),
            holes=np.zeros(len(view.needed), dtype=bool),
            outside_fraction=self._outside,
            seconds={"relight": time.perf_counter() - start},
        )
