"""The cheapest relighting that is accurate enough: errors predicted from the field itself.

A captured field has no ground truth, so every candidate configuration is scored by hold-out
relighting on the field's own measurements. The environment is first gathered onto the measured
lights (the panorama's Voronoi cells around them, :func:`projection_light_weights`): under that
lighting the true relit value of sample p at measured camera s is a sum of measurements,
``y[s, p] = sum_t W_t F[s, t, p]``, with nothing interpolated. Three error terms follow:

- **lights**: the lights are split into up to ``MOST_FOLDS`` interleaved folds (one light each
  on a field of as few lights, so a sparse field loses little when one is held out); each fold
  is held out, predicted from the rest by the candidate's light predictor (its interpolation,
  or its model refitted without the fold), and the held-out part of ``y`` compared. Errors
  add with their sign, so a highlight every neighbour misses in the same direction counts in
  full.
- **views**: the same with folds of cameras, predicted by the candidate's view interpolation
  (or its model refitted without them).
- **lighting**: the candidate against the same predictor with exact lighting (every panorama
  pixel; the 64-row grid for models), both on the field: the error of sampling K lights, at
  the worst of ``LIGHTING_VIEWS`` measured cameras.

Each term is a relative RMSE over the samples the cameras see; they are combined as independent
errors, ``sqrt(lights^2 + views^2 + lighting^2)``. Held-out folds leave gaps wider than the
field's spacing, so the lights and views terms lean high; the benchmark measures the predictions
against the simulator's ground truth (``rig bench``, section "advisor").

What is compared and answered (candidates, predictions, the advice, the capture density a
pre-capture suggests) is :mod:`render.advice`, its names also importable from here.

The work runs on a random subset of the samples (default 3 000): errors are averages over
samples, and the fits and relightings are per sample. Speed is measured on that subset and the
per-sample part scaled to the whole field.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet
from core.progress import progress_bar
from processing.interpolation import InterpolationMethod, interpolation_weights
from processing.panorama import Panorama
from processing.sample_models import PARAMETRIC_MODELS, SampleModels, fit_sample_models
from render.advice import (
    Advice,
    Candidate,
    CaptureDensity,
    Prediction,
    capture_density,
    default_candidates,
)
from render.engines.interpolated import Predictor
from render.engines.models import ModelRelighter, ModelRelightSettings
from render.engines.modes import RelightEngine, RelightMode
from render.engines.paper_sums import blend_cameras, relight
from render.light_weights import LightWeights, projection_light_weights

__all__ = [
    "Advice",
    "Advisor",
    "Candidate",
    "CaptureDensity",
    "Prediction",
    "advise",
    "capture_density",
    "default_candidates",
]

#: Most interleaved hold-out folds of lights and of cameras (fewer positions: one fold each).
MOST_FOLDS = 12
#: Fewest lights the hold-out works with, and fewest cameras for the views term.
FEWEST_LIGHTS, FEWEST_CAMERAS = 8, 4
#: Samples the advisor works on (a random subset of those some camera sees).
ADVISOR_SAMPLES = 3_000
#: Measured cameras the lighting term looks through (it keeps the worst), and the timings.
LIGHTING_VIEWS = 8
TIMING_VIEWS = 3


def _folds(count: int) -> list[NDArray[np.int64]]:
    """Interleaved folds of ``count`` indices (each spread over the whole layout)."""
    folds = min(MOST_FOLDS, count)
    return [np.arange(f, count, folds, dtype=np.int64) for f in range(folds)]


class _Sums:
    """Sums of squared errors and of squared true values: a relative RMSE built up in parts."""

    def __init__(self) -> None:
        self.error = 0.0
        self.energy = 0.0

    def add(self, predicted: NDArray[np.floating], truth: NDArray[np.floating],
            mask: NDArray[np.bool_]) -> None:  # fmt: skip
        true = np.asarray(truth, np.float64)[mask]
        self.error += float(np.sum((np.asarray(predicted, np.float64)[mask] - true) ** 2))
        self.energy += float(np.sum(true**2))

    @property
    def relative(self) -> float:
        return math.sqrt(self.error / self.energy) if self.energy > 0 else 0.0


def _timed_radiance(
    engine: RelightEngine,
    field: ReflectanceField,
    panorama: Panorama,
    cameras: Sequence[int],
    timed: Collection[int] = (),
) -> tuple[list[tuple[NDArray[np.float32], NDArray[np.bool_]]], float, float]:
    """Relit samples at ``cameras``, and the ms of preparing a lighting and of relighting.

    Times are of a new lighting at an unchanged view (the interactive loop) at the ``timed``
    cameras, the fastest of them (the least disturbed by other work on the machine); 0 when
    none is timed.
    """
    out, prepare, render = [], [], []
    engine.set_lighting(panorama)
    for s in cameras:
        engine.set_view(field.cameras[s])
        image = engine.render()
        if s in timed:
            engine.render()  # the first renders after a view change build the view's caches
            prepare.append(engine.set_lighting(panorama))
            image = engine.render()
            render.append(image.seconds["relight"])
        out.append((image.radiance, image.needed & field.visibility[s]))
    if not prepare:
        return out, 0.0, 0.0
    return out, 1e3 * min(prepare), 1e3 * min(render)


@dataclass
class _Fold:
    """One hold-out fold: what is kept, what is held out, and the models fitted without it."""

    kept: NDArray[np.int64]
    held: NDArray[np.int64]
    part: ReflectanceField
    engines: dict[str, ModelRelighter]


class Advisor:
    """Predicts the error and speed of relighting configurations on one field.

    The sample subset, the hold-out folds and their model fits do not depend on the lighting,
    so they are made once (on first use) and every :meth:`predict` reuses them.

    Parameters
    ----------
    field : ReflectanceField
    candidates : the configurations to compare (default :func:`default_candidates` of the
        models a field of its kind can fit)
    samples : int, samples to work on (point fields; pixel fields use all)
    seed : int, of the sample subset
    """

    def __init__(
        self,
        field: ReflectanceField,
        candidates: Sequence[Candidate] | None = None,
        *,
        samples: int = ADVISOR_SAMPLES,
        seed: int = 0,
    ) -> None:
        s_count, t_count, p_count = field.shape
        if t_count < FEWEST_LIGHTS:
            raise InputError(
                f"{field.path}: predicting errors holds out measured lights; the field has "
                f"{t_count} lights (at least {FEWEST_LIGHTS} needed)"
            )
        if candidates is None:
            names = (
                PARAMETRIC_MODELS
                if field.sample_kind == "points"
                else (*PARAMETRIC_MODELS, "hsh2", "hsh3")
            )
            candidates = default_candidates(names)  # fmt: skip
        if not candidates:
            raise InputError("no candidate configurations to compare")
        self.candidates = list(candidates)
        self.field_samples = p_count
        keep: NDArray[np.int64] | None = None
        if field.sample_kind == "points" and p_count > samples:
            seen = np.flatnonzero(field.visibility.any(axis=0))
            chosen = np.random.default_rng(seed).choice(seen, min(samples, len(seen)), False)
            keep = np.sort(chosen)
        self.part = field.subset(samples=keep)
        models = [c.light_predictor[1] for c in self.candidates if c.mode.uses_models]
        self._model_names = list(dict.fromkeys(models))
        self._models: SampleModels | None = None
        self.views_tested = field.sample_kind == "points" and s_count >= FEWEST_CAMERAS
        self._light_folds: list[_Fold] | None = None
        self._camera_folds: list[_Fold] | None = None
        self._shared: dict[str, ModelRelighter] = {}

    def _fold(self, held: NDArray[np.int64], count: int, axis: str) -> _Fold:
        kept = np.setdiff1d(np.arange(count), held)
        part = self.part.subset(**{axis: kept})
        engines: dict[str, ModelRelighter] = {}
        if self._model_names:
            fitted = fit_sample_models(part, self._model_names)
            engines = {
                name: ModelRelighter(part, ModelRelightSettings(model=name), fitted)
                for name in self._model_names
            }
        return _Fold(kept, held, part, engines)

    def _folds(self) -> tuple[list[_Fold], list[_Fold]]:
        if self._light_folds is None or self._camera_folds is None:
            s_count, t_count, _ = self.part.shape
            light_held = _folds(t_count)
            camera_held = _folds(s_count) if self.views_tested else []
            steps = progress_bar(
                total=len(light_held) + len(camera_held), desc="hold-out fits", unit="fold"
            )
            self._light_folds, self._camera_folds = [], []
            for held in light_held:
                self._light_folds.append(self._fold(held, t_count, "lights"))
                steps.update()
            for held in camera_held:
                self._camera_folds.append(self._fold(held, s_count, "cameras"))
                steps.update()
            steps.close()
        return self._light_folds, self._camera_folds

    def hold_out_errors(
        self, weights: NDArray[np.floating]
    ) -> tuple[dict[Predictor, float], dict[Predictor, float]]:
        """The lights and views terms of every predictor the candidates use.

        Parameters
        ----------
        weights : ndarray, shape (T, 3), light carried by each measured light (radiance x sr)

        Returns
        -------
        lights, views : dict of predictor (``Candidate.light_predictor`` /
            ``Candidate.view_predictor``) to relative RMSE; ``views`` is empty for pixel fields
            and fields of fewer than ``FEWEST_CAMERAS`` cameras
        """
        field = self.part
        directions = field.light_directions
        w = np.asarray(weights, dtype=np.float64)
        light_keys = list(dict.fromkeys(c.light_predictor for c in self.candidates))
        view_keys = list(dict.fromkeys(c.view_predictor for c in self.candidates))
        light_folds, camera_folds = self._folds()
        lights = {key: _Sums() for key in light_keys}
        views = {key: _Sums() for key in view_keys}
        # Lights: predict each fold's measured values at every camera.
        for fold in light_folds:
            kept, held = fold.kept, fold.held
            for engine in fold.engines.values():
                engine.set_lights(LightSet(directions[held], w[held]))
            # The light each kept light carries for the fold, per interpolation (T_kept, 3).
            carried = {}
            for key in light_keys:
                if key[0] == "interpolation":
                    method = cast(InterpolationMethod, key[1])
                    a = interpolation_weights(directions[kept], directions[held], method,
                                              m=key[2] or 3)  # fmt: skip
                    carried[key] = a.dense(len(kept)).T @ w[held]
            for s in range(field.shape[0]):
                slab = field.camera_slab(s).astype(np.float64)
                truth = np.einsum("tc,tpc->pc", w[held], slab[held])
                seen = field.visibility[s]
                for key in light_keys:
                    if key[0] == "model":
                        fold.engines[key[1]].set_view(field.cameras[s])
                        image = fold.engines[key[1]].render()
                        lights[key].add(image.radiance, truth, seen & image.needed)
                    else:
                        predicted = np.einsum("jc,jpc->pc", carried[key], slab[kept])
                        lights[key].add(predicted, truth, seen)
        # Views: predict each fold's cameras from the others under the gathered lighting.
        gathered = LightWeights(w[None].astype(np.float32), None, 0.0, "projection")
        for fold in camera_folds:
            for engine in fold.engines.values():
                engine.set_lights(LightSet(directions.copy(), w))
            for s in fold.held:
                camera = field.cameras[int(s)]
                truth = np.einsum("tc,tpc->pc", w, field.camera_slab(int(s)).astype(np.float64))
                seen = field.visibility[s]
                for key in view_keys:
                    if key[0] == "model":
                        fold.engines[key[1]].set_view(camera)
                        image = fold.engines[key[1]].render()
                        views[key].add(image.radiance, truth, seen & image.needed)
                    else:
                        method = cast(InterpolationMethod, key[1])
                        blend = blend_cameras(fold.part, camera, method, n=key[2] or 3, needed=seen)
                        views[key].add(
                            relight(fold.part, gathered, blend), truth, seen & ~blend.holes
                        )
        return (
            {key: sums.relative for key, sums in lights.items()},
            {key: sums.relative for key, sums in views.items()} if self.views_tested else {},
        )

    def _engine(self, mode: RelightMode) -> RelightEngine:
        if not isinstance(mode, ModelRelightSettings):  # the model engines are shared below
            return mode.open(self.part)
        if self._models is None:
            self._models = fit_sample_models(self.part, self._model_names)
        if mode.model not in self._shared:  # choosing shadow marks once per model
            self._shared[mode.model] = ModelRelighter(self.part, mode, self._models)
        return self._shared[mode.model].with_lighting(mode)

    def predict(self, panorama: Panorama) -> list[Prediction]:
        """Every candidate's predicted error and speed under ``panorama``, in candidate order."""
        part = self.part
        s_count = part.shape[0]
        weights = projection_light_weights(panorama.rgb, part.light_directions).rgb[0]
        lights, views = self.hold_out_errors(weights)
        cameras = sorted({round(float(i)) for i in np.linspace(0, s_count - 1, LIGHTING_VIEWS)})
        timed = set(cameras[:: max(len(cameras) // TIMING_VIEWS, 1)][:TIMING_VIEWS])
        reference: dict[str, list[tuple[NDArray[np.float32], NDArray[np.bool_]]]] = {}
        predictions = []
        for candidate in progress_bar(self.candidates, desc="candidates"):
            relit, prepare_ms, render_ms = _timed_radiance(
                self._engine(candidate.mode), part, panorama, cameras, timed
            )
            key = repr(candidate.exact)
            if key not in reference:
                reference[key] = (
                    relit
                    if candidate.exact == candidate.mode
                    else _timed_radiance(self._engine(candidate.exact), part, panorama, cameras)[0]
                )
            # The worst view: a sun's highlight in a coarse lighting errs only where it shows.
            lighting = 0.0
            for (value, mask), (exact, exact_mask) in zip(relit, reference[key], strict=True):
                view = _Sums()
                view.add(value, exact, mask & exact_mask)
                lighting = max(lighting, view.relative)
            terms = (
                lights[candidate.light_predictor],
                views.get(candidate.view_predictor, 0.0),
                lighting,
            )
            predictions.append(
                Prediction(
                    candidate,
                    *terms,
                    error=math.sqrt(sum(t * t for t in terms)),
                    lighting_ms=prepare_ms,
                    frame_ms=prepare_ms + render_ms * self.field_samples / part.shape[2],
                )
            )
        return predictions

    def advise(self, panorama: Panorama, tolerance: float = 0.02) -> Advice:
        """The advice under ``panorama``: the fastest candidate predicted within ``tolerance``.

        Fastest by predicted time per new lighting (ties: the smaller error); ``tolerance`` is
        a relative RMSE in (0, 1). When no candidate is within it, the advice's choice is None.
        """
        if not 0.0 < tolerance < 1.0:
            raise InputError(f"tolerance must be a relative error in (0, 1), got {tolerance}")
        predictions = self.predict(panorama)
        within = [p for p in predictions if p.error <= tolerance]
        choice = min(within, key=lambda p: (p.frame_ms, p.error)) if within else None
        return Advice(choice, predictions, tolerance, self.part.shape[2], self.field_samples)


def advise(
    field: ReflectanceField,
    panorama: Panorama,
    tolerance: float = 0.02,
    *,
    candidates: Sequence[Candidate] | None = None,
    samples: int = ADVISOR_SAMPLES,
    seed: int = 0,
) -> Advice:
    """The cheapest configuration predicted within ``tolerance`` on ``field`` under ``panorama``.

    See :class:`Advisor` (parameters) and the module docstring (how errors are predicted).
    """
    advisor = Advisor(field, candidates, samples=samples, seed=seed)
    return advisor.advise(panorama, tolerance)
