"""Which rung relights a field of pixels under a panorama: chosen by held-out error under it.

The light-stage sum relights the panorama's smooth light inside the measured region: a
quadrature of the sphere whose errors cancel between neighbouring cells, the best rung or within
a few tenths of a point of it under broad skies on path-traced scenes (docs/evaluation.md). What
it gathers badly, light concentrated within a cell (a sun, a lamp) and light outside the region
the measured lights surround, is split off (:func:`processing.light_split.split_light`) and
predicted at its own directions by the rung chosen for it here: when that light is under
:data:`SHARP_SHARE` of the panorama's, the sum relights everything and nothing is chosen.

Under an environment a rung is used as a weighted sum of its predictions, so the error that
matters is not one light's but the panorama's sum's. The choice therefore looks like the use:

1. the field's lights are split (a spread quarter held out in turn, twice, as the
   single-light choice splits them, and the lowest lights held out when part of the sharp
   light lies below the measured lights, so extrapolation is tested where the use
   extrapolates);
2. the sharp light (as the object sees it: below the horizon blocked when the capture says so)
   is gathered into the spherical Voronoi cells of the held-out lights, E_j;
3. the truth is the sum of the held-out images weighted by E_j, and each candidate predicts
   every held-out light from the fit lights alone and is weighted the same way; its error is
   the relative RMSE in linear light over the object's pixels, its excess over the error of
   the same sum at the measured lights scaled to the panorama's gaps as
   :class:`render.rung_choice.UseGaps` scales it, the splits weighted by the share
   of the light they stand for (the lowest lights: the share outside the measured
   lights; the quarters: the rest).

No split's error is below the error at the measured lights, so a candidate whose error so far
plus that floor over the splits left is already above the best complete one's is stopped there
(the quick candidates come first): the choice is the same, the slow rungs' fits on the splits
are spared where they cannot win.

The winner is refitted on every light and relights the sharp light through
:class:`render.engines.predicted.PredictorRelightSettings` with ``split``, the sum the rest;
when the sum itself wins (its nearest measured light predicts the held-out ones best), it
relights everything. ``--method NAME`` relights the whole panorama through one rung
(:func:`environment_mode`): the light-stage sum is ``RelightSettings(scheme="projection")``
(Debevec et al. 2000), barycentric interpolation the ``pixels`` scheme, the fitted model alone
:data:`render.engines.modes.MOST_ACCURATE_MODELS`, any other predictor
:class:`render.engines.predicted.PredictorRelightSettings`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.directions import angle_between
from core.errors import InputError, NotApplicable
from core.field_store import ReflectanceField
from core.light_set import grid_lights
from core.progress import progress_bar
from processing.image_quality import relative_rmse
from processing.light_split import split_light
from processing.lights import disassemble_lights
from processing.measured_region import MeasuredRegion
from processing.panorama import Panorama
from processing.sample_models import SampleModels
from render.engines.interpolated import RelightSettings
from render.engines.modes import MOST_ACCURATE_MODELS, RelightMode
from render.engines.predicted import PredictorRelightSettings
from render.light_prediction import make_predictor
from render.light_splits import lowest_lights
from render.rung_choice import GAP_EXPONENT, LOWEST, light_folds
from render.rung_choice import SLOW_CANDIDATES as RUNG_SLOW_CANDIDATES

__all__ = [
    "ENVIRONMENT_CANDIDATES",
    "LIGHT_STAGE",
    "MIN_LIGHTS",
    "SHARP_SHARE",
    "SLOW_CANDIDATES",
    "CandidateScore",
    "EnvironmentChoice",
    "choose_environment_mode",
    "environment_mode",
    "held_out_splits",
]

#: The light-stage sum's name in tables (its single-light predictor is ``nearest``).
LIGHT_STAGE = "light-stage"
#: Quick candidates (seconds each on an RTI capture), the baseline first.
ENVIRONMENT_CANDIDATES = (
    LIGHT_STAGE,
    "barycentric",
    "hsh3",
    "lambert+ggx",
    "lambert+ggx+residual",
    "light-stage+lambert+ggx",
    "adaptive",
    "relief",
)
#: Candidates that train a network (minutes): left out by ``fast``; the single-light
#: choice's (:data:`render.rung_choice.SLOW_CANDIDATES`).
SLOW_CANDIDATES = RUNG_SLOW_CANDIDATES
#: The fewest lights the choice splits.
MIN_LIGHTS = 6
#: Share of the panorama's light below the measured lights above which extrapolation is tested.
EXTRAPOLATION_SHARE = 0.02
#: Rows of the blocks the panorama's light outside the measured region is read from.
OUTSIDE_GRID = 32
#: Share of the light split off as sharp below which the light-stage sum relights it all.
SHARP_SHARE = 0.01


@dataclass(frozen=True)
class CandidateScore:
    """One candidate's held-out error under the panorama.

    Attributes
    ----------
    name : str
    error : float, relative RMSE (linear light) of the panorama-weighted held-out sum
    seconds : float, fitting and predicting on the splits
    note : str, why it could not apply (its error is then infinite), or where it was stopped
        as unable to win (its error is then a lower bound)
    """

    name: str
    error: float
    seconds: float
    note: str = ""


@dataclass(frozen=True)
class EnvironmentChoice:
    """The chosen mode, every candidate's score and why.

    ``sharp_share``: the share of the panorama's light the chosen rung predicts (the rest is
    the light-stage sum's); ``scores`` are errors under that light alone.
    """

    mode: RelightMode
    scores: tuple[CandidateScore, ...]
    splits: tuple[str, ...]
    reason: str
    sharp_share: float = 1.0


def environment_mode(name: str) -> RelightMode:
    """The relighting mode that relights a field of pixels with candidate ``name``."""
    if name == LIGHT_STAGE:
        return RelightSettings(scheme="projection", view_interpolation="nearest")
    if name == "barycentric":
        return RelightSettings(
            scheme="pixels", interpolation="barycentric", view_interpolation="nearest"
        )
    if name == "lambert+ggx":
        return replace(MOST_ACCURATE_MODELS, model="lambert+ggx")
    return PredictorRelightSettings(method=name)


Split = tuple[str, NDArray[np.int64], NDArray[np.int64], float]


def held_out_splits(field: ReflectanceField, panorama: Panorama) -> list[Split]:
    """The (name, fit, test, weight) light splits that resemble relighting under ``panorama``.

    The folds between the lights are the single-light choice's
    (:func:`render.rung_choice.light_folds`: a spread quarter of the lights held out in turn,
    so a rung is fitted at three quarters of the use's density, and a sun is scored on two
    held-out sets). The weights sum to 1: the lowest lights' split weighs the share of the
    panorama's light outside the measured lights, when above :data:`EXTRAPOLATION_SHARE`.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_LIGHTS` lights.
    """
    if field.shape[1] < MIN_LIGHTS:
        raise InputError(
            f"{field.path}: {field.shape[1]} lights are too few to choose a relighting by "
            f"held-out lights ({MIN_LIGHTS} or more); name one with --method"
        )
    grid = grid_lights(panorama.rgb, OUTSIDE_GRID).nonempty()
    energy = grid.rgb.sum(axis=1)
    outside = MeasuredRegion.build(field.light_directions).outside(grid.directions)
    share = float(energy[outside].sum() / energy.sum()) if energy.sum() > 0 else 0.0
    lowest = lowest_lights(field)
    below = share > EXTRAPOLATION_SHARE and len(lowest) <= field.shape[1] - 3
    between = light_folds(field)
    inside = (1.0 - share if below else 1.0) / len(between)
    splits = [(name, fit, test, inside) for name, fit, test in between]
    if below:
        rest = np.setdiff1d(np.arange(field.shape[1], dtype=np.int64), lowest)
        splits.append((LOWEST, rest, lowest, share))
    return splits


def _weighted_truth(
    field: ReflectanceField, panorama: Panorama, test: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The held-out lights' cell energies (Q, 3) and the truth they weight (P, 3)."""
    cells = disassemble_lights(panorama.rgb, field.light_directions[test])
    slab = field.camera_slab(0)[test]
    return cells.rgb, np.einsum("qc,qpc->pc", cells.rgb, slab.astype(np.float64))


