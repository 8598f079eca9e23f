"""Held-out-light evaluation: every method predicts lights it never saw, as the RTI literature does.

A field is split into the lights a method may use (the fit lights) and the lights it must
predict (the test lights), or a second capture of other lights is given as the test. Each
method (:mod:`render.light_prediction`) predicts every test image from the fit lights alone,
and :mod:`processing.image_quality` scores it against the measured image: PSNR and SSIM of the
8-bit sRGB images, mean CIEDE2000, relative RMSE in linear light. Means are over the test
images; the mean PSNR is that of the mean squared error over them (relight's protocol: a
single exactly predicted image would make a mean of PSNRs infinite).

Images: a field of pixels is its one view; a field of points is splatted into each captured
camera's image (:class:`render.field_view.FieldView`), the metrics taken over the pixels it
covers. What is scored (the fit and test lights of a split or a test capture, and of a large
view its tiles) is :mod:`render.held_out_lights`.

Display range of the 8-bit metrics: an RTI capture's values are its images' decoded 8-bit
values, so white is 1; a simulated (HDR) field is scaled so that the test images'
99.5th percentile is white (:func:`processing.image_quality.display_scale`), once for all
methods.

Splits of one capture (``split``): :mod:`render.light_splits`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError, RigError
from core.field_store import ReflectanceField
from core.progress import progress_bar
from processing.image_quality import ImageQuality, clipped_srgb_8bit, display_scale, image_quality
from render.field_view import FieldView
from render.held_out_lights import PixelSample
from render.light_prediction import PREDICTORS, make_predictor, training_summary
from render.light_splits import split_lights
from render.prediction_methods import LightPredictor
from render.rung_choice import choose_light_rung

__all__ = [
    "CHOICE_SAMPLES",
    "CHOSEN",
    "Evaluation",
    "HeldOutError",
    "MethodResult",
    "evaluate",
    "held_out_errors",
]

#: The product's own choice as a method: ``rig relight --lights``'s automatic rung (with
#: ``-fast``: the quick rungs only), chosen on the fit lights for the test lights' directions.
CHOSEN = ("auto", "auto-fast")
#: Samples of a field of points :func:`held_out_errors` predicts (a random subset).
CHOICE_SAMPLES = 3000


@dataclass(frozen=True)
class HeldOutError:
    """A method's error on held-out lights, in linear light and as displayed.

    Attributes
    ----------
    relative_rmse : float, sqrt(sum (p - r)^2 / sum r^2) in linear light
    psnr : float, dB, of the 8-bit sRGB display values (the display range as the module says;
        inf when exact)
    """

    relative_rmse: float
    psnr: float

    def __str__(self) -> str:
        return f"{self.relative_rmse:.2%} ({self.psnr:.1f} dB)"


def held_out_errors(
    field: ReflectanceField,
    methods: Sequence[str],
    *,
    split: str = "every-other",
    samples: int = CHOICE_SAMPLES,
    seed: int = 0,
) -> dict[str, HeldOutError]:
    """The error of each method on held-out lights of ``field`` itself, for choosing.

    Each method is fitted on the split's fit lights alone and predicts the others; the errors
    are taken over every visible (camera, sample, test light): the relative RMSE in linear
    light (bright values weigh most) and the PSNR of the 8-bit sRGB values (dark regions
    count as the eye sees them). Unlike a leave-one-light-out score of a fit that saw every
    light, no light a method is scored on reached its fit. A field of points is judged on
    ``samples`` random samples.

    Raises
    ------
    InputError
        The split leaves too few lights (see :func:`split_lights`).
    """
    fit_index, test_index = split_lights(field, split)
    keep = None
    if field.sample_kind == "points" and field.shape[2] > samples:
        chosen = np.random.default_rng(seed).choice(field.shape[2], size=samples, replace=False)
        keep = np.sort(chosen)
    fit = field.subset(lights=fit_index, samples=keep)
    test = field.subset(lights=test_index, samples=keep)
    truths = [test.camera_slab(s)[:, test.visibility[s]] for s in range(test.shape[0])]
    rti = field.provenance.get("source") == "rti"
    scale = 1.0 if rti else display_scale(np.concatenate([t.reshape(-1, 3) for t in truths]))
    shown = [clipped_srgb_8bit(t, scale).astype(np.float64) for t in truths]
    energy = sum(float(np.sum(t.astype(np.float64) ** 2)) for t in truths)
    count = sum(t.size for t in truths)
    errors: dict[str, HeldOutError] = {}
    for name in methods:
        predictor = make_predictor(fit, name)
        squared = displayed = 0.0
        for s, (truth, seen) in enumerate(zip(truths, shown, strict=True)):
            predicted = predictor.predict(s, test.light_directions)[:, test.visibility[s]]
            squared += float(np.sum((predicted - truth) ** 2))
            displayed += float(np.sum((clipped_srgb_8bit(predicted, scale) - seen) ** 2))
        mse = displayed / count if count else 0.0
        errors[name] = HeldOutError(
            math.sqrt(squared / energy) if energy > 0 else 0.0,
            10.0 * math.log10(255.0**2 / mse) if mse > 0 else math.inf,
        )
    return errors


@dataclass(frozen=True)
class MethodResult:
    """One method's predictions of the test images.

    Attributes
    ----------
    name : str
    mean : ImageQuality or None, the means over the test images (None: not applicable)
    per_image : tuple of ImageQuality, in test-image order (camera-major)
    seconds : float, fitting the method and predicting every test image
    predict_ms : float, milliseconds to predict one more image once fitted
    note : str, why the method does not apply, or what it chose (sigma, a training's length)
    training : tuple of dict, a learned method's curve: per pass, its phase, epoch, seconds,
        training error and held-out error (None without held-out lights)
    """

    name: str
    mean: ImageQuality | None
    per_image: tuple[ImageQuality, ...]
    seconds: float
    predict_ms: float
    note: str = ""
    training: tuple[dict[str, Any], ...] = ()


@dataclass(frozen=True)
class Evaluation:
    """Every method's held-out-light scores on one field."""

    field: str
    test: str
    fit_lights: int
    test_lights: int
    cameras: int
    scale: float
    test_names: tuple[str, ...]
    methods: tuple[MethodResult, ...]
    sample: PixelSample | None = None

    def best(self) -> MethodResult:
        """The method of the highest mean PSNR."""
        scored = [m for m in self.methods if m.mean is not None]
        if not scored:
            raise InputError("no method could be evaluated")
        return max(scored, key=lambda m: m.mean.psnr if m.mean is not None else -math.inf)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready document: the set-up, then per method its means and per-image scores."""
        return {
            "field": self.field,
            "test": self.test,
            "fit_lights": self.fit_lights,
            "test_lights": self.test_lights,
            "cameras": self.cameras,
            "display_scale": self.scale,
            "test_images": list(self.test_names),
            "pixels": None if self.sample is None else self.sample.to_json(),
            "methods": {
                m.name: {
                    "mean": None if m.mean is None else m.mean.to_dict(),
                    "per_image": [q.to_dict() for q in m.per_image],
                    "seconds": m.seconds,
                    "predict_ms": m.predict_ms,
                    "note": m.note,
                    **({"training": list(m.training)} if m.training else {}),
                }
                for m in self.methods
            },
        }

    def markdown(self) -> str:
        """A Markdown table of the means, best PSNR first."""
        lines = [
            f"Held-out lights: {self.test_lights} test lights predicted from {self.fit_lights} "
            f"({self.cameras} camera{'s' if self.cameras != 1 else ''}); field {self.field}, "
            f"test {self.test}."
            + ("" if self.sample is None else f" Large view, {self.sample.note()}."),
            "",
            "| method | PSNR (dB) | SSIM | ΔE2000 | rel. RMSE | all (s) | one more (ms) | note |",
            "|---|---:|---:|---:|---:|---:|---:|---|",
        ]
        ranked = sorted(
            self.methods, key=lambda m: -(m.mean.psnr if m.mean is not None else -math.inf)
        )
        for m in ranked:
            if m.mean is None:
                lines.append(f"| {m.name} | | | | | | | {m.note} |")
                continue
            q = m.mean
            lines.append(
                f"| {m.name} | {q.psnr:.2f} | {q.ssim:.4f} | {q.delta_e:.2f} | "
                f"{q.rel_rmse:.2%} | {m.seconds:.2f} | {m.predict_ms:.1f} | {m.note} |"
            )
        for m in ranked:
            if m.training:
                lines.append("")
                lines.append(f"{m.name}: {_curve(m.training)}")
        return "\n".join(lines) + "\n"


def _curve(training: Sequence[dict[str, Any]], points: int = 6) -> str:
    """A training curve in a line: error at a few passes (held-out error where lights were)."""
    steps = np.unique(np.linspace(0, len(training) - 1, min(points, len(training))).astype(int))
    parts = []
    for record in (training[i] for i in steps):
        held = record["validation_error"]
        extra = "" if held is None else f", held-out {held:.4f}"
        parts.append(f"pass {record['epoch']} ({record['phase']}, {record['seconds']:.0f} s): "
                     f"training {record['train_error']:.4f}{extra}")  # fmt: skip
    return "; ".join(parts)


def _check_pair(fit: ReflectanceField, test: ReflectanceField) -> None:
    s, _, p = fit.shape
    ts, _, tp = test.shape
    if (s, p) != (ts, tp) or fit.sample_kind != test.sample_kind:
        raise InputError(
            f"{test.path} does not match {fit.path}: {ts} cameras x {tp} {test.sample_kind} "
            f"against {s} x {p} {fit.sample_kind}; the test images must be of the same view(s)"
        )
    if fit.image_shape != test.image_shape:
        raise InputError(f"{test.path}: images {test.image_shape}, the field's {fit.image_shape}")
    if not np.allclose(fit.camera_directions, test.camera_directions, atol=1e-6):
        raise InputError(f"{test.path}: its cameras are not the field's")


def _psnr_of_mean_mse(psnrs: Sequence[float]) -> float:
    """PSNR of the test images' mean squared error (relight's protocol).

    Finite unless every image is predicted exactly, and not owned by one perfect image as a
    mean of PSNRs is.
    """
    mse = [255.0**2 * 10.0 ** (-p / 10.0) for p in psnrs]  # inf PSNR: 0
    mean = float(np.mean(mse))
    return math.inf if mean == 0 else 20.0 * math.log10(255.0) - 10.0 * math.log10(mean)


class _Views:
    """How a camera's sample values become an image, and which pixels count."""

    def __init__(self, field: ReflectanceField, mask: NDArray[np.bool_] | None) -> None:
        self.field = field
        self.mask = mask
        self._views: dict[int, FieldView] = {}

    def image(self, camera: int, values: NDArray[np.floating]) -> NDArray[np.float32]:
        return self._view(camera).image(values)

    def pixels(self, camera: int) -> NDArray[np.bool_]:
        covered = self._view(camera).coverage
        if self.mask is None or self.field.image_shape is None:
            return covered
        return covered & self.mask

    def _view(self, camera: int) -> FieldView:
        if camera not in self._views:
            spacing = next(iter(self._views.values())).spacing if self._views else None
            self._views[camera] = FieldView.captured(self.field, camera, spacing=spacing)
        return self._views[camera]


