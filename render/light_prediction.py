"""A field's radiance under lights it did not measure: every method, behind one interface.

Held-out evaluation (:mod:`render.evaluation`) and ``rig relight --lights`` ask the same
question of a method: what does camera ``s`` see under a directional light of unit irradiance
from direction ``d``? A :class:`LightPredictor` answers it for many directions at once.

==========================  ===============================================================
method                      what predicts the unmeasured light
==========================  ===============================================================
``nearest``                 the image of the nearest measured light
``barycentric``             the three measured lights around it (spherical triangulation)
``rbf``                     every measured light, Gaussian-weighted by distance and
                            normalised, as the RTI tools' ``rbf`` (relight, OpenLIME):
                            w_i = exp(-|d - l_i|^2 / sigma^2), weights below 0.001 of the
                            total dropped; sigma chosen by leave-one-light-out error
``ptm``, ``hsh2``, ``hsh3``  a linear basis per sample fitted by least squares to linear
                            radiance (PTM: 6 terms; HSH of order 2 and 3: 4 and 9 terms)
``ptm-8bit`` ...            the same bases fitted, as RTI tools fit them, to the 8-bit
                            sRGB values of the images, and decoded back to linear light
``lambert``,                the project's per-sample models (:mod:`processing.sample_models`)
``lambert+ggx``             with their shadow marks
``<model>+residual``        the model, plus the ``barycentric`` interpolation of what it
                            misses at the measured lights: what the model carries
                            generalises (the shape of a lobe between lights), the residual
                            carries the rest (measured on the bundled RTI capture, the
                            barycentric residual beat the ``rbf`` one by 1.6 dB)
``adaptive``                per sample, ``barycentric`` and ``lambert+ggx+residual`` mixed
                            by their leave-one-light-out errors (each weighted by the other's
                            share of the error): where the model explains a sample its
                            residual helps, where it does not (cast shadows, grazing light)
                            plain interpolation is kept
``light-stage+lambert+ggx``  the model plus its residual at the nearest measured light:
                            under an environment, the light-stage sum corrected by the model
``learned``,                a code per sample and one small decoder shared by the object,
``learned+residual``        trained on the capture (:mod:`processing.learned_rti`, the class
                            of neural RTI; about a minute of training on 2 cores), alone and
                            with the ``barycentric`` residual
==========================  ===============================================================

Fitted predictions are bounded by what the data allow: at least 0 and at most
:func:`bound_factor` times the sample's brightest measured value (per channel). A lobe
fitted to a few noisy values can otherwise predict a pixel tens of times brighter than any
image shows; but between sparse lights a real highlight does outshine every measured value.
The factor is :data:`BOUND` up to :data:`BOUND_SPACING_DEG` of mean light spacing and grows
with the square of the spacing beyond. Measured with :func:`render.evaluation.held_out_errors`
(lambert+ggx, every other light held out): on the bundled RTI capture (fit lights 9.4 degrees
apart) a bound of 1.25 gave 19.0 % against 36 % unbounded and 41 % at 10; on the simulated
glossy sphere with 8 fit lights (38 degrees apart) 1.25 gave 45 %, 10 gave 3.5 % and no
bound 2.3 %.

Directions are unit vectors in the rig frame. The bases take the light in the camera frame
for a field of pixels (the RTI convention) and in the rig frame for a field of points (its
lights are the rig's upper hemisphere, where the hemispherical harmonics are defined).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from dataclasses import field as default
from typing import Literal, Protocol, get_args

import numpy as np
from numpy.typing import NDArray

from core.camera_model import rig_to_camera
from core.colour import linear_to_srgb, srgb_to_linear
from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet
from core.progress import progress_bar
from processing.interpolation import InterpolationMethod, interpolation_weights, mean_spacing_deg
from processing.learned_rti import LearnedRTI
from processing.learned_rti_training import TrainingSettings, train_learned_rti
from processing.sample_model_store import models_for_field
from processing.sample_models import (
    BASIS_MODELS,
    SampleModels,
    choose_model,
    evaluate_basis,
    fit_sample_models,
)
from processing.sample_models.bases import fit_basis
from processing.sample_models.fits import BasisModelName
from render.model_relight import prepare_lighting, relight_models

__all__ = [
    "BOUND",
    "BOUND_SPACING_DEG",
    "PREDICTORS",
    "RBF_DROP",
    "RBF_SIGMAS",
    "LightPredictor",
    "MixturePredictor",
    "PredictorName",
    "bound_factor",
    "choose_rbf_sigma",
    "eight_bit_levels",
    "environment_radiance",
    "fit_basis_8bit",
    "leave_one_out_barycentric",
    "make_predictor",
    "rbf_weights",
    "training_summary",
]

PredictorName = Literal[
    "nearest",
    "barycentric",
    "rbf",
    "ptm",
    "hsh2",
    "hsh3",
    "ptm-8bit",
    "hsh2-8bit",
    "hsh3-8bit",
    "lambert",
    "lambert+ggx",
    "lambert+residual",
    "lambert+ggx+residual",
    "adaptive",
    "learned",
    "learned+residual",
    "light-stage+lambert+ggx",
]
#: Every method, the baselines first.
PREDICTORS: tuple[PredictorName, ...] = get_args(PredictorName)

#: Fitted predictions are at most this times a sample's brightest measured value (dense
#: lights; see :func:`bound_factor`).
BOUND = 1.25
#: Mean light spacing (degrees) up to which :data:`BOUND` holds.
BOUND_SPACING_DEG = 10.0

#: Widths sigma the ``rbf`` kernel is chosen among (chord distance between unit vectors; the
#: RTI tools' default is 0.125 for about 100 lights).
RBF_SIGMAS = tuple(float(s) for s in np.geomspace(0.03, 1.0, 19))
#: Normalised weights below this are dropped (and the rest renormalised), as the RTI tools do.
RBF_DROP = 1e-3
#: Samples the leave-one-light-out choice of sigma reads (a random subset of a big field).
SIGMA_SAMPLES = 4096
#: Bytes of predictions :func:`environment_radiance` holds at once (lights x samples x RGB).
BATCH_BYTES = 256 * 2**20


class LightPredictor(Protocol):
    """Radiance a camera sees under directional lights of unit irradiance."""

    @property
    def name(self) -> str:
        """The method's name (a :data:`PREDICTORS` entry)."""
        ...

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        """Radiance (Q, P, 3), float32, seen by ``camera`` under Q lights (Q, 3).

        Each light is directional, of unit irradiance.
        """
        ...


