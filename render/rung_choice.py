"""Which rung predicts a field's unmeasured lights: one, or several mixed per pixel.

``rig relight --lights`` (and any caller that wants the best prediction of new lights) asks
every rung the same question on the field's own lights, in folds that look like the use:

- a spread quarter of the lights held out, then another (:data:`SPREAD_GROUPS`,
  :data:`INTERPOLATION_FOLDS`): each held-out light is predicted from its neighbours while the
  rest keeps three quarters of the capture's density, near what the use has;
- when a requested light lies outside the measured lights (below the lowest ring), the lowest
  sixth of the lights held out as well (:func:`render.light_splits.lowest_lights`): extrapolation
  is tested where the use extrapolates.

Each candidate is fitted on every light and on each fold. Its expected error in the use, per
pixel, is its error at the measured lights plus its held-out excess scaled to the gaps of the
requested lights (:class:`UseGaps`: a held-out dome light is as far from the rest as the dome's
spacing, a requested light usually lies between measured ones), on the 8-bit sRGB levels the RTI
literature's PSNR compares. Objects mix materials (a matte base, a glossy figure, metal inlays),
and the best rung differs between them; so the best candidates are also mixed per pixel, each
pixel weighting a member by the inverse of its expected error there (smoothed over a few
pixels): the best :data:`MIXED`; or, when the networks were trained, both and the best of the
rest, and the two alone, the better-scored kept (two networks trained apart err apart and gain
by their mean, and the folds judge a network least well). A mixture is scored honestly: a
fold's weights come from the errors of the other folds only. The winner, a rung or the
mixture, predicts with its fits on every light.

Fields of pixels mix; a field of points chooses one rung (its samples have no image grid to
smooth the errors over).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field as default
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from core.colour import linear_to_srgb
from core.directions import angle_between
from core.errors import InputError, NotApplicable
from core.field_store import ReflectanceField
from core.progress import progress_bar
from processing.image_quality import display_scale
from processing.learned_rti_training import TrainingSettings
from processing.measured_region import MeasuredRegion
from render.light_prediction import make_predictor
from render.light_splits import lowest_lights, spread_groups
from render.prediction_methods import LightPredictor, MixturePredictor

__all__ = [
    "GAP_EXPONENT",
    "LIGHT_CANDIDATES",
    "MIXED",
    "SLOW_CANDIDATES",
    "RungChoice",
    "RungScore",
    "UseGaps",
    "choose_light_rung",
    "light_folds",
    "mixture_members",
]

#: Quick candidates: the interpolations, the RTI tools' fits (on 8-bit values as they fit
#: them, and in linear light), the models with their residual, and with a relief's shadows.
LIGHT_CANDIDATES = (
    "barycentric",
    "rbf",
    "ptm-8bit",
    "hsh3-8bit",
    "hsh3",
    "lambert+ggx+residual",
    "adaptive",
    "relief",
)
#: Candidates that train a network: left out by ``fast``. Told the relief's shadows, the
#: network scored 0.0-1.6 dB above the plain one on six path-traced domes, and 0.36 below on
#: the bundled capture, whose choice with it alone fell to lambert+ggx+residual (1.5 dB
#: below the plain one's): both, at three more trainings a choice (docs/evaluation.md).
SLOW_CANDIDATES = ("learned+residual", "learned+relief+residual")
#: Members of a mixture: the :data:`SLOW_CANDIDATES` that were trained, wherever they rank,
#: then the best of the rest by score; and the networks alone (:func:`mixture_members`). Two
#: networks trained apart err apart (the principled knot: 26.22 and 26.19 dB, their mean
#: 26.79), and a fold, which trains a network on three quarters of the lights, judges it
#: least well (there `learned+residual` came fifth, 1.6 dB below the best). Pairs, and more,
#: of the quick rungs mixed worse: `relief` and `barycentric` on the glazed and plastic bowls
#: (docs/evaluation.md).
MIXED = 3
#: Gaussian width (pixels) the per-pixel errors are smoothed with before they weight.
ERROR_BLUR_PX = 1.5
#: A mixture wins only by at least this much (dB): a tie keeps the simpler single rung. Its
#: weights come from folds whose gaps are about 2.5x the use's, where the rungs differ less:
#: on ten captures (``bench.choice_study --fast``, 2026-12-05) its expected gain over the best
#: rung was 0.46 dB above what it gained on average (the glazed bowl: +0.19 expected, -0.86
#: scored), and at 0.05 it was chosen there.
MIXTURE_MARGIN_DB = 0.2
#: Bytes of held-out predictions kept for the mixture; a larger field chooses one rung.
MIXTURE_BYTES = 1536 * 2**20

#: The lights are dealt into this many spread groups (:func:`render.light_splits.spread_groups`)
#: and the first :data:`INTERPOLATION_FOLDS` groups are held out in turn: each fold keeps three
#: quarters of the lights. Holding out half (every other light) scored the rungs at half the
#: capture's density, where a network trained on the capture loses more than interpolation
#: does: on the bundled capture learned+residual came 2.0 dB below adaptive held out at half
#: density, 0.3 dB below at three quarters, 0.5 dB below on the lights held out of its use.
SPREAD_GROUPS = 4
INTERPOLATION_FOLDS = 2
#: How the use's error grows with its gap (see :class:`UseGaps`): between the linear growth of
#: features sharper than the gap and the quadratic growth of interpolating smooth data. Sharp
#: features (shadows, highlights) carry most of the error: on nine path-traced domes and the
#: bundled capture (``bench.choice_study --fast``), 1.5 expected the chosen rung 1.9 dB above
#: what it scored on average (up to 3.3), 1 expects it 0.0 dB above (mean |error| 1.0 dB, up
#: to 2.6) and chooses the same rungs.
GAP_EXPONENT = 1.0
#: The fold that holds out the lowest lights (extrapolation below the measured lights).
LOWEST = "the lowest lights"

Fold = tuple[str, NDArray[np.int64], NDArray[np.int64]]


@dataclass(frozen=True)
class RungScore:
    """One candidate's held-out score.

    Attributes
    ----------
    name : str, a rung, or ``mixture`` (of :attr:`RungChoice.members`)
    psnr : float, dB, of the 8-bit images over every fold's test lights (-inf: cannot apply)
    seconds : float, fitting and predicting in every fold
    note : str, why it cannot apply
    """

    name: str
    psnr: float
    seconds: float
    note: str = ""


@dataclass(frozen=True)
class RungChoice:
    """The chosen rung (or mixture), every score, and the mixture's make-up.

    Attributes
    ----------
    name : str, the winner
    scores : tuple of RungScore, best first
    folds : tuple of str, the folds' names
    members : tuple of str, the mixture's rungs (empty when it was not formed)
    weights : ndarray (M, P) float32 or None, the mixture's per-pixel weights from every fold
    predictors : dict, the winner's rungs fitted on every light (by name)
    """

    name: str
    scores: tuple[RungScore, ...]
    folds: tuple[str, ...]
    members: tuple[str, ...] = ()
    weights: NDArray[np.float32] | None = None
    predictors: dict[str, LightPredictor] = default(default_factory=dict, compare=False)

    def predictor(self, whole: ReflectanceField) -> LightPredictor:
        """The winner fitted on every light of ``whole`` (the field it was chosen on)."""
        names = self.members if self.name == "mixture" else (self.name,)
        rungs = [self.predictors.get(n) or make_predictor(whole, n)
                 for n in names]  # fmt: skip
        if self.name != "mixture":
            return rungs[0]
        assert self.weights is not None
        return MixturePredictor(whole, rungs, self.weights)

    def describe(self) -> str:
        """The winner in words (a mixture names its members)."""
        if self.name != "mixture":
            return self.name
        return f"a per-pixel mixture of {', '.join(self.members)}"


def light_folds(field: ReflectanceField, queries: NDArray[np.floating] | None = None) -> list[Fold]:
    """The (name, fit, test) folds of ``field``'s lights that look like predicting ``queries``.

    Parameters
    ----------
    field : ReflectanceField
    queries : ndarray (Q, 3), optional, the lights to be predicted (rig frame); when one lies
        outside the measured lights, a fold holds out the lowest lights
    """
    group = spread_groups(field, SPREAD_GROUPS)
    every = np.arange(field.shape[1], dtype=np.int64)
    folds: list[Fold] = [
        (f"spread group {g + 1} of {SPREAD_GROUPS}", every[group != g], every[group == g])
        for g in range(INTERPOLATION_FOLDS)
    ]
    if queries is not None and len(queries):
        outside = MeasuredRegion.build(field.light_directions).outside(
            np.asarray(queries, dtype=np.float64)
        )
        lowest = lowest_lights(field)
        if outside.any() and len(lowest) <= field.shape[1] - 3:
            rest = np.setdiff1d(np.arange(field.shape[1], dtype=np.int64), lowest)
            folds.append((LOWEST, rest, lowest))
    return folds


def _display(values: NDArray[np.floating], scale: float) -> NDArray[np.float32]:
    """Values as 8-bit sRGB levels, unrounded (0..255): what the PSNR compares."""
    return linear_to_srgb(np.asarray(values, dtype=np.float32) * np.float32(scale)) * 255.0


def _smoothed(errors: NDArray[np.float64], field: ReflectanceField) -> NDArray[np.float64]:
    """Per-pixel errors (P,) blurred over the image, the mask's other pixels left out."""
    assert field.image_shape is not None
    seen = field.visibility[0].reshape(field.image_shape).astype(np.float64)
    image = errors.reshape(field.image_shape) * seen
    blurred = cv2.GaussianBlur(image, (0, 0), ERROR_BLUR_PX)
    coverage = cv2.GaussianBlur(seen, (0, 0), ERROR_BLUR_PX)
    mean = float(errors[seen.ravel() > 0].mean()) if seen.any() else 0.0
    return np.where(coverage > 1e-6, blurred / np.maximum(coverage, 1e-6), mean).ravel()


