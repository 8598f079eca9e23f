"""Which relighting a field gets: interpolation of its values, or its fitted per-sample models.

Both engines, :class:`render.engines.interpolated.Relighter` (the paper's eq. 1-3 and our
linear schemes) and :class:`render.engines.models.ModelRelighter`, take a lighting (from
:func:`processing.environment.light_environment`) and a view and return a
:class:`render.engines.interpolated.RelitImage`. A mode (:class:`RelightMode`: their
settings) opens its engine, names the lighting it takes and what predicts unmeasured lights
and views, so no caller asks which kind of mode it holds.
:func:`most_accurate_mode` decides between them on the field's own measurements: the error of
predicting every other measured light from the rest, for the chosen model and for barycentric
interpolation over the lights, so the decision works on real captures, where no ground truth
exists. The same comparison (:class:`HeldOutComparison`) tells the guards whether their advice
to relight through the models would help.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField
from processing.environment import EnvironmentLighting, LightingControls
from processing.panorama import Panorama
from processing.sample_model_store import models_for_field
from processing.sample_models import SampleModels, choose_model, interpolation_loo
from render.engines.interpolated import Predictor, RelitImage, best_settings
from render.engines.models import ModelRelightSettings
from render.evaluation import HeldOutError, held_out_errors

__all__ = [
    "MOST_ACCURATE_MODELS",
    "HeldOutComparison",
    "ModeChoice",
    "RelightEngine",
    "RelightMode",
    "most_accurate_mode",
    "open_relighter",
]


class RelightEngine(Protocol):
    """What both relighting engines do: a lighting and a view in, a relit image out."""

    @property
    def environment(self) -> EnvironmentLighting | None:
        """The current lighting: the panorama as relit and its lights; None without a panorama."""
        ...

    def set_lighting(
        self,
        panorama: Panorama,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> float:
        """Light with a panorama under the user's controls; returns the seconds it took."""
        ...

    def set_environment(self, lighting: EnvironmentLighting) -> None:
        """Prepare a lighting made by :func:`processing.environment.light_environment`."""
        ...

    def set_view(self, camera: PinholeCamera) -> float:
        """Prepare the view of ``camera``; returns the seconds it took."""
        ...

    def render(self) -> RelitImage:
        """Relight the current view under the current lighting."""
        ...