def _summed_error(
    field: ReflectanceField,
    panorama: Panorama,
    name: str,
    part: ReflectanceField,
    test: NDArray[np.int64],
    models: SampleModels | None = None,
) -> float:
    """Relative RMSE of ``name`` fitted on ``part``, its ``test`` predictions summed alike.

    ``part``: ``field`` itself, or its subset of the fit lights; ``models``: a fit of
    ``part``.
    """
    weights, truth = _weighted_truth(field, panorama, test)
    predictor = make_predictor(part, "nearest" if name == LIGHT_STAGE else name, models=models)
    predicted = predictor.predict(0, field.light_directions[test])
    estimate = np.einsum("qc,qpc->pc", weights, predicted.astype(np.float64))
    seen = field.visibility[0]
    return relative_rmse(estimate[None, seen], truth[None, seen])


def _gap_ratio(field: ReflectanceField, panorama: Panorama, split: Split, *, below: bool) -> float:
    """The panorama's light's mean gap to the measured lights over the split's held-out gap.

    ``below``: of the light outside the measured lights (the lowest lights' split), else of
    the light inside them.
    """
    _, fit, test, _ = split
    lights = field.light_directions
    held = np.degrees(angle_between(lights[test][:, None], lights[fit][None]).min(axis=1))
    grid = grid_lights(panorama.rgb, OUTSIDE_GRID).nonempty()
    outside = MeasuredRegion.build(lights).outside(grid.directions)
    energy = grid.rgb.sum(axis=1) * (outside if below else ~outside)
    if energy.sum() <= 0 or held.mean() <= 0:
        return 1.0
    gaps = np.degrees(angle_between(grid.directions[:, None], lights[None]).min(axis=1))
    return float(np.sum(energy * gaps) / energy.sum() / held.mean())


