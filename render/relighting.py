"""One relighting of a field under a panorama: the request, the choice of mode, the warnings.

Every program that relights a field under an environment (``rig relight``, ``rig batch``, the
demo and its simulated capture, the live viewer) states what it wants as data, a
:class:`RelightRequest`: the panorama and its controls (:class:`PanoramaControls`), the view,
and either a mode or what the user asked of one (:class:`ModeRequest`, resolved by
:func:`choose_mode`). The controls are applied once, to the panorama as the object sees it;
the mode's choice, the guards and the engine's lights all take that panorama.
:func:`prepare_relighting` resolves the mode, measures the warnings and opens the engine, lit,
at the request's view; :func:`relight_request` renders it. A program that relights request
after request on one field (the viewer) keeps a :class:`RelightingCache`, the same steps with
what did not change kept: the adjusted panorama, the chosen mode, the engines (their models,
precomputation and lighting) and their views. The engines themselves are
:mod:`render.engines.modes`'s.
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass, field, replace
from typing import Literal

from core.camera_model import PinholeCamera
from core.errors import InputError, RigError
from core.field_store import ReflectanceField
from processing.environment import EnvironmentLighting
from processing.interpolation import InterpolationMethod
from processing.panorama import Panorama, VisibleEnvironments
from processing.sample_model_store import (
    default_models_path,
    models_for_field,
    read_sample_models,
)
from processing.sample_models import SampleModels
from processing.sampling import SamplerName
from render.engines.interpolated import RelightSettings, RelitImage, Scheme
from render.engines.models import ModelLightingMode, ModelRelighter, ModelRelightSettings
from render.engines.modes import (
    MOST_ACCURATE_MODELS,
    HeldOutComparison,
    RelightEngine,
    RelightMode,
    most_accurate_mode,
    open_relighter,
)
from render.engines.panorama_lit import AdjustedPanorama, PanoramaControls, PanoramaLitEngine
from render.environment_choice import CandidateScore, choose_environment_mode, environment_mode
from render.guards import RelightWarning, relight_warnings

__all__ = [
    "ChosenMode",
    "LitRelighting",
    "ModeRequest",
    "PanoramaControls",
    "PreparedRelighting",
    "RelightRequest",
    "RelightingCache",
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
class ModeRequest:
    """What was asked of the relighting mode; every None is the project's choice.

    With nothing set, a field of pixels is relit by the method that predicts held-out lights
    best under this panorama (:func:`render.environment_choice.choose_environment_mode`), a
    field of points by the better of its models and interpolation on held-out lights
    (:func:`render.engines.modes.most_accurate_mode`).

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
    lit = RelightingCache(field, models=models).prepare(request)
    warnings = relighting_warnings(field, lit.camera, lit.seen, lit.chosen)
    return PreparedRelighting(**vars(lit), warnings=tuple(warnings))


@dataclass(frozen=True)
class LitRelighting:
    """A request as a :class:`RelightingCache` prepared it: its engine, lit, at its view.

    Attributes
    ----------
    engine : RelightEngine, lit by ``adjusted``, set to ``camera``
    chosen : ChosenMode
    adjusted : AdjustedPanorama, the request's panorama under its controls
    environment : EnvironmentLighting, the lighting the engine took (the panorama as lit and
        its lights)
    camera : PinholeCamera, the view
    seconds : dict, what was redone for this request: "lighting" (the adjustment and the
        engine's lighting) and "view", 0.0 where the engine kept what it had
    """

    engine: RelightEngine
    chosen: ChosenMode
    adjusted: AdjustedPanorama
    environment: EnvironmentLighting
    camera: PinholeCamera
    seconds: dict[str, float]

    @property
    def seen(self) -> Panorama:
        """The panorama as the object sees it (the controls applied)."""
        return self.adjusted.seen


@dataclass(frozen=True)
class PreparedRelighting(LitRelighting):
    """A request's engine, lit and at its view (:class:`LitRelighting`), with its warnings.

    A sequence turns its adjusted panorama or its view further, frame 0 being the engine as
    prepared (:func:`render.sequence.relight_prepared_sequence`).

    Attributes
    ----------
    warnings : tuple of RelightWarning, what to expect of this relighting
    """

    warnings: tuple[RelightWarning, ...]


@dataclass
class _Opened:
    """An engine the cache holds, the fit it was opened with, and what it was last set to."""

    engine: RelightEngine
    models: SampleModels | None
    lit: AdjustedPanorama | None = None
    environment: EnvironmentLighting | None = None
    view: PinholeCamera | None = None