class RelightMode(Protocol):
    """A way to relight a field: interpolating the measured values, or through models.

    :class:`RelightSettings` interpolates the measured values; :class:`ModelRelightSettings`
    relights through per-sample models.
    """

    @property
    def uses_models(self) -> bool:
        """Whether the engine relights through the field's fitted models."""
        ...

    @property
    def sampled_k(self) -> int | None:
        """K of a sampled lighting; None when every pixel (or block) of the panorama lights."""
        ...

    def lighting_controls(
        self,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> LightingControls:
        """The lighting the mode takes from a panorama under the user's controls."""
        ...

    def predictors(self) -> tuple[Predictor, Predictor]:
        """What predicts an unmeasured light, and an uncaptured view."""
        ...

    def exact_lighting(self, grid_height: int) -> RelightMode:
        """The same predictors with (near) exact lighting: the reference of the lighting term."""
        ...

    def describe(self, models: SampleModels | None = None) -> str:
        """A short name for reports."""
        ...

    def open(
        self, field_store: ReflectanceField, models: SampleModels | None = None
    ) -> RelightEngine:
        """The engine of this mode (a model mode fits the field when ``models`` is None)."""
        ...


#: The model mode :func:`most_accurate_mode` picks: the model chosen by LOO, the panorama
#: summed exactly into 64 x 128 blocks (docs/models.md: the sampled lights' discretisation,
#: not the models, dominates the error of glossy objects at K = 256).
MOST_ACCURATE_MODELS = ModelRelightSettings(model="auto", lighting="grid", grid_height=64)


def open_relighter(
    field: ReflectanceField, mode: RelightMode, models: SampleModels | None = None
) -> RelightEngine:
    """The engine for ``mode`` on ``field``.

    A model mode fits ``field`` (or reads its saved fit) when ``models`` is None.
    """
    return mode.open(field, models)


@dataclass(frozen=True)
class HeldOutComparison:
    """The field's chosen model against interpolation, on lights neither saw.

    Attributes
    ----------
    model : str, the model chosen among the fitted ones
    model_error : HeldOutError, its error on the held-out lights
    interpolation : str, the light interpolation of the best linear settings
    interpolation_error : HeldOutError, its error on the same lights
    how : str, which lights were held out (every other light, or one at a time)
    """

    model: str
    model_error: HeldOutError
    interpolation: str
    interpolation_error: HeldOutError
    how: str

    @property
    def models_win(self) -> bool:
        """Whether the model predicts the held-out lights better than interpolation does.

        Better in linear light (relative RMSE) and not worse as displayed (PSNR on 8-bit
        sRGB): on the real capture a model that tied interpolation in linear light (20.1 %
        against 20.0 % on test lights) lost 2.8 dB in the dark regions, and the relative RMSE
        alone had chosen it (``python -m bench.guard_advice``).
        """
        m, i = self.model_error, self.interpolation_error
        return m.relative_rmse < i.relative_rmse and m.psnr >= i.psnr

    def __str__(self) -> str:
        return (
            f"on {self.how}, model {self.model} errs {self.model_error} and "
            f"{self.interpolation} interpolation {self.interpolation_error}"
        )


@dataclass(frozen=True)
class ModeChoice:
    """The relighting mode chosen for a field, and why.

    Attributes
    ----------
    mode : RelightSettings or ModelRelightSettings
    models : SampleModels, the field's fit
    comparison : HeldOutComparison, the measurement the choice rests on
    reason : str, one sentence for the user
    """

    mode: RelightMode
    models: SampleModels
    comparison: HeldOutComparison
    reason: str


def most_accurate_mode(
    field: ReflectanceField,
    models: SampleModels | None = None,
    *,
    models_path: str | os.PathLike[str] | None = None,
) -> ModeChoice:
    """Choose between per-sample models and interpolation by their error on held-out lights.

    Parameters
    ----------
    field : ReflectanceField
    models : SampleModels, optional
        Default: the fit saved at ``models_path`` (default beside the field), or a new fit
        (saved there).

    Returns
    -------
    ModeChoice
        ``MOST_ACCURATE_MODELS`` when the model chosen among the fitted ones predicts held-out
        lights better than barycentric interpolation does (:attr:`HeldOutComparison.models_win`:
        in linear light, and not worse as displayed), else
        :func:`render.engines.interpolated.best_settings`.

    Notes
    -----
    The comparison is honest: both are fitted on every other light and scored on the others
    (:func:`render.evaluation.held_out_errors`). A leave-one-light-out score of a nonlinear
    fit that saw every light is biased toward the model (on a real capture it called
    lambert+ggx 29 % where a refit without the light gave 42 %). A field of fewer than six
    lights cannot be split; it falls back to the leave-one-light-out scores.
    """
    linear = best_settings(field)
    if models is None:
        models = models_for_field(field, models_path)
    chosen = choose_model(models).chosen
    how = "held-out lights (every other light)"
    try:
        errors = held_out_errors(field, [chosen, linear.interpolation])
    except InputError:
        how = "held-out lights (leave one out: too few lights to split)"
        interpolated = interpolation_loo(field, linear.interpolation).relative_rmse
        # No display error without held-out images: the linear error decides alone.
        errors = {
            chosen: HeldOutError(models.fits[chosen].loo.relative_rmse, math.inf),
            linear.interpolation: HeldOutError(interpolated, math.inf),
        }
    comparison = HeldOutComparison(
        chosen, errors[chosen], linear.interpolation, errors[linear.interpolation], how
    )
    if comparison.models_win:
        reason = (
            f"model {chosen} predicts {how} with {comparison.model_error} error, "
            f"{linear.interpolation} interpolation with {comparison.interpolation_error}"
        )
        return ModeChoice(MOST_ACCURATE_MODELS, models, comparison, reason)
    reason = (
        f"{linear.interpolation} interpolation predicts {how} with "
        f"{comparison.interpolation_error} error, the best model ({chosen}) with "
        f"{comparison.model_error}"
    )
    return ModeChoice(linear, models, comparison, reason)