# --- the RTI tools' rbf ---------------------------------------------------------------------


def rbf_weights(
    measured: NDArray[np.floating], queries: NDArray[np.floating], sigma: float
) -> NDArray[np.float64]:
    """Normalised Gaussian weights (Q, T) of the measured directions for each query.

    w_i = exp(-|q - l_i|^2 / sigma^2), normalised to sum 1, weights below :data:`RBF_DROP`
    dropped and the rest renormalised (relight's ``lightWeightsRbf``). Taken relative to the
    nearest direction, so no row underflows to all zeros however small sigma is.
    """
    if not sigma > 0:
        raise InputError(f"the rbf width sigma must be positive, got {sigma}")
    m = np.asarray(measured, dtype=np.float64)
    q = np.asarray(queries, dtype=np.float64)
    squared = np.sum((q[:, None, :] - m[None, :, :]) ** 2, axis=2)
    return _normalised(np.exp(-(squared - squared.min(axis=1, keepdims=True)) / sigma**2))


def _normalised(kernel: NDArray[np.float64]) -> NDArray[np.float64]:
    weights = kernel / kernel.sum(axis=1, keepdims=True)
    weights[weights < RBF_DROP] = 0.0
    return weights / weights.sum(axis=1, keepdims=True)


def choose_rbf_sigma(
    directions: NDArray[np.floating],
    values: NDArray[np.floating],
    sigmas: tuple[float, ...] = RBF_SIGMAS,
) -> float:
    """The sigma of :data:`RBF_SIGMAS` whose leave-one-light-out prediction errs least.

    Parameters
    ----------
    directions : ndarray, shape (T, 3), the measured lights
    values : ndarray, shape (T, N, 3) or (T, N), what is interpolated (a subset of samples)

    Returns
    -------
    float, the chosen sigma (light j predicted from the others: its own weight removed)
    """
    d = np.asarray(directions, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).reshape(len(d), -1)
    squared = np.sum((d[:, None, :] - d[None, :, :]) ** 2, axis=2)
    np.fill_diagonal(squared, np.inf)
    best, best_error = sigmas[0], np.inf
    for sigma in sigmas:
        kernel = np.exp(-(squared - squared.min(axis=1, keepdims=True)) / sigma**2)
        error = float(np.sum((_normalised(kernel) @ v - v) ** 2))
        if error < best_error:
            best, best_error = sigma, error
    return best


