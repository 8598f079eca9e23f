"""Held-out-light evaluation: every method predicts lights it never saw, as the RTI literature does.

A field is split into the lights a method may use (the fit lights) and the lights it must
predict (the test lights), or a second capture of other lights is given as the test. Each
method (:mod:`render.light_prediction`) predicts every test image from the fit lights alone,
and :mod:`processing.image_quality` scores it against the measured image: PSNR and SSIM of the
8-bit sRGB images, mean CIEDE2000, relative RMSE in linear light. Means are over the test
images; the mean PSNR is that of the mean squared error over them (relight's protocol: a
single exactly predicted image would make a mean of PSNRs infinite).

Images: a field of pixels is its one view; a field of points is splatted into each captured
camera's image (:func:`render.splat.plan_splats`), the metrics taken over the pixels it covers.
A view of more than :data:`EVALUATE_PIXELS` pixels (a DSLR capture) is scored on tiles spread
evenly over it (:func:`pixel_sample`), read from the store band by band: the scores say so
(:meth:`PixelSample.note`), and the memory is that of the tiles whatever the view's size.

Display range of the 8-bit metrics: an RTI capture's values are its images' decoded 8-bit
values, so white is 1; a simulated (HDR) field is scaled so that the test images'
99.5th percentile is white (:func:`processing.image_quality.display_scale`), once for all
methods.

Splits of one capture (``split``): :mod:`render.light_splits`.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError, RigError
from core.field_store import ReflectanceField, is_field_store
from core.image_io import TransferChoice
from core.progress import progress_bar
from processing.image_quality import (
    SSIM_WINDOW,
    ImageQuality,
    clipped_srgb_8bit,
    display_scale,
    image_quality,
)
from processing.rti import import_rti
from render.field_view import FieldView
from render.light_prediction import PREDICTORS, make_predictor, training_summary
from render.light_splits import split_lights
from render.prediction_methods import LightPredictor
from render.rung_choice import choose_light_rung

__all__ = [
    "CHOICE_SAMPLES",
    "CHOSEN",
    "EVALUATE_PIXELS",
    "TILE_SIDE",
    "Evaluation",
    "HeldOut",
    "HeldOutError",
    "MethodResult",
    "PixelSample",
    "against_test",
    "evaluate",
    "held_out_errors",
    "held_out_split",
    "pixel_sample",
    "test_field_from_lp",
]

#: The product's own choice as a method: ``rig relight --lights``'s automatic rung (with
#: ``-fast``: the quick rungs only), chosen on the fit lights for the test lights' directions.
CHOSEN = ("auto", "auto-fast")
#: Samples of a field of points :func:`held_out_errors` predicts (a random subset).
CHOICE_SAMPLES = 3000
#: Pixels of a view :func:`evaluate` scores at most: a larger view (a DSLR capture of 24
#: megapixels) is scored on :data:`TILE_SIDE` tiles spread evenly over it
#: (:func:`pixel_sample`), so that every method's fit and predictions of every test image stay
#: within memory (at 60 lights a 24-megapixel view is 17 GB of float32; its predictions under
#: 30 test lights 8.6 GB more). Measured with 60 lights (bench.scale_rti): the learned rung
#: alone peaked at 3.7 GB on 262,144 pixels and 1.2 GB on 131,072, every method together at
#: 5.3 GB on 262,144. 131,072 pixels x 30 test images is 3.9 million scored pixels.
EVALUATE_PIXELS = 8 * 128 * 128
#: Side (pixels) of the tiles a large view is scored on: square, so SSIM's 11 x 11 windows see
#: the neighbourhoods the view has.
TILE_SIDE = 128


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


def test_field_from_lp(
    lp_path: str | Path, *, transfer: TransferChoice = "auto", sample: PixelSample | None = None
) -> ReflectanceField:
    """The test images of an ``.lp`` file (and its images) as a field held in memory.

    ``transfer`` decodes them as :func:`processing.rti.import_rti` does the field's; with a
    ``sample``, only its tiles are kept (the import streams, the tiles are read from it).
    """
    with tempfile.TemporaryDirectory(prefix="rig-evaluate-") as scratch:
        store = import_rti(lp_path, Path(scratch) / "test.zarr", progress=False, transfer=transfer)
        # In memory: the temporary store goes.
        return store.subset() if sample is None else sample.take(store)


@dataclass(frozen=True)
class PixelSample:
    """The tiles of a large view that :func:`evaluate` scores (:func:`pixel_sample`).

    Attributes
    ----------
    view : (height, width) of the whole view, pixels
    side : int, the tiles' side, pixels
    columns : int, tiles per row (of the view's grid of tiles, and of the mosaic scored)
    origins : tuple of (row, column), each tile's top-left pixel in the view, row by row
    """

    view: tuple[int, int]
    side: int
    columns: int
    origins: tuple[tuple[int, int], ...]

    @property
    def pixels(self) -> int:
        """Pixels of the tiles (those scored: less the seams, see :meth:`mask`)."""
        return len(self.origins) * self.side * self.side

    def note(self) -> str:
        """What was scored, in a sentence for the table and the JSON."""
        height, width = self.view
        rows = len(self.origins) // self.columns
        share = self.pixels / (height * width)
        return (
            f"pixels: scored on {len(self.origins)} tiles of {self.side} x {self.side} (a "
            f"{self.columns} x {rows} grid spread evenly over the {width} x {height} view; "
            f"{self.pixels:,} of its {height * width:,} pixels, {share:.1%}), the "
            f"{_SEAM} pixels beside each seam between two tiles left out"
        )

    def take(self, field: ReflectanceField) -> ReflectanceField:
        """The tiles of ``field`` (this view) side by side, held in memory (every light).

        Raises InputError when ``field`` is not a field of pixels of this view's size.
        """
        if field.image_shape != self.view:
            raise InputError(
                f"{field.path}: images {field.image_shape}, the tiles are of a view of {self.view}"
            )
        return field.tiles(self.origins, self.side, self.columns)

    def mask(self, mask: NDArray[np.bool_] | None) -> NDArray[np.bool_]:
        """The pixels of the mosaic that count: ``mask`` (H, W) of the view on the tiles.

        Less :data:`_SEAM` pixels on each side of every seam between two tiles: an SSIM window
        there would mix two places of the view (the view's own border is left out by SSIM
        itself, as for a whole view).
        """
        rows = len(self.origins) // self.columns
        out = np.ones((rows * self.side, self.columns * self.side), dtype=bool)
        if mask is not None:
            for index, (row, column) in enumerate(self.origins):
                y, x = index // self.columns * self.side, index % self.columns * self.side
                out[y : y + self.side, x : x + self.side] = mask[
                    row : row + self.side, column : column + self.side
                ]
        for seam in range(1, self.columns):
            out[:, seam * self.side - _SEAM : seam * self.side + _SEAM] = False
        for seam in range(1, rows):
            out[seam * self.side - _SEAM : seam * self.side + _SEAM] = False
        return out

    def to_json(self) -> dict[str, Any]:
        """The tiles, for the evaluation's JSON."""
        return {
            "note": self.note(),
            "view": list(self.view),
            "side": self.side,
            "columns": self.columns,
            "origins": [list(o) for o in self.origins],
        }


#: Pixels left out beside each seam of a mosaic of tiles: half an SSIM window.
_SEAM = SSIM_WINDOW // 2


def pixel_sample(
    image_shape: tuple[int, int] | None,
    max_pixels: int | None = None,
    side: int | None = None,
) -> PixelSample | None:
    """The tiles a view of ``image_shape`` is scored on, or None when it is scored whole.

    A view of more than ``max_pixels`` pixels is scored on up to ``max_pixels // side^2``
    tiles (at least one) of ``side`` x ``side`` pixels, in the grid of the most such tiles
    whose aspect is nearest the view's, each cell holding one tile at its centre: evenly
    spread, the same for every method and every test image, and reproducible (no random
    draw).

    Parameters
    ----------
    image_shape : (height, width), or None (a field of points: scored whole)
    max_pixels : int, the most pixels scored whole (default :data:`EVALUATE_PIXELS`)
    side : int, the tiles' side (default :data:`TILE_SIDE`; smaller when the view or
        ``max_pixels`` is)
    """
    max_pixels = EVALUATE_PIXELS if max_pixels is None else max_pixels
    side = min(TILE_SIDE if side is None else side, math.isqrt(max_pixels))
    if image_shape is None or image_shape[0] * image_shape[1] <= max_pixels:
        return None
    height, width = image_shape
    count = max(1, max_pixels // (side * side))
    aspect = width / height
    columns = max(
        range(1, count + 1), key=lambda c: (count // c * c, -abs(math.log(c * c / count / aspect)))
    )
    rows = count // columns
    side = min(side, height // rows, width // columns)
    if side < SSIM_WINDOW:
        raise InputError(
            f"{max_pixels} pixels in {rows} x {columns} tiles of a {width} x {height} view "
            f"leave tiles under {SSIM_WINDOW} pixels; score more pixels"
        )

    def starts(cells: int, length: int) -> list[int]:
        return [min(max(0, round((c + 0.5) * length / cells - side / 2)), length - side)
                for c in range(cells)]  # fmt: skip

    origins = tuple((r, c) for r in starts(rows, height) for c in starts(columns, width))
    return PixelSample(view=(height, width), side=side, columns=columns, origins=origins)


@dataclass(frozen=True)
class HeldOut:
    """What :func:`evaluate` scores: the fit lights, the test lights, the pixels that count.

    Attributes
    ----------
    fit, test : ReflectanceField, the same view(s) under the fit and the test lights (the
        tiles of ``sample`` when a large view is sampled)
    mask : ndarray (H, W) of bool or None, the pixels that count (of ``fit``'s images)
    sample : PixelSample or None, the tiles scored (None: every pixel)
    test_lights : ndarray of int or None, the field's lights held out (a split)
    """

    fit: ReflectanceField
    test: ReflectanceField
    mask: NDArray[np.bool_] | None
    sample: PixelSample | None
    test_lights: NDArray[np.int64] | None = None


def held_out_split(
    field: ReflectanceField,
    split: str,
    mask: NDArray[np.bool_] | None = None,
    *,
    max_pixels: int | None = None,
    side: int | None = None,
) -> HeldOut:
    """A split of ``field``'s own lights (:func:`render.light_splits.split_lights`), in memory.

    A view of more than ``max_pixels`` pixels is read as the ``side`` tiles of
    :func:`pixel_sample` (band by band of the store: never whole), then split.
    """
    fit_index, test_index = split_lights(field, split)
    sample = pixel_sample(field.image_shape, max_pixels, side)
    base = field if sample is None else sample.take(field)
    return HeldOut(
        fit=base.subset(lights=fit_index),
        test=base.subset(lights=test_index),
        mask=mask if sample is None else sample.mask(mask),
        sample=sample,
        test_lights=test_index,
    )


def against_test(
    field: ReflectanceField,
    test: str | Path,
    mask: NDArray[np.bool_] | None = None,
    *,
    transfer: TransferChoice = "auto",
    max_pixels: int | None = None,
    side: int | None = None,
) -> HeldOut:
    """``field`` against the test lights of an ``.lp`` capture or a field store of its view.

    A view of more than ``max_pixels`` pixels is scored on the ``side`` tiles of
    :func:`pixel_sample`, of both.

    Raises
    ------
    InputError
        ``test`` is neither an ``.lp`` file nor a field store.
    """
    where = Path(test)
    sample = pixel_sample(field.image_shape, max_pixels, side)
    if is_field_store(where):
        opened = ReflectanceField.open(where)
        tested = opened if sample is None else sample.take(opened)
    elif where.suffix.lower() == ".lp":
        tested = test_field_from_lp(where, transfer=transfer, sample=sample)
    else:
        raise InputError(f"{where}: give an .lp file or a field store")
    return HeldOut(
        fit=field if sample is None else sample.take(field),
        test=tested,
        mask=mask if sample is None else sample.mask(mask),
        sample=sample,
    )


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
    progress: bool = False,
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
    progress : bool, a bar over the methods
    client : distributed.Client, optional; one Dask task per method on its cluster (the
        scores are the same; the times are the workers')
    sample : PixelSample, optional, the tiles of a large view ``fit`` and ``test`` hold
        (:func:`held_out_split`, :func:`against_test`): recorded and said with the scores

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
        with progress_bar(total=len(methods), desc="evaluate", unit="method", show=progress) as bar:
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
        scored: dict[int, MethodResult] = dict(
            compute_each(client, tasks, progress=progress, what="evaluate")
        )
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