def choose_environment_mode(
    field: ReflectanceField,
    panorama: Panorama,
    *,
    candidates: Sequence[str] | None = None,
    models: SampleModels | None = None,
    fast: bool = False,
) -> EnvironmentChoice:
    """Choose how a field of pixels is relit under ``panorama`` (see the module).

    Parameters
    ----------
    field : ReflectanceField of pixels (one view)
    panorama : Panorama, as the object sees it (yaw, exposure and the horizon applied)
    candidates : names, optional; default :data:`ENVIRONMENT_CANDIDATES` and, unless ``fast``,
        :data:`SLOW_CANDIDATES`
    models : SampleModels, optional, a saved fit of the field (else fitted, or read from beside
        a store)
    fast : bool, leave out the candidates that train a network

    Raises
    ------
    InputError
        A field of points, or one with fewer than :data:`MIN_LIGHTS` lights. A candidate
        that does not apply (:class:`core.errors.NotApplicable`) is left out with its reason;
        any other error of a candidate stops the choice.
    """
    if field.image_shape is None:
        raise InputError(f"{field.path}: the environment choice is made for fields of pixels")
    names = list(candidates or (*ENVIRONMENT_CANDIDATES, *(() if fast else SLOW_CANDIDATES)))
    parts = split_light(panorama.rgb, field.light_directions)
    if parts.sharp_share < SHARP_SHARE:
        reason = (
            f"{LIGHT_STAGE}: the panorama's light is smooth over the measured lights "
            f"({parts.sharp_share:.1%} of it concentrated within a light's cell or outside them)"
        )
        return EnvironmentChoice(environment_mode(LIGHT_STAGE), (), (), reason, parts.sharp_share)
    panorama = replace(panorama, rgb=parts.sharp)
    splits = held_out_splits(field, panorama)
    # The heaviest split first: a candidate that cannot win is stopped the sooner.
    order = sorted(splits, key=lambda split: -split[3])
    ratios = [_gap_ratio(field, panorama, split, below=split[0] == LOWEST) for split in order]
    errors = dict.fromkeys(names, 0.0)
    seconds = dict.fromkeys(names, 0.0)
    notes: dict[str, str] = {}
    # One part per split, kept for every candidate: the rungs built on one model fit it once.
    subsets: dict[int, ReflectanceField] = {}
    everything = np.arange(field.shape[1], dtype=np.int64)
    lowest = math.inf  # the best complete candidate's error so far
    bar = progress_bar(total=len(names) * len(order), desc="choosing", unit="method")
    try:
        for name in names:  # the quick candidates first: they set the bar the slow ones meet
            start = time.perf_counter()
            done = 0
            try:
                # The use's gaps are narrower than a held-out light's: the excess over the
                # error at the measured lights shrinks (rung_choice.UseGaps).
                inside = _summed_error(field, panorama, name, field, everything, models)
                for index, (_, fit, test, weight) in enumerate(order):
                    # No split's term is below the measured lights' error: a bound on the rest.
                    bound = errors[name] + inside * sum(split[3] for split in order[index:])
                    if bound >= lowest:
                        errors[name] = bound
                        notes[name] = (
                            f"stopped after {index} of {len(order)} splits: at least "
                            f"{bound:.1%}, above the best's {lowest:.1%}"
                        )
                        break
                    if index not in subsets:
                        subsets[index] = field.subset(lights=fit)
                    error = _summed_error(field, panorama, name, subsets[index], test)
                    excess = max(error**2 - inside**2, 0.0) * ratios[index] ** GAP_EXPONENT
                    errors[name] += weight * math.sqrt(inside**2 + excess)
                    done += 1
                    bar.update()
                else:
                    lowest = min(lowest, errors[name])
            except NotApplicable as problem:  # a basis with more terms than the lights
                errors[name], notes[name] = math.inf, str(problem)
            bar.update(len(order) - done)
            seconds[name] = time.perf_counter() - start
    finally:
        bar.close()
    scores = tuple(
        sorted(
            (CandidateScore(n, errors[n], seconds[n], notes.get(n, "")) for n in names),
            key=lambda score: score.error,
        )
    )
    best = scores[0]
    stage = next((s for s in scores if s.name == LIGHT_STAGE), None)
    against = (
        f", the light-stage sum {stage.error:.1%}" if stage is not None and best != stage else ""
    )
    between = sum(weight for name, _, _, weight in splits if name != LOWEST)
    how = f"a spread quarter in turn, {between:.0%}" + "".join(
        f" and {name}, {weight:.0%}" for name, _, _, weight in splits if name == LOWEST
    )
    share = (
        f"{parts.sharp_share:.0%} of the light (concentrated within a light's cell or outside "
        "the measured lights)"
    )
    held = (
        f"held-out lights ({how}) summed under that light with {best.error:.1%} error{against} "
        f"({sum(seconds.values()):.0f} s to choose among {len(names)})"
    )
    if best.name == LIGHT_STAGE:
        mode = environment_mode(LIGHT_STAGE)
        reason = (
            f"{LIGHT_STAGE} for all the light: its nearest measured light predicts the sharp "
            f"{share} best, {held}"
        )
    else:
        mode = PredictorRelightSettings(method=best.name, split=True)
        reason = (
            f"{best.name} relights the sharp {share}, {LIGHT_STAGE} the rest; it predicts {held}"
        )
    return EnvironmentChoice(
        mode, scores, tuple(name for name, _, _, _ in splits), reason, parts.sharp_share
    )
