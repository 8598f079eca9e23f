"""What the advisor compares and answers: candidates, predictions, the advice, a capture density.

A :class:`Candidate` is a relighting configuration (:func:`default_candidates`: the paper's,
the linear schemes, the models); :class:`render.advisor.Advisor` predicts each one's error and
speed on a field (a :class:`Prediction`) and answers with an :class:`Advice`: the fastest
within the tolerance. From the advice on a sparse pre-capture, :func:`capture_density`
suggests how many camera and light positions the real capture needs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from core.errors import InputError
from processing.sample_models import PARAMETRIC_MODELS
from render.engines.interpolated import Predictor, RelightSettings
from render.engines.models import ModelRelightSettings
from render.engines.modes import RelightMode

__all__ = [
    "EXACT_GRID",
    "MOST_POSITIONS",
    "Advice",
    "Candidate",
    "CaptureDensity",
    "Prediction",
    "capture_density",
    "default_candidates",
]

#: Most light or camera positions a density suggestion goes to (a dense light stage: 400).
MOST_POSITIONS = 2_000
#: The exact lighting of the model candidates' lighting term (as ``MOST_ACCURATE_MODELS``).
EXACT_GRID = 64


@dataclass(frozen=True)
class Candidate:
    """One relighting configuration the advisor may choose.

    Attributes
    ----------
    name : str, for people
    mode : RelightSettings or ModelRelightSettings
    """

    name: str
    mode: RelightMode

    @property
    def light_predictor(self) -> Predictor:
        """What predicts an unmeasured light (see :data:`render.engines.interpolated.Predictor`)."""
        return self.mode.predictors()[0]

    @property
    def view_predictor(self) -> Predictor:
        """What predicts an uncaptured view (see :data:`render.engines.interpolated.Predictor`)."""
        return self.mode.predictors()[1]

    @property
    def exact(self) -> RelightMode:
        """The same predictors with exact lighting (the reference of the lighting term)."""
        return self.mode.exact_lighting(EXACT_GRID)


def default_candidates(models: Sequence[str] = PARAMETRIC_MODELS) -> list[Candidate]:
    """The configurations compared by default: the paper's, our linear schemes, the models.

    Parameters
    ----------
    models : model names to offer (those fitted to the field)
    """
    out = [Candidate(f"paper, K={k}", RelightSettings.paper_configuration(k)) for k in (16, 64)]
    wide = replace(RelightSettings.paper_configuration(64), m=6, n=6)
    out.append(Candidate("paper, K=64, cosine 6 x 6", wide))
    out += [
        Candidate(
            f"sampled K={k}, barycentric",
            RelightSettings(
                scheme="sampled", k=k, interpolation="barycentric", view_interpolation="barycentric"
            ),
        )
        for k in (16, 64, 256, 1024)
    ]
    out.append(
        Candidate(
            "median cut K=64, barycentric",
            RelightSettings(
                scheme="sampled", k=64, sampler="median-cut", interpolation="barycentric",
                view_interpolation="barycentric",
            ),
        )
    )  # fmt: skip
    out.append(
        Candidate(
            "every pixel (eq. 2), barycentric",
            RelightSettings(
                scheme="pixels", interpolation="barycentric", view_interpolation="barycentric"
            ),
        )
    )
    for name in models:
        out += [
            Candidate(f"{name}, sampled K={k}", ModelRelightSettings(model=name, k=k))
            for k in (16, 64, 256)
        ]
        out += [
            Candidate(f"{name}, grid {g}", ModelRelightSettings(model=name, lighting="grid",
                                                                grid_height=g))
            for g in (16, 32, 64)
        ]  # fmt: skip
    return out


@dataclass(frozen=True)
class Prediction:
    """A candidate's predicted error (relative RMSE over seen samples) and speed.

    Attributes
    ----------
    candidate : Candidate
    lights, views, lighting : float, the three error terms (``views`` 0 for pixel fields)
    error : float, sqrt of the sum of their squares
    lighting_ms : float, preparing a new lighting (sampling, weights), milliseconds
    frame_ms : float, a new lighting at an unchanged view: ``lighting_ms`` plus relighting
        the field's samples (measured on the subset, scaled to the field's sample count)
    """

    candidate: Candidate
    lights: float
    views: float
    lighting: float
    error: float
    lighting_ms: float
    frame_ms: float


@dataclass(frozen=True)
class Advice:
    """The advisor's answer.

    Attributes
    ----------
    choice : Prediction or None, the fastest candidate within the tolerance (None: none is)
    predictions : list of Prediction, every candidate, in candidate order
    tolerance : float, relative RMSE
    samples : int, samples the predictions were made on (of ``field_samples``)
    field_samples : int
    """

    choice: Prediction | None
    predictions: list[Prediction]
    tolerance: float
    samples: int
    field_samples: int

    def format(self) -> str:
        """A table of every candidate and a sentence on the choice, for people."""
        lines = [
            f"{'candidate':34s} {'lights':>7s} {'views':>7s} {'lighting':>8s} {'error':>7s} "
            f"{'ms/frame':>9s}"
        ]
        for p in self.predictions:
            mark = " <- chosen" if self.choice is not None and p is self.choice else ""
            lines.append(
                f"{p.candidate.name:34s} {p.lights:7.2%} {p.views:7.2%} {p.lighting:8.2%} "
                f"{p.error:7.2%} {p.frame_ms:9.1f}{mark}"
            )
        if self.choice is None:
            best = min(self.predictions, key=lambda p: p.error)
            lines.append(
                f"no configuration is predicted within {self.tolerance:.2%}; the most accurate is "
                f"{best.candidate.name} ({best.error:.2%}): capture more lights or cameras"
            )
        else:
            lines.append(
                f"choice: {self.choice.candidate.name}, predicted error {self.choice.error:.2%} "
                f"(tolerance {self.tolerance:.2%}), {self.choice.frame_ms:.1f} ms per new "
                f"lighting at {self.field_samples} samples"
            )
        lines.append(
            f"(predicted by holding out measured lights and cameras, on {self.samples} of "
            f"{self.field_samples} samples)"
        )
        return "\n".join(lines)


@dataclass(frozen=True)
class CaptureDensity:
    """A capture density suggested from a sparse pre-capture.

    Attributes
    ----------
    cameras, lights : int, suggested position counts
    candidate : Candidate, the relighting the density is for
    predicted : Prediction, that candidate's prediction on the pre-capture
    reason : str, for people
    """

    cameras: int
    lights: int
    candidate: Candidate
    predicted: Prediction
    reason: str


def capture_density(advice: Advice, cameras: int, lights: int) -> CaptureDensity:
    """The fewest images (cameras x lights) predicted to relight within the tolerance.

    Interpolation error falls with the square of the spacing, and the spacing of N positions
    on the hemisphere with 1 / sqrt(N), so a held-out error e at N positions is taken to
    become e N / N' at N'. The error budget left after the lighting term is split evenly
    between lights and views. Models limited by what they cannot represent (shadows a
    light grid resolves only so far) fall more slowly: the suggestion is then a lower bound,
    and a second pre-capture at the suggested density checks it.

    Parameters
    ----------
    advice : Advice of the pre-capture
    cameras, lights : int, the pre-capture's counts
    """
    best: tuple[int, float, CaptureDensity] | None = None
    for p in advice.predictions:
        left = advice.tolerance**2 - p.lighting**2
        if left <= 0:
            continue  # the lighting alone exceeds the tolerance at any density
        target = math.sqrt(left / 2.0)
        needed_t = lights if p.lights <= target else math.ceil(lights * p.lights / target)
        needed_s = cameras if p.views <= target else math.ceil(cameras * p.views / target)
        if max(needed_t, needed_s) > MOST_POSITIONS:
            continue
        images = needed_t * needed_s
        reason = (
            f"{p.candidate.name}: held-out error {p.lights:.2%} over lights and {p.views:.2%} "
            f"over views at {cameras} x {lights}; each must fall to {target:.2%}"
        )
        density = CaptureDensity(needed_s, needed_t, p.candidate, p, reason)
        if best is None or (images, p.frame_ms) < best[:2]:
            best = (images, p.frame_ms, density)
    if best is None:
        raise InputError(
            f"no configuration reaches {advice.tolerance:.2%} within {MOST_POSITIONS} light and "
            f"camera positions; relax the tolerance"
        )
    return best[2]
