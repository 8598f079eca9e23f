"""One relighting of a field under a panorama: the request, the choice of mode, the warnings.

Every program that relights a field under an environment (``rig relight``, ``rig batch``, the
demo and its simulated capture, the live viewer's warnings) states what it wants as data, a
:class:`RelightRequest`: the panorama and its controls (:class:`PanoramaControls`), the view,
and either a mode or what the user asked of one (:class:`ModeRequest`, resolved by
:func:`choose_mode`). :func:`prepare_relighting` resolves the mode, measures the warnings once
on the panorama as the object sees it and opens the engine; :func:`relight_request` renders the
request's view with it. The engines themselves are :mod:`render.relight_mode`'s.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError, RigError
from core.field_store import ReflectanceField
from processing.interpolation import InterpolationMethod
from processing.panorama import Panorama, adjust_panorama, visible_environment
from processing.sample_model_store import (
    default_models_path,
    models_for_field,
    read_sample_models,
)
from processing.sample_models import SampleModels
from processing.sampling import SamplerName
from render.environment_choice import CandidateScore, choose_environment_mode, environment_mode
from render.guards import RelightWarning, relight_warnings
from render.model_relight import ModelLightingMode, ModelRelightSettings
from render.relight_mode import (
    MOST_ACCURATE_MODELS,
    HeldOutComparison,
    RelightEngine,
    RelightMode,
    most_accurate_mode,
    open_relighter,
)
from render.relighter import RelightSettings, RelitImage, Scheme

__all__ = [
    "ChosenMode",
    "ModeRequest",
    "PanoramaControls",
    "PreparedRelighting",
    "RelightRequest",
    "Relit",
    "choose_mode",
    "prepare_relighting",
    "relight_request",
    "relighting_notes",
    "relighting_warnings",
]

#: Share of the light from outside the measured lights above which a relit image says so.
OUTSIDE_NOTE = 0.05


@dataclass(frozen=True, kw_only=True)
class PanoramaControls:
    """The user's controls on a panorama.

    Attributes
    ----------
    yaw_deg : float, counter-clockwise rotation seen from above, degrees
    exposure : float, radiance scale, > 0
    modulation : ndarray, shape (h, w), float, optional: multiplies the sampling density of
        the sampled modes (the paper's threshold modulation), in the panorama's own frame
    """

    yaw_deg: float = 0.0
    exposure: float = 1.0
    modulation: NDArray[np.floating] | None = None

    def as_seen(self, panorama: Panorama, field: ReflectanceField) -> Panorama:
        """``panorama`` as ``field``'s object sees it: rotated, scaled, its horizon applied.

        What the mode's choice and the guards judge; the engines apply the same controls to
        the panorama themselves (with their own caches).
        """
        adjusted = adjust_panorama(panorama, yaw_deg=self.yaw_deg, exposure=self.exposure)
        return visible_environment(adjusted, field.below_horizon)


@dataclass(frozen=True, kw_only=True)
class ModeRequest:
    """What was asked of the relighting mode; every None is the project's choice.

    With nothing set, a field of pixels is relit by the method that predicts held-out lights
    best under this panorama (:func:`render.environment_choice.choose_environment_mode`), a
    field of points by the better of its models and interpolation on held-out lights
    (:func:`render.relight_mode.most_accurate_mode`).

    Attributes
    ----------
    paper : bool, the paper's configuration exactly (sampled, K lights)
    scheme : "sampled", "pixels", "projection" or "model" (per-sample models), optional
    k : int, sampled lights, optional (default 64; for ``model``: sample K lights rather than
        sum the panorama's grid)
    sampler : the sampler of the sampled modes
    interpolation, view_interpolation : over the measured lights and cameras, optional
    m, n : nearest measured lights and cameras, optional
    model : ``model`` only: the per-sample model ("auto": by leave-one-light-out)
    grid : the panorama summed into grid x 2 grid lights (the models' exact lighting)
    method : a field of pixels: a named predictor, "light-stage", or "auto"
    fast : "auto" on a field of pixels: the quick rungs only
    models_path : a saved fit of the field (default: beside it)
    """

    paper: bool = False
    scheme: Scheme | Literal["model"] | None = None
    k: int | None = None
    sampler: SamplerName = "tmed"
    interpolation: InterpolationMethod | None = None
    view_interpolation: InterpolationMethod | None = None
    m: int | None = None
    n: int | None = None
    model: str = "auto"
    grid: int | None = None
    method: str = "auto"
    fast: bool = False
    models_path: str | os.PathLike[str] | None = None

    def _steering(self) -> dict[str, object]:
        """The options that steer an interpolation scheme, by their flag's name."""
        return {"--scheme": self.scheme, "--interp": self.interpolation,
                "--view-interp": self.view_interpolation, "-k": self.k, "-m": self.m,
                "-n": self.n}  # fmt: skip


@dataclass(frozen=True)
class ChosenMode:
    """The mode a request resolved to, and what informs it.

    Attributes
    ----------
    mode : RelightMode
    models : SampleModels or None, the field's fit when the mode or its choice used it
    comparison : HeldOutComparison or None, the held-out measurement the choice rests on
    reason : str or None, why this mode, one sentence (None: the mode was given)
    scores : tuple of CandidateScore, every candidate's held-out error (a pixel field's choice)
    """

    mode: RelightMode
    models: SampleModels | None = None
    comparison: HeldOutComparison | None = None
    reason: str | None = None
    scores: tuple[CandidateScore, ...] = ()


def choose_mode(
    field: ReflectanceField,
    request: ModeRequest,
    seen: Panorama | None,
    *,
    models: SampleModels | None = None,
) -> ChosenMode:
    """The relighting mode ``request`` asks for on ``field``.

    Parameters
    ----------
    field : ReflectanceField
    request : ModeRequest
    seen : Panorama or None, the panorama as the object sees it
        (:meth:`PanoramaControls.as_seen`); a field of pixels' automatic choice is made under
        it. None (several panoramas, as ``rig batch``): the choice on held-out lights alone.
    models : SampleModels, optional, the field's fit when the caller has it (else read from
        ``request.models_path`` or beside the field, or fitted, as the mode needs)

    Raises
    ------
    InputError
        Options that contradict each other or the field (a named method on a field of
        points, a scheme beside a method, more nearest lights than measured).
    """
    s_count, t_count, _ = field.shape
    for flag, value, have, what in (("-m", request.m, t_count, "lights"),
                                    ("-n", request.n, s_count, "cameras")):  # fmt: skip
        if value is not None and value > have:
            raise InputError(f"{flag} {value}: {field.path} has only {have} measured {what}")
    k = 64 if request.k is None else request.k
    if request.paper:
        return ChosenMode(RelightSettings.paper_configuration(k=k))
    grid = MOST_ACCURATE_MODELS.grid_height if request.grid is None else request.grid
    if request.scheme == "model":
        lighting: ModelLightingMode = "grid" if request.k is None else "sampled"
        mode = ModelRelightSettings(
            model=request.model, lighting=lighting, k=k, sampler=request.sampler, grid_height=grid
        )
        if models is None:
            models = models_for_field(field, request.models_path)
        return ChosenMode(mode, models)
    steering = request._steering()
    unsteered = all(value is None for value in steering.values())
    if request.method != "auto" or (
        field.sample_kind == "pixels" and unsteered and seen is not None
    ):
        return _pixel_field_mode(field, request, seen, models)
    if unsteered:
        choice = most_accurate_mode(field, models, models_path=request.models_path)
        chosen = choice.mode
        if chosen == MOST_ACCURATE_MODELS:
            chosen = replace(MOST_ACCURATE_MODELS, grid_height=grid)
        # The fit and the comparison inform the warnings whichever mode won.
        return ChosenMode(chosen, choice.models, choice.comparison, choice.reason)
    settings = RelightSettings(request.scheme or "sampled", k=k, sampler=request.sampler,
                               m=request.m or 3, n=request.n or 3)  # fmt: skip
    if request.interpolation:
        settings = replace(settings, interpolation=request.interpolation)
    if request.view_interpolation:
        settings = replace(settings, view_interpolation=request.view_interpolation)
    return ChosenMode(settings)


def _pixel_field_mode(
    field: ReflectanceField,
    request: ModeRequest,
    seen: Panorama | None,
    models: SampleModels | None,
) -> ChosenMode:
    """``method`` (or its automatic choice under the panorama) on a field of pixels."""
    if field.sample_kind != "pixels":
        raise InputError(
            f"--method relights a field of pixels (an RTI capture); {field.path} is a field of "
            "points: use --scheme (model, or an interpolation scheme)"
        )
    given = [flag for flag, value in request._steering().items() if value is not None]
    if given:
        raise InputError(
            f"--method {request.method} chooses the relighting; drop {', '.join(given)}"
        )
    # A saved fit serves the choice and the engine instead of a new one.
    saved = None if request.models_path is None else models_for_field(field, request.models_path)
    if request.method != "auto":
        return ChosenMode(environment_mode(request.method), saved)
    assert seen is not None  # choose_mode sends "auto" here only with a panorama
    choice = choose_environment_mode(field, seen, models=saved, fast=request.fast)
    return ChosenMode(choice.mode, saved, None, choice.reason, choice.scores)


@dataclass(frozen=True, kw_only=True)
class RelightRequest:
    """One relighting: a panorama, its controls, a view and the mode (or what was asked of it).

    Attributes
    ----------
    panorama : Panorama, as read (the controls are applied by the relighting)
    camera : PinholeCamera, the view (a field of pixels: its capture's camera)
    lighting : PanoramaControls
    mode : RelightMode, or a ModeRequest the relighting resolves (:func:`choose_mode`)
    """

    panorama: Panorama
    camera: PinholeCamera
    lighting: PanoramaControls = field(default_factory=PanoramaControls)
    mode: RelightMode | ModeRequest = field(default_factory=ModeRequest)


@dataclass(frozen=True)
class PreparedRelighting:
    """A request's engine, lit and set to its view, with its mode and warnings.

    Attributes
    ----------
    engine : RelightEngine, lit by the request's panorama and controls, set to its view
    chosen : ChosenMode
    warnings : tuple of RelightWarning, what to expect of this relighting
    seen : Panorama, the panorama as the object sees it
    """

    engine: RelightEngine
    chosen: ChosenMode
    warnings: tuple[RelightWarning, ...]
    seen: Panorama


def prepare_relighting(
    field: ReflectanceField,
    request: RelightRequest,
    *,
    models: SampleModels | None = None,
) -> PreparedRelighting:
    """Resolve ``request``'s mode, measure its warnings and open its engine, lit, at its view.

    ``models``: the field's fit when the caller has it (a given mode that uses models needs
    one; a resolved mode brings its own).
    """
    seen = request.lighting.as_seen(request.panorama, field)
    if isinstance(request.mode, ModeRequest):
        chosen = choose_mode(field, request.mode, seen, models=models)
    else:
        chosen = ChosenMode(request.mode, models)
    warnings = relighting_warnings(field, request.camera, seen, chosen)
    engine = open_relighter(field, chosen.mode, chosen.models)
    engine.set_lighting(
        request.panorama,
        yaw_deg=request.lighting.yaw_deg,
        exposure=request.lighting.exposure,
        modulation=request.lighting.modulation,
    )
    engine.set_view(request.camera)
    return PreparedRelighting(engine, chosen, tuple(warnings), seen)


def relighting_warnings(
    field: ReflectanceField, camera: PinholeCamera, seen: Panorama, chosen: ChosenMode
) -> list[RelightWarning]:
    """The guards' warnings (``render.guards.relight_warnings``) for a resolved mode.

    An interpolating mode without a fit in hand reads the fit saved beside the field, if any:
    its lobe and leave-one-out error inform the ghosting, sun and noise guards.
    """
    models = chosen.models
    saved = default_models_path(field.path)
    if not chosen.mode.uses_models and models is None and saved.exists():
        with contextlib.suppress(RigError):
            models = read_sample_models(saved, field)
    return relight_warnings(field, camera, seen.rgb, chosen.mode, models, chosen.comparison)


@dataclass(frozen=True)
class Relit:
    """A relit view and how it was made.

    Attributes
    ----------
    image : RelitImage
    chosen : ChosenMode
    warnings : tuple of RelightWarning, the guards' warnings
    notes : tuple of str, what the image itself shows (holes, light from outside the
        measured lights): :func:`relighting_notes`
    """

    image: RelitImage
    chosen: ChosenMode
    warnings: tuple[RelightWarning, ...]
    notes: tuple[str, ...]


def relight_request(
    field: ReflectanceField,
    request: RelightRequest,
    *,
    models: SampleModels | None = None,
) -> Relit:
    """Relight ``field`` as ``request`` asks: the image, the mode, the warnings and notes."""
    prepared = prepare_relighting(field, request, models=models)
    image = prepared.engine.render()
    notes = relighting_notes(image, uses_models=prepared.chosen.mode.uses_models)
    return Relit(image, prepared.chosen, prepared.warnings, notes)


def relighting_notes(image: RelitImage, *, uses_models: bool) -> tuple[str, ...]:
    """What a relit image shows that its user should know: holes, light from outside."""
    notes = []
    if image.holes.any():
        notes.append(
            f"warning: {int(image.holes.sum())} visible samples are seen by no chosen camera "
            "(holes)"
        )
    if image.outside_fraction > OUTSIDE_NOTE and not uses_models:
        notes.append(
            f"warning: {image.outside_fraction:.0%} of the light comes from outside the "
            "measured lights (below the lowest ring, say); it is moved to the nearest measured "
            "lights"
        )
    elif image.outside_fraction > OUTSIDE_NOTE:
        notes.append(
            f"note: {image.outside_fraction:.0%} of the light comes from outside the measured "
            "lights; the fitted models shade it, its cast shadows are extrapolated from the "
            "measured ones"
        )
    return tuple(notes)