def _weights(errors: Sequence[NDArray[np.float64]]) -> NDArray[np.float32]:
    """Per-pixel weights (M, P) inversely proportional to each member's error there."""
    inverse = np.stack([1.0 / (e + 1e-3) for e in errors])
    return (inverse / inverse.sum(axis=0, keepdims=True)).astype(np.float32)


def mixture_members(ranked: Sequence[str]) -> list[tuple[str, ...]]:
    """The mixtures to try (:data:`MIXED`), from every candidate's name, best first.

    The :data:`SLOW_CANDIDATES` among ``ranked`` and the best of the rest, :data:`MIXED` in
    all; and the networks alone when two or more were trained. Each in its rank.
    """
    networks = [n for n in ranked if n in SLOW_CANDIDATES][:MIXED]
    rest = [n for n in ranked if n not in SLOW_CANDIDATES][: MIXED - len(networks)]
    chosen = {*networks, *rest}
    tries = [tuple(n for n in ranked if n in chosen)]
    if 2 <= len(networks) < len(tries[0]):
        tries.append(tuple(networks))
    return tries


def choose_light_rung(
    field: ReflectanceField,
    queries: NDArray[np.floating] | None = None,
    *,
    fast: bool = False,
    candidates: Sequence[str] | None = None,
    mix: bool = True,
    learned: TrainingSettings | None = None,
) -> RungChoice:
    """Choose the rung (or the per-pixel mixture) that predicts ``field``'s lights best.

    Parameters
    ----------
    field : ReflectanceField (camera 0 is scored: a field of pixels' one view)
    queries : ndarray (Q, 3), optional, the lights to predict (rig frame; see
        :func:`light_folds` and :class:`UseGaps`)
    fast : bool, leave out the candidates that train a network
    candidates : names, optional (default :data:`LIGHT_CANDIDATES`, then
        :data:`SLOW_CANDIDATES` unless ``fast``)
    mix : bool, also try the per-pixel mixture (fields of pixels)
    learned : TrainingSettings, optional, how the learned rung trains (its default settings)

    Raises
    ------
    InputError
        A field too small to split, or no candidate that applies. A candidate that does not
        apply (:class:`core.errors.NotApplicable`: a basis with more terms than a fold's
        lights) is left out with its reason; any other error of a candidate (its fit cannot
        be saved, say) stops the choice.
    """
    names = list(candidates or (*LIGHT_CANDIDATES, *(() if fast else SLOW_CANDIDATES)))
    folds = light_folds(field, queries)
    gaps = UseGaps.of(field, folds, queries)
    seen = field.visibility[0]
    rti = field.provenance.get("source") == "rti"
    scale = 1.0 if rti else display_scale(field.camera_slab(0)[:, seen])
    measured = _display(field.camera_slab(0)[:, seen], scale)
    truths = [_display(field.camera_slab(0)[test][:, seen], scale) for _, _, test in folds]
    keep = mix and field.image_shape is not None
    held = sum(len(t) for t in truths) + len(measured)
    keep = keep and held * int(seen.sum()) * 12 * len(names) <= MIXTURE_BYTES
    trials: dict[str, _Trial] = {}
    seconds = dict.fromkeys(names, 0.0)
    notes: dict[str, str] = {}
    bar = progress_bar(total=len(names) * (len(folds) + 1), desc="choosing", unit="fit")
    try:
        for name in names:
            start = time.perf_counter()
            try:
                predictor = make_predictor(field, name, learned=learned)
                at_measured = predictor.predict(0, field.light_directions)[:, seen]
                trials[name] = _Trial(predictor, _mse(at_measured, measured, scale), [],
                                      at_measured if keep else None, [])  # fmt: skip
            except NotApplicable as error:  # a basis with more terms than the lights
                notes[name] = str(error)
            seconds[name] += time.perf_counter() - start
            bar.update()
        for (_, fit, test), truth in zip(folds, truths, strict=True):
            # One part per fold for every candidate: the rungs built on one model (the model,
            # its residual, the adaptive mixture) fit it once there, and those on the relief
            # (``relief``, the network told its shadows) its heights. One fold at a time, as
            # each part is a copy of most of the field.
            part = field.subset(lights=fit)
            for name in list(trials):
                start = time.perf_counter()
                try:
                    predicted = make_predictor(part, name, learned=learned).predict(
                        0, field.light_directions[test]
                    )[:, seen]
                except NotApplicable as error:  # a basis with more terms than a fold's lights
                    notes[name] = str(error)
                    del trials[name]
                else:
                    trials[name].folds.append(_mse(predicted, truth, scale))
                    trials[name].held_out.append(predicted if keep else predicted[:0])
                seconds[name] += time.perf_counter() - start
                bar.update()
    finally:
        bar.close()
    if not trials:
        raise InputError(f"{field.path}: no method applies ({'; '.join(notes.values())})")
    use = {name: gaps.use_errors(trial.inside, trial.folds) for name, trial in trials.items()}
    scores = [RungScore(n, _psnr(use[n]) if n in use else -math.inf, seconds[n], notes.get(n, ""))
              for n in names]  # fmt: skip
    scores.sort(key=lambda s: -s.psnr)
    fold_names = tuple(name for name, _, _ in folds)
    applied = [s.name for s in scores if s.name in trials]
    tries = mixture_members(applied)
    found = {n: trials[n].predictor for n in applied[:1]}
    if not keep or len(tries[0]) < 2:
        return RungChoice(scores[0].name, tuple(scores), fold_names, predictors=found)
    mixtures = {
        members: _mixture_use_errors(
            field, [trials[m] for m in members], gaps, measured, truths, scale
        )
        for members in tries
    }
    members = max(tries, key=lambda m: _psnr(mixtures[m]))
    mixture = mixtures[members]
    weights = _weights([_smoothed(_full(field, use[m]), field) for m in members])
    mixed = RungScore("mixture", _psnr(mixture), sum(seconds[m] for m in members))
    ranked = tuple(sorted([*scores, mixed], key=lambda s: -s.psnr))
    name = "mixture" if mixed.psnr > scores[0].psnr + MIXTURE_MARGIN_DB else scores[0].name
    found = {m: trials[m].predictor for m in (members if name == "mixture" else applied[:1])}
    return RungChoice(name, ranked, fold_names, members, weights, predictors=found)