def _test_images(
    test: ReflectanceField, views: _Views
) -> dict[tuple[int, int], NDArray[np.float32]]:
    """The measured test images, by (camera, test light)."""
    s_count, t_test, _ = test.shape
    truth = {s: test.camera_slab(s) for s in range(s_count)}
    return {(s, q): views.image(s, truth[s][q]) for s in range(s_count) for q in range(t_test)}


def _score_method(
    fit: ReflectanceField,
    test: ReflectanceField,
    name: str,
    scale: float,
    views: _Views,
    images: dict[tuple[int, int], NDArray[np.float32]],
) -> MethodResult:
    """One method's predictions of every test image, scored (see :func:`evaluate`)."""
    s_count, t_test, _ = test.shape
    start = time.perf_counter()
    try:
        predictor = (
            _chosen(fit, test, fast=name == "auto-fast")
            if name in CHOSEN
            else make_predictor(fit, name, scale=scale)
        )
        predicted = {s: predictor.predict(s, test.light_directions) for s in range(s_count)}
    except RigError as error:
        return MethodResult(name, None, (), 0.0, 0.0, f"not applicable: {error}")
    elapsed = time.perf_counter() - start
    again = time.perf_counter()  # fitted now: what one more image costs
    predictor.predict(0, test.light_directions[:1])
    per_image_ms = 1000.0 * (time.perf_counter() - again)
    scores = tuple(
        image_quality(views.image(s, predicted[s][q]), images[s, q], views.pixels(s), scale=scale)
        for s in range(s_count)
        for q in range(t_test)
    )
    mean = ImageQuality(
        psnr=_psnr_of_mean_mse([q.psnr for q in scores]),
        ssim=float(np.mean([q.ssim for q in scores])),
        delta_e=float(np.mean([q.delta_e for q in scores])),
        rel_rmse=float(np.mean([q.rel_rmse for q in scores])),
    )
    sigma = getattr(predictor, "sigma", None)
    note = f"sigma {sigma:.3g}" if isinstance(sigma, float) else ""
    trained, curve = training_summary(predictor)
    return MethodResult(name, mean, scores, elapsed, per_image_ms, note or trained, tuple(curve))