class RelightingCache:
    """Requests on one field relit one after another, each redoing only what it changes.

    The steps of :func:`prepare_relighting`, with what a request shares with the one before
    kept: the panorama adjusted by its controls (several modes under one lighting adjust it
    once), the mode chosen for a :class:`ModeRequest`, an engine per mode with its lighting
    and view. The engines of models are kept, whatever mode comes next (their models and
    transfer are the expensive part) and a new one shares their prepared models; an engine
    that interpolates holds only its lighting, so one of another K or sampler replaces it.
    Panoramas and modulation maps are told apart by identity: load a changed one as a new
    object.

    Parameters
    ----------
    field : ReflectanceField
    models : SampleModels, optional, the field's fit when the caller has it
    comparison : HeldOutComparison, optional, the held-out measurement behind the caller's
        choice of mode (it informs the warnings)
    """

    def __init__(
        self,
        field: ReflectanceField,
        *,
        models: SampleModels | None = None,
        comparison: HeldOutComparison | None = None,
    ) -> None:
        self.field = field
        self.models = models
        self.comparison = comparison
        self._visible = VisibleEnvironments(field.below_horizon)
        self._adjusted: AdjustedPanorama | None = None
        self._chosen: tuple[ModeRequest, Panorama, ChosenMode] | None = None
        self._engines: dict[RelightMode, _Opened] = {}

    def prepare(self, request: RelightRequest) -> LitRelighting:
        """``request``'s engine, lit and at its view, redoing only what changed."""
        start = time.perf_counter()
        adjusted = self._adjust(request)
        adjusting = time.perf_counter() - start
        chosen = self._choose(request.mode, adjusted)
        opened = self._engine(chosen)
        seconds = {"lighting": 0.0, "view": 0.0}
        if opened.environment is None or not adjusted.lights_as(opened.lit):
            start = time.perf_counter()
            engine = opened.engine
            # Every mode's engine is lit through the shared base, where the controls apply once.
            assert isinstance(engine, PanoramaLitEngine)
            opened.environment = engine.take_lighting(adjusted)
            opened.lit = adjusted
            seconds["lighting"] = adjusting + time.perf_counter() - start
        if opened.view != request.camera:
            seconds["view"] = opened.engine.set_view(request.camera)
            opened.view = request.camera
        return LitRelighting(
            opened.engine, chosen, adjusted, opened.environment, request.camera, seconds
        )

    def _adjust(self, request: RelightRequest) -> AdjustedPanorama:
        """The request's panorama under its controls: adjusted anew only when they changed."""
        visible, controls = self._visible(request.panorama), request.lighting
        last = self._adjusted
        if last is None or last.visible is not visible or last.controls.turn != controls.turn:
            last = controls.adjusted(visible)
        elif last.controls.modulation is not controls.modulation:
            # The map steers the sampling of the lights; the panorama's rotation and scale stand.
            last = replace(last, controls=controls)
        self._adjusted = last
        return last

    def _choose(self, mode: RelightMode | ModeRequest, adjusted: AdjustedPanorama) -> ChosenMode:
        """The mode: given, or chosen for the request (once while it and the panorama stand)."""
        if not isinstance(mode, ModeRequest):
            return ChosenMode(mode, self.models, self.comparison)
        last = self._chosen
        if last is None or last[0] != mode or last[1] is not adjusted.seen:
            chosen = choose_mode(self.field, mode, adjusted.seen, models=self.models)
            self._chosen = (mode, adjusted.seen, chosen)
            return chosen
        return last[2]

    def _engine(self, chosen: ChosenMode) -> _Opened:
        mode = chosen.mode
        held = self._engines.get(mode)
        if held is None or held.models is not chosen.models:
            self._engines[mode] = _Opened(self._open(chosen), chosen.models)
            stale = [m for m in self._engines if m != mode and not m.uses_models]
            for other in stale:
                del self._engines[other]
        return self._engines[mode]

    def _open(self, chosen: ChosenMode) -> RelightEngine:
        """The mode's engine; a model engine shares the models another one prepared."""
        if isinstance(chosen.mode, ModelRelightSettings):
            for opened in self._engines.values():
                if isinstance(opened.engine, ModelRelighter) and opened.models is chosen.models:
                    try:
                        return opened.engine.with_lighting(chosen.mode)
                    except InputError:
                        continue  # another model or visibility: prepare anew
        return open_relighter(self.field, chosen.mode, chosen.models)


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
