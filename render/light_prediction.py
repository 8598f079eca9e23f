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
``relief``                  ``lambert+ggx+residual`` whose cast shadows between measured
                            lights come from a height field fitted to the measured shadows
                            (:mod:`processing.relief_shadows`) where the lights around
                            disagree, instead of a fraction of each: pixel fields
``light-stage+lambert+ggx``  the model plus its residual at the nearest measured light:
                            under an environment, the light-stage sum corrected by the model
``learned``,                a code per sample and one small decoder shared by the object,
``learned+residual``        trained on the capture (:mod:`processing.learned_rti`, the class
                            of neural RTI; about a minute of training on 2 cores), alone and
                            with the ``barycentric`` residual
``learned+relief``,         the network told each light's visibility at each pixel by
``learned+relief+residual``  ``relief`` (the measured marks at the measured lights): it
                            learns each pixel lit and in shadow, the relief says where a
                            cast shadow falls between the lights: pixel fields
==========================  ===============================================================

Each method's predictor is :mod:`render.prediction_methods`'s, the RTI tools' fits
:mod:`render.rti_fits`'s; here are the names (:data:`PREDICTORS`, kept in
:mod:`core.predictor_names` so that ``rig``'s parsers offer them without importing the
library), :func:`make_predictor`, the sum of a predictor under many lights
(:func:`environment_radiance`) and how a learned predictor trained (:func:`training_summary`).
"""

from __future__ import annotations

import math
import weakref

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet
from core.predictor_names import PREDICTORS, PredictorName
from processing.interpolation import InterpolationMethod, interpolation_weights
from processing.learned_rti_training import TrainingSettings
from processing.sample_model_store import models_for_field
from processing.sample_models import BASIS_MODELS, SampleModels, choose_model, fit_sample_models
from render.engines.model_shading import prepare_lighting, relight_models
from render.learned_predictor import TRAINED, LearnedPredictor
from render.prediction_methods import (
    LightPredictor,
    MixturePredictor,
    _Adaptive,
    _Basis,
    _Interpolating,
    _Model,
    _Relief,
    _ReliefFits,
    _Residual,
)
from render.rti_fits import choose_rbf_sigma, sigma_subset

__all__ = [
    "PREDICTORS",
    "PredictorName",
    "environment_radiance",
    "make_predictor",
    "training_summary",
]


#: Bytes of predictions :func:`environment_radiance` holds at once (lights x samples x RGB).
BATCH_BYTES = 256 * 2**20


#: Model fits of in-memory fields (while they live), by the models fitted.
_FITTED: weakref.WeakKeyDictionary[ReflectanceField, dict[tuple[str, ...], SampleModels]]
_FITTED = weakref.WeakKeyDictionary()
#: The relief rung's fits of fields (while they live), shared by ``relief`` and the network
#: told its shadows: a choice's fold makes both, and fits the heights once.
_RELIEFS: weakref.WeakKeyDictionary[ReflectanceField, _ReliefFits] = weakref.WeakKeyDictionary()


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
    learned = getattr(predictor, "base", predictor)
    if not isinstance(learned, LearnedPredictor):
        return "", []
    trained = TRAINED.get(learned.field, {})
    shadowed = learned.shadows is not None
    models = [
        m for (_, settings, shadows), m in trained.items()
        if settings == learned.settings and shadows == shadowed
    ]  # fmt: skip
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
    field: ReflectanceField, names: list[str], models: SampleModels | None
) -> SampleModels:
    if models is not None and all(n in models.fits for n in names):
        return models
    if field.radiance_digest is not None:  # a store: its fit is saved beside it and reused
        return models_for_field(field, models=names)
    # Held in memory (a split's subset): nothing saved, but kept while the subset lives, so the
    # rungs built on one model (the model, its residual, the adaptive mixture) fit it once.
    fitted = _FITTED.setdefault(field, {})
    key = tuple(sorted(names))
    if key not in fitted:
        fitted[key] = fit_sample_models(field, names)
    return fitted[key]


def make_predictor(
    field: ReflectanceField,
    name: str,
    *,
    models: SampleModels | None = None,
    scale: float = 1.0,
    sigma: float | None = None,
    learned: TrainingSettings | None = None,
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
            choose_rbf_sigma(field.light_directions, sigma_subset(field))
            if sigma is None
            else sigma
        )
        return _Interpolating(field, name, chosen)
    if name.removesuffix("+residual") in ("learned", "learned+relief"):
        shadows = make_predictor(field, "relief", models=models) if "+relief" in name else None
        assert shadows is None or isinstance(shadows, _Relief)
        network = LearnedPredictor(
            field, name.removesuffix("+residual"), learned or TrainingSettings(), shadows
        )
        return _Residual(field, name, network) if name.endswith("+residual") else network
    basis = name.removesuffix("-8bit")
    if basis in BASIS_MODELS:
        return _Basis(field, name, basis, name.endswith("-8bit"), scale)
    if name.startswith("light-stage+"):
        model = name.removeprefix("light-stage+")
        fitted = _fitted_models(field, [model], models)
        return _Residual(field, name, _Model(field, model, fitted), interpolation="nearest")
    model = "lambert+ggx" if name in ("adaptive", "relief") else name.removesuffix("+residual")
    fitted = _fitted_models(field, [model], models)
    base = _Model(field, model, fitted)
    if name == "adaptive":
        return _Adaptive(field, name, _Residual(field, "lambert+ggx+residual", base))
    if name == "relief":
        # A fit the caller gave may not be the field's own: its relief is not shared.
        fits = _RELIEFS.setdefault(field, _ReliefFits()) if models is None else _ReliefFits()
        return _Relief(field, name, _Residual(field, "lambert+ggx+residual", base), fits)
    return _Residual(field, name, base) if name.endswith("+residual") else base