@dataclass
class _Trial:
    """One candidate on the field: fitted on every light, and on each fold."""

    predictor: LightPredictor
    inside: NDArray[np.float64]  # (N,) per-pixel MSE at the measured lights, fit on all
    folds: list[NDArray[np.float64]]  # per fold (N,) per-pixel held-out MSE
    at_measured: NDArray[np.float32] | None  # (T, N, 3) linear, fit on all (for the mixture)
    held_out: list[NDArray[np.float32]]  # per fold (Q_f, N, 3) linear (for the mixture)


def _mse(
    predicted: NDArray[np.float32], truth: NDArray[np.float32], scale: float
) -> NDArray[np.float64]:
    """Per-pixel mean squared error (N,) of linear ``predicted`` (Q, N, 3) on the display levels."""
    difference = _display(predicted, scale) - truth
    return np.mean(difference.astype(np.float64) ** 2, axis=(0, 2))


@dataclass(frozen=True)
class UseGaps:
    """How far the use's lights are from the measured ones, against the folds' held-out lights.

    A held-out light is as far from the fit lights as the dome's spacing; a light to predict
    usually lies between measured lights, closer. Interpolation error grows with that gap,
    between linearly (features sharper than the gap) and quadratically (smooth data) by the
    usual bounds: the per-pixel error of the use is taken as the error at the measured lights
    (0 for a rung that reproduces them, the fit's residual for a basis) plus the held-out
    excess scaled by ``ratio ** GAP_EXPONENT``, ``ratio`` the mean gap of the use over the
    folds'. Requests outside the measured lights are scored by the lowest-lights fold, scaled
    alike by their gap over that fold's, and weighed by their share.

    Attributes
    ----------
    ratio : float, the use's mean gap over the interpolation folds' (1 without requests)
    outside : float, share of the requests outside the measured lights
    below : float, the requests outside: their mean gap over the lowest lights' fold's
    """

    ratio: float
    outside: float
    below: float = 1.0

    @classmethod
    def of(
        cls, field: ReflectanceField, folds: list[Fold], queries: NDArray[np.floating] | None
    ) -> UseGaps:
        """The gaps of predicting ``queries`` from ``field``, against ``folds``'."""
        if queries is None or not len(queries):
            return cls(1.0, 0.0)
        lights = field.light_directions
        q = np.asarray(queries, dtype=np.float64)
        outside = MeasuredRegion.build(lights).outside(q)
        held = [np.degrees(angle_between(lights[test][:, None], lights[fit][None]).min(axis=1))
                for name, fit, test in folds if name != LOWEST]  # fmt: skip
        fold_gap = float(np.mean(np.concatenate(held)))
        inside = q[~outside]
        ratio = 1.0
        if len(inside) and fold_gap > 0:
            nearest = angle_between(inside[:, None], lights[None]).min(axis=1)
            ratio = float(np.mean(np.degrees(nearest))) / fold_gap
        lowest = [(fit, test) for name, fit, test in folds if name == LOWEST]
        if not lowest:
            return cls(ratio, 0.0)
        fit, test = lowest[0]
        low_gap = np.degrees(angle_between(lights[test][:, None], lights[fit][None]).min(axis=1))
        far = np.degrees(angle_between(q[outside][:, None], lights[None]).min(axis=1))
        return cls(ratio, float(outside.mean()), float(far.mean() / max(low_gap.mean(), 1e-9)))

    def use_errors(
        self, inside: NDArray[np.float64], folds: list[NDArray[np.float64]]
    ) -> NDArray[np.float64]:
        """Per-pixel MSE (N,) expected in the use, from the measured and the folds' errors."""
        between = np.mean(folds[:2], axis=0)
        expected = inside + np.maximum(between - inside, 0.0) * self.ratio**GAP_EXPONENT
        if len(folds) > 2:
            below = inside + np.maximum(folds[2] - inside, 0.0) * self.below**GAP_EXPONENT
            return (1.0 - self.outside) * expected + self.outside * below
        return expected