def _chosen(fit: ReflectanceField, test: ReflectanceField, *, fast: bool) -> LightPredictor:
    """What ``rig relight --lights`` predicts ``test``'s lights with: its choice on ``fit``."""
    choice = choose_light_rung(fit, test.light_directions, fast=fast)
    return choice.predictor(fit)


def _score_on_worker(
    fit: ReflectanceField,
    test: ReflectanceField,
    name: str,
    scale: float,
    mask: NDArray[np.bool_] | None,
) -> MethodResult:
    """A Dask task: one method scored, the test images made again on the worker."""
    views = _Views(test, mask)
    return _score_method(fit, test, name, scale, views, _test_images(test, views))


def evaluate(
    fit: ReflectanceField,
    test: ReflectanceField,
    methods: Sequence[str] = PREDICTORS,
    *,
    scale: float | None = None,
    mask: NDArray[np.bool_] | None = None,
    test_names: Sequence[str] | None = None,
    client: Any = None,
    sample: PixelSample | None = None,
) -> Evaluation:
    """Score every method's predictions of ``test``'s lights from ``fit``'s.

    Parameters
    ----------
    fit : ReflectanceField, the lights the methods may use
    test : ReflectanceField, the same cameras and samples under the lights to predict
    methods : names of :data:`render.light_prediction.PREDICTORS`
    scale : float, optional, the linear value of 8-bit white (default: see the module)
    mask : ndarray (H, W) of bool, optional (pixel fields), the pixels that count
    test_names : names of the test lights (default ``light N``)
    client : distributed.Client, optional; one Dask task per method on its cluster (the
        scores are the same; the times are the workers')
    sample : PixelSample, optional, the tiles of a large view ``fit`` and ``test`` hold
        (:mod:`render.held_out_lights`): recorded and said with the scores

    Returns
    -------
    Evaluation; a method that cannot apply (a basis on too few lights) has ``mean`` None and
    says why in its note.
    """
    _check_pair(fit, test)
    if fit.image_shape is None and mask is not None:
        raise InputError("a mask applies to a field of pixels")
    views = _Views(test, mask)
    images = _test_images(test, views)
    if scale is None:
        rti = fit.provenance.get("source") == "rti" or test.provenance.get("source") == "rti"
        stack = np.concatenate([images[key][views.pixels(key[0])] for key in images])
        scale = 1.0 if rti else display_scale(stack)
    if client is None:
        results = []
        with progress_bar(total=len(methods), desc="evaluate", unit="method") as bar:
            for name in methods:
                bar.set_description(f"evaluate: {name}")  # which method the time goes to
                results.append(_score_method(fit, test, name, scale, views, images))
                bar.update()
    else:
        from dask.delayed import delayed

        from core.cluster import compute_each

        # One task per method; each worker rebuilds the test images (the fields go along
        # pickled: a store by its path, a subset with its radiance).
        # hash=False: a key of its own each time, never one still being released from a
        # previous call with the same fields (Dask would then lose it mid-task)
        fields = client.scatter([fit, test], broadcast=True, hash=False)
        tasks = [delayed(_score_on_worker, pure=False)(*fields, name, scale, mask)
                 for name in methods]  # fmt: skip
        scored: dict[int, MethodResult] = dict(compute_each(client, tasks, what="evaluate"))
        results = [scored[i] for i in range(len(methods))]
    s_count, t_test, _ = test.shape
    names = (
        tuple(test_names) if test_names is not None else tuple(f"light {q}" for q in range(t_test))
    )
    return Evaluation(
        field=str(fit.path),
        test=str(test.path),
        fit_lights=fit.shape[1],
        test_lights=t_test,
        cameras=s_count,
        scale=float(scale),
        test_names=names,
        methods=tuple(results),
        sample=sample,
    )