def _sigma_subset(field: ReflectanceField, seed: int = 0) -> NDArray[np.float32]:
    """(T, N, 3) radiance of up to :data:`SIGMA_SAMPLES` visible (camera, sample) pairs."""
    rng = np.random.default_rng(seed)
    s_count = field.shape[0]
    per_camera = max(1, SIGMA_SAMPLES // s_count)
    parts = []
    for s in range(s_count):
        seen = np.flatnonzero(field.visibility[s])
        if seen.size:
            pick = rng.choice(seen, size=min(per_camera, seen.size), replace=False)
            parts.append(field.camera_slab(s)[:, np.sort(pick)])
    if not parts:
        raise InputError(f"{field.path}: no camera sees any sample")
    return np.concatenate(parts, axis=1)


# --- the predictors ------------------------------------------------------------------------


def eight_bit_levels(values: NDArray[np.floating], scale: float = 1.0) -> NDArray[np.float32]:
    """The 8-bit sRGB values, 0..255, that RTI tools fit: scaled, clipped, encoded, rounded.

    Parameters
    ----------
    values : ndarray, any shape, linear radiance
    scale : float, the linear value that 8-bit white stands for is 1 / ``scale``

    Returns
    -------
    ndarray, same shape, float32 whole numbers 0..255
    """
    encoded = linear_to_srgb(np.clip(np.asarray(values, dtype=np.float32) * scale, 0.0, 1.0))
    return np.round(encoded * 255.0).astype(np.float32)


def fit_basis_8bit(
    basis: BasisModelName,
    values: NDArray[np.floating],
    lights: NDArray[np.floating],
    scale: float = 1.0,
) -> NDArray[np.float32]:
    """Basis coefficients fitted as RTI tools fit them: to the 8-bit sRGB values, 0..255.

    The least-squares fit (:func:`processing.sample_models.bases.fit_basis`) of
    :func:`eight_bit_levels`; the ``-8bit`` predictors and :mod:`render.web_export` share it.

    Parameters
    ----------
    basis : {"ptm", "hsh2", "hsh3"}
    values : ndarray, shape (T, P, 3), linear radiance of P samples under T lights
    lights : ndarray, shape (T, 3), the lights in the frame the basis takes (a pixel field's
        camera frame)
    scale : float, the linear value that 8-bit white stands for is 1 / ``scale``

    Returns
    -------
    ndarray, shape (P, B, 3), float32: coefficients in 8-bit units (a basis sum of 255 is
    white)
    """
    levels = eight_bit_levels(values, scale)
    return fit_basis(basis, levels, np.asarray(lights, dtype=np.float64)).coefficients


def bound_factor(light_directions: NDArray[np.floating]) -> float:
    """How many times its brightest measured value a sample may be predicted (see the module).

    :data:`BOUND` x max(1, (spacing / :data:`BOUND_SPACING_DEG`) ^ 2), ``spacing`` the mean
    angle between neighbouring measured lights.
    """
    spacing = mean_spacing_deg(light_directions) if len(light_directions) > 1 else 180.0
    return BOUND * max(1.0, (spacing / BOUND_SPACING_DEG) ** 2)


def _bounded(
    field: ReflectanceField, camera: int, values: NDArray[np.floating]
) -> NDArray[np.float32]:
    """``values`` (Q, P, 3) clipped to [0, :func:`bound_factor` x the brightest measured]."""
    peak = field.camera_slab(camera).max(axis=0)
    limit = bound_factor(field.light_directions) * peak[None]
    return np.clip(values, 0.0, limit).astype(np.float32)


def _basis_frame_directions(
    field: ReflectanceField, camera: int, directions: NDArray[np.floating]
) -> NDArray[np.float64]:
    d = np.asarray(directions, dtype=np.float64)
    return rig_to_camera(d, field.cameras[camera]) if field.sample_kind == "pixels" else d


@dataclass
class _Interpolating:
    field: ReflectanceField
    name: str
    sigma: float | None = None

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        slab = self.field.camera_slab(camera)
        measured = self.field.light_directions
        if self.name == "rbf":
            assert self.sigma is not None
            weights = rbf_weights(measured, directions, self.sigma)
            return np.einsum("qt,tpc->qpc", weights, slab).astype(np.float32)
        method: InterpolationMethod = "nearest" if self.name == "nearest" else "barycentric"
        sparse = interpolation_weights(measured, directions, method, policy="clamp")
        return sparse.apply(slab).astype(np.float32)


@dataclass
class _Basis:
    field: ReflectanceField
    name: str
    basis: str
    eight_bit: bool
    scale: float
    _coefficients: dict[int, NDArray[np.float32]] = default(default_factory=dict)

    def _fit(self, camera: int) -> NDArray[np.float32]:
        if camera not in self._coefficients:
            slab = self.field.camera_slab(camera)
            lights = _basis_frame_directions(self.field, camera, self.field.light_directions)
            self._coefficients[camera] = (
                fit_basis_8bit(self.basis, slab, lights, self.scale)  # type: ignore[arg-type]
                if self.eight_bit
                else fit_basis(self.basis, slab, lights).coefficients  # type: ignore[arg-type]
            )
        return self._coefficients[camera]

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        coefficients = self._fit(camera)
        design = evaluate_basis(self.basis, _basis_frame_directions(self.field, camera, directions))
        values = np.einsum("qb,pbc->qpc", design, coefficients)
        if self.eight_bit:
            values = srgb_to_linear(np.clip(values / 255.0, 0.0, 1.0)) / self.scale
        return _bounded(self.field, camera, values)


@dataclass
class _Model:
    field: ReflectanceField
    name: str
    models: SampleModels

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        d = np.asarray(directions, dtype=np.float64)
        choice = choose_model(self.models, candidates=[self.name])
        pinhole = self.field.cameras[camera]
        needed = self.field.visibility[camera]
        out = np.zeros((len(d), self.field.shape[2], 3), dtype=np.float32)
        for q in range(len(d)):
            lights = LightSet(directions=d[q : q + 1], rgb=np.ones((1, 3)))
            lighting = prepare_lighting(self.models, lights)
            out[q] = relight_models(self.models, choice, lighting, pinhole, needed=needed)
        return _bounded(self.field, camera, out)


@dataclass
class _Residual:
    """A model plus the interpolation of its residual at the measured lights.

    ``interpolation``: barycentric (``<model>+residual``), or nearest (``light-stage+<model>``:
    under an environment, the light-stage sum of the images plus the model's correction of the
    sum's discretisation, which is small where the light is broad and moves a sun's highlight
    where the model puts it).
    """

    field: ReflectanceField
    name: str
    base: LightPredictor
    interpolation: InterpolationMethod = "barycentric"
    _residual: dict[int, NDArray[np.float32]] = default(default_factory=dict)

    def _residual_of(self, camera: int) -> NDArray[np.float32]:
        if camera not in self._residual:
            fitted = self.base.predict(camera, self.field.light_directions)
            self._residual[camera] = self.field.camera_slab(camera) - fitted
        return self._residual[camera]

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        measured = self.field.light_directions
        weights = interpolation_weights(measured, directions, self.interpolation, policy="clamp")
        correction = weights.apply(self._residual_of(camera))
        return _bounded(self.field, camera, self.base.predict(camera, directions) + correction)


def leave_one_out_barycentric(
    directions: NDArray[np.floating], values: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Each measured light's values predicted barycentrically from the others: (T, ...).

    The honest leave-one-light-out prediction: the triangulation is rebuilt without the
    light (T triangulations of T - 1 directions).
    """
    d = np.asarray(directions, dtype=np.float64)
    v = np.asarray(values)
    out = np.zeros(v.shape, dtype=np.float64)
    for j in range(len(d)):
        keep = np.r_[0:j, j + 1 : len(d)]
        weights = interpolation_weights(d[keep], d[j : j + 1], "barycentric", policy="clamp")
        out[j] = weights.apply(v[keep])[0]
    return out


@dataclass
class _Adaptive:
    """Barycentric and model + residual, mixed per sample by their leave-one-light-out errors."""

    field: ReflectanceField
    name: str
    residual: _Residual
    _share: dict[int, NDArray[np.float64]] = default(default_factory=dict)

    def share(self, camera: int) -> NDArray[np.float64]:
        """Weight (P,) of model + residual per sample: the barycentric share of the error."""
        if camera not in self._share:
            measured = self.field.light_directions
            data = self.field.camera_slab(camera)
            residual = self.residual._residual_of(camera)
            fitted = data - residual
            alone = leave_one_out_barycentric(measured, data)
            helped = fitted + leave_one_out_barycentric(measured, residual)
            error_alone = np.sum((alone - data) ** 2, axis=(0, 2))
            error_helped = np.sum((helped - data) ** 2, axis=(0, 2))
            total = error_alone + error_helped
            self._share[camera] = np.divide(
                error_alone, total, out=np.full_like(total, 0.5), where=total > 0
            )
        return self._share[camera]

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        measured = self.field.light_directions
        weights = interpolation_weights(measured, directions, "barycentric", policy="clamp")
        alone = weights.apply(self.field.camera_slab(camera))
        helped = self.residual.predict(camera, directions)
        share = self.share(camera)[None, :, None]
        return _bounded(self.field, camera, share * helped + (1.0 - share) * alone)


#: Trained networks by field (while it lives), so ``learned`` and ``learned+residual`` of one
#: field train once.
_TrainedKey = tuple[int, TrainingSettings]
_TRAINED: weakref.WeakKeyDictionary[ReflectanceField, dict[_TrainedKey, LearnedRTI]]
_TRAINED = weakref.WeakKeyDictionary()


#: Model fits of in-memory fields (while they live), by the models fitted.
_FITTED: weakref.WeakKeyDictionary[ReflectanceField, dict[tuple[str, ...], SampleModels]]
_FITTED = weakref.WeakKeyDictionary()


@dataclass
class _Learned:
    """The learned model of a field.

    One network for a field of points (lights in the rig frame, every camera's samples), one
    per camera for a field of pixels (lights in its frame).
    """

    field: ReflectanceField
    name: str
    settings: TrainingSettings
    progress: bool
    _codes: dict[int, NDArray[np.float32]] = default(default_factory=dict)

    def _train(self, cameras: list[int], lights: NDArray[np.float64]) -> LearnedRTI:
        # At most the samples training reads, drawn evenly from the cameras: a large field of
        # points is never gathered whole.
        rng = np.random.default_rng(self.settings.seed)
        share = -(-self.settings.max_samples // len(cameras))
        parts = []
        for s in cameras:
            seen = np.flatnonzero(self.field.visibility[s])
            if seen.size > share:
                seen = np.sort(rng.choice(seen, size=share, replace=False))
            parts.append(self.field.camera_slab(s)[:, seen])
        values = np.concatenate(parts, axis=1)
        if values.shape[1] == 0:
            raise InputError(f"{self.field.path}: no camera sees any sample; nothing to learn")
        bar = progress_bar(desc="training", unit="step", show=self.progress)

        def advance(step: int, planned: int) -> None:
            # The steps foreseen change as training learns its pace (a time budget).
            if bar.total != planned:
                bar.set_total(planned)
            bar.update(step - bar.n)

        try:
            return train_learned_rti(values, lights, self.settings, advance)
        finally:
            bar.close()

    def model(self, camera: int) -> LearnedRTI:
        """The model that predicts ``camera``'s view (trained on first use)."""
        key = (camera if self.field.sample_kind == "pixels" else -1, self.settings)
        trained = _TRAINED.setdefault(self.field, {})
        if key not in trained:
            cameras = [camera] if key[0] >= 0 else list(range(self.field.shape[0]))
            lights = _basis_frame_directions(self.field, camera, self.field.light_directions)
            trained[key] = self._train(cameras, lights)
        return trained[key]

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        model = self.model(camera)
        seen = self.field.visibility[camera]
        if camera not in self._codes:
            self._codes[camera] = model.encode(self.field.camera_slab(camera)[:, seen])
        frame = _basis_frame_directions(self.field, camera, directions)
        out = np.zeros((len(frame), self.field.shape[2], 3), dtype=np.float32)
        out[:, seen] = model.decode(self._codes[camera], frame)
        return _bounded(self.field, camera, out)


@dataclass
class MixturePredictor:
    """Several predictors of one field of pixels, mixed per pixel by fixed weights.

    Attributes
    ----------
    field : ReflectanceField
    members : list of LightPredictor, M of them
    weights : ndarray, shape (M, P), float32, each pixel's weights (summing to 1)
    name : str
    """

    field: ReflectanceField
    members: list[LightPredictor]
    weights: NDArray[np.float32]
    name: str = "mixture"

    def __post_init__(self) -> None:
        expected = (len(self.members), self.field.shape[2])
        if self.weights.shape != expected:
            raise InputError(f"mixture weights must have shape {expected}, got "
                             f"{self.weights.shape}")  # fmt: skip

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        """Radiance (Q, P, 3): the members' predictions mixed per pixel."""
        out = np.zeros((len(np.atleast_2d(directions)), self.field.shape[2], 3), np.float32)
        for member, weight in zip(self.members, self.weights, strict=True):
            out += weight[None, :, None] * member.predict(camera, directions)
        return out


def training_summary(
    predictor: LightPredictor,
) -> tuple[str, list[dict[str, float | str | None]]]:
    """How a learned predictor trained: a short note and its curve (empty for other methods).

    Returns
    -------
    note : str, passes, seconds and device of the model(s) trained so far
    curve : list of dict, per pass: phase, epoch, seconds, train_error, validation_error
        (None where no lights were held out)
    """
    learned = predictor if isinstance(predictor, _Learned) else getattr(predictor, "base", None)
    if not isinstance(learned, _Learned):
        return "", []
    trained = _TRAINED.get(learned.field, {})
    models = [m for (_, settings), m in trained.items() if settings == learned.settings]
    if not models:
        return "", []
    model = models[0]
    note = (
        f"trained {model.epochs} passes ({model.steps} steps) in {model.seconds:.0f} s on "
        f"{model.device}"
    )
    curve: list[dict[str, float | str | None]] = [
        {"phase": r.phase, "epoch": r.epoch, "seconds": r.seconds, "train_error": r.train_error,
         "validation_error": None if math.isnan(r.validation_error) else r.validation_error}
        for r in model.history
    ]  # fmt: skip
    return note, curve


def environment_radiance(
    predictor: LightPredictor, camera: int, lights: LightSet, samples: int
) -> NDArray[np.float32]:
    """Radiance (P, 3), float32, of ``camera``'s samples under many lights at once.

    The sum over the lights of their rgb (radiance x sr) times the predicted radiance under a
    directional light of unit irradiance from each direction. The models shade every light in
    one pass, and what is linear in the measured images (interpolation, residuals, bases)
    sums the weights first; any other predictor (the learned rung) predicts the lights in
    batches within :data:`BATCH_BYTES`. Unlike :meth:`LightPredictor.predict` the sum is not
    bounded per light.

    Parameters
    ----------
    predictor : LightPredictor (from :func:`make_predictor`)
    camera : int
    lights : LightSet, directions (K, 3) in the rig frame, rgb (K, 3)
    samples : int, P
    """
    rgb = np.asarray(lights.rgb, dtype=np.float64)
    if isinstance(predictor, _Model):
        choice = choose_model(predictor.models, candidates=[predictor.name])
        lighting = prepare_lighting(predictor.models, lights)
        pinhole = predictor.field.cameras[camera]
        needed = predictor.field.visibility[camera]
        return relight_models(predictor.models, choice, lighting, pinhole, needed=needed)
    if isinstance(predictor, _Residual):
        base = environment_radiance(predictor.base, camera, lights, samples)
        residual = predictor._residual_of(camera)
        summed = _summed_interpolation(predictor.field, lights, residual, predictor.interpolation)
        return (base + summed).astype(np.float32)
    if isinstance(predictor, MixturePredictor):
        mixed = np.zeros((samples, 3), dtype=np.float64)
        for member, weight in zip(predictor.members, predictor.weights, strict=True):
            mixed += weight[:, None] * environment_radiance(member, camera, lights, samples)
        return mixed.astype(np.float32)
    if isinstance(predictor, _Adaptive):
        share = predictor.share(camera)[:, None]
        helped = environment_radiance(predictor.residual, camera, lights, samples)
        slab = predictor.field.camera_slab(camera)
        alone = _summed_interpolation(predictor.field, lights, slab, "barycentric")
        return (share * helped + (1.0 - share) * alone).astype(np.float32)
    out = np.zeros((samples, 3), dtype=np.float64)
    batch = max(1, min(len(rgb), BATCH_BYTES // max(1, 12 * samples)))
    for start in range(0, len(rgb), batch):
        predicted = predictor.predict(camera, lights.directions[start : start + batch])
        out += np.einsum("qc,qpc->pc", rgb[start : start + batch], predicted)
    return out.astype(np.float32)


def _summed_interpolation(
    field: ReflectanceField,
    lights: LightSet,
    values: NDArray[np.floating],
    method: InterpolationMethod,
) -> NDArray[np.float64]:
    """Sum over ``lights`` of rgb x the interpolation of ``values`` (T, P, 3) by ``method``."""
    sparse = interpolation_weights(
        field.light_directions, lights.directions, method, policy="clamp"
    )
    per_light = np.zeros((len(field.light_directions), 3), dtype=np.float64)
    rgb = np.asarray(lights.rgb, dtype=np.float64)
    for k in range(sparse.indices.shape[1]):
        for c in range(3):
            per_light[:, c] += np.bincount(
                sparse.indices[:, k], sparse.weights[:, k] * rgb[:, c], len(per_light)
            )
    return np.einsum("tc,tpc->pc", per_light, np.asarray(values, dtype=np.float64))


def _fitted_models(
    field: ReflectanceField, names: list[str], models: SampleModels | None, progress: bool
) -> SampleModels:
    if models is not None and all(n in models.fits for n in names):
        return models
    if field.radiance_digest is not None:  # a store: its fit is saved beside it and reused
        return models_for_field(field, models=names, progress=progress)
    # Held in memory (a split's subset): nothing saved, but kept while the subset lives, so the
    # rungs built on one model (the model, its residual, the adaptive mixture) fit it once.
    fitted = _FITTED.setdefault(field, {})
    key = tuple(sorted(names))
    if key not in fitted:
        fitted[key] = fit_sample_models(field, names, progress=progress)
    return fitted[key]


def make_predictor(
    field: ReflectanceField,
    name: str,
    *,
    models: SampleModels | None = None,
    scale: float = 1.0,
    sigma: float | None = None,
    learned: TrainingSettings | None = None,
    progress: bool = False,
) -> LightPredictor:
    """The predictor ``name`` (a :data:`PREDICTORS` entry) of ``field``.

    Parameters
    ----------
    field : ReflectanceField, the measured lights to predict from
    name : str
    models : SampleModels, optional, a fit of ``field`` to use (else fitted, or read from
        beside a store)
    scale : float, linear value that 8-bit white stands for (the ``-8bit`` bases)
    sigma : float, optional, the ``rbf`` width (default: chosen by leave-one-light-out)
    learned : TrainingSettings, optional, how the ``learned`` model trains (default settings)
    progress : bool, progress bars while fitting

    Raises
    ------
    InputError
        An unknown name, or a basis for a field it cannot be fitted to (too few lights).
    """
    if name not in PREDICTORS:
        raise InputError(f"unknown method {name!r}; use one of {', '.join(PREDICTORS)}")
    if name in ("nearest", "barycentric"):
        return _Interpolating(field, name)
    if name == "rbf":
        chosen = (
            choose_rbf_sigma(field.light_directions, _sigma_subset(field))
            if sigma is None
            else sigma
        )
        return _Interpolating(field, name, chosen)
    if name.removesuffix("+residual") == "learned":
        network = _Learned(field, "learned", learned or TrainingSettings(), progress)
        return _Residual(field, name, network) if name.endswith("+residual") else network
    basis = name.removesuffix("-8bit")
    if basis in BASIS_MODELS:
        return _Basis(field, name, basis, name.endswith("-8bit"), scale)
    if name.startswith("light-stage+"):
        model = name.removeprefix("light-stage+")
        fitted = _fitted_models(field, [model], models, progress)
        return _Residual(field, name, _Model(field, model, fitted), interpolation="nearest")
    model = "lambert+ggx" if name == "adaptive" else name.removesuffix("+residual")
    fitted = _fitted_models(field, [model], models, progress)
    base = _Model(field, model, fitted)
    if name == "adaptive":
        return _Adaptive(field, name, _Residual(field, "lambert+ggx+residual", base))
    return _Residual(field, name, base) if name.endswith("+residual") else base