def _full(field: ReflectanceField, values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Values of the object's pixels (N,) spread over every pixel (P,), 0 elsewhere."""
    out = np.zeros(field.shape[2])
    out[field.visibility[0]] = values
    return out


def _mixture_use_errors(
    field: ReflectanceField,
    trials: list[_Trial],
    gaps: UseGaps,
    measured: NDArray[np.float32],
    truths: list[NDArray[np.float32]],
    scale: float,
) -> NDArray[np.float64]:
    """The mixture's per-pixel use errors (N,), each fold mixed by the other folds' errors."""
    seen = field.visibility[0]

    def mixed(values: list[NDArray[np.float32]], weights: NDArray[np.float32]) -> NDArray[Any]:
        out = np.zeros_like(values[0])
        for weight, value in zip(weights, values, strict=True):
            out += weight[None, :, None] * value
        return out

    def mse(predicted: NDArray[np.float32], truth: NDArray[np.float32]) -> NDArray[np.float64]:
        return np.mean((_display(predicted, scale) - truth).astype(np.float64) ** 2, axis=(0, 2))

    def weights_without(fold: int) -> NDArray[np.float32]:
        errors = [np.mean([e for g, e in enumerate(t.folds) if g != fold], axis=0) for t in trials]
        return _weights([_smoothed(_full(field, e), field)[seen] for e in errors])

    folds = [mse(mixed([t.held_out[f] for t in trials], weights_without(f)), truths[f])
             for f in range(len(truths))]  # fmt: skip
    overall = _weights([_smoothed(_full(field, np.mean(t.folds, axis=0)), field)[seen]
                        for t in trials])  # fmt: skip
    at_measured = [t.at_measured for t in trials]
    assert all(a is not None for a in at_measured)
    inside = mse(mixed([a for a in at_measured if a is not None], overall), measured)
    return gaps.use_errors(inside, folds)


def _psnr(errors: NDArray[np.float64]) -> float:
    """PSNR (dB) of per-pixel mean squared errors of 8-bit levels."""
    mse = float(np.mean(errors)) if errors.size else math.nan
    if not math.isfinite(mse):
        return -math.inf
    return math.inf if mse <= 0 else 10.0 * math.log10(255.0**2 / mse)
