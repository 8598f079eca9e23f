"""Each method's predictor of unmeasured lights, behind :class:`LightPredictor`.

The methods are named and made in :mod:`render.light_prediction` (:func:`make_predictor`);
here are their predictors: the interpolations of the measured images (nearest, barycentric,
the RTI tools' rbf of :mod:`render.rti_fits`), the linear bases (PTM, HSH, in linear light or
fitted to 8-bit values), the per-sample models, a model plus the interpolation of its residual
(or the light-stage sum plus the model's correction), the adaptive mix of barycentric and
model + residual, the model + residual with a relief's cast shadows, and a per-pixel mixture
of any of them; the learned model's is :mod:`render.learned_predictor`.

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

from dataclasses import dataclass, replace
from dataclasses import field as default
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from core.camera_model import rig_to_camera
from core.colour import srgb_to_linear
from core.errors import InputError, NotApplicable
from core.field_store import ReflectanceField
from core.light_set import LightSet
from core.progress import progress_bar
from processing.interpolation import (
    DirectionWeights,
    InterpolationMethod,
    interpolation_weights,
    mean_spacing_deg,
)
from processing.mark_distances import distance_marks, distance_share, mark_distances
from processing.relief_shadows import (
    DECISIVE_TRAVEL,
    FIT_STEPS,
    TRUSTED_DISAGREEMENT,
    despeckled,
    relief_contradictions,
    relief_disagreement,
    relief_heights,
    relief_visibility,
    shadow_travel,
)
from processing.sample_models import (
    ParametricFit,
    SampleModels,
    choose_model,
    evaluate_basis,
    leave_one_out_barycentric,
)
from processing.sample_models.bases import fit_basis
from render.engines.model_shading import prepare_lighting, relight_models
from render.rti_fits import fit_basis_8bit, rbf_weights

__all__ = [
    "BOUND",
    "BOUND_SPACING_DEG",
    "LightPredictor",
    "MixturePredictor",
    "bound_factor",
]

#: Fitted predictions are at most this times a sample's brightest measured value (dense
#: lights; see :func:`bound_factor`).
BOUND = 1.25
#: Mean light spacing (degrees) up to which :data:`BOUND` holds.
BOUND_SPACING_DEG = 10.0


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
    limit = (bound_factor(field.light_directions) * peak[None]).astype(np.float32)
    # Straight into float32: a panorama's grid predicts thousands of lights per frame.
    out = np.empty(np.shape(values), dtype=np.float32)
    return np.clip(values, np.float32(0.0), limit, out=out)


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
        # One matrix product (Q, B) @ (B, P x 3): einsum does not reach BLAS for this layout,
        # and a panorama's grid asks for thousands of lights per frame.
        points = coefficients.shape[0]
        flat = coefficients.transpose(1, 0, 2).reshape(coefficients.shape[1], points * 3)
        values = (design.astype(flat.dtype) @ flat).reshape(len(design), points, 3)
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


#: Interpolated marks strictly between these: the lights around disagree, the relief decides.
_UNANIMOUS = (0.02, 0.98)
#: Barycentric weights below this are rounding (a measured light's neighbours get 1e-16).
_NEGLIGIBLE = 1e-9


@dataclass
class _ReliefFits:
    """What :class:`_Relief` fits of a field, per camera: shared by the predictors of one field.

    The ``relief`` rung and the network told its shadows (``learned+relief``) are made apart,
    a choice's fold makes both: sharing these, the heights are fitted once. Holds no
    reference to the field, so a weak cache keyed by the field lets both go together.
    """

    heights: dict[int, NDArray[np.float32]] = default(default_factory=dict)
    trusted: dict[int, NDArray[np.bool_]] = default(default_factory=dict)
    #: Per camera (T, P): 1 where the relief reproduces a measured mark (or says nothing).
    reproduced: dict[int, NDArray[np.float32]] = default(default_factory=dict)
    #: Per camera: the measured marks' signed distances (T, P) and their weight (P,).
    moved: dict[int, tuple[NDArray[np.float32], NDArray[np.float32]]] = default(
        default_factory=dict
    )


@dataclass
class _Relief:
    """``lambert+ggx+residual`` whose cast shadows between lights come from a fitted relief.

    Where the measured lights around a requested one disagree on a pixel's shadow, the
    barycentric marks would give it a fraction of each; the heights of
    :func:`processing.relief_shadows.relief_heights`, fitted to every measured mark, say
    where the shadow moved instead. They decide only where they are likely right: the
    shadow moves further than its occluder is tall between the lights
    (:data:`processing.relief_shadows.DECISIVE_TRAVEL`), the relief reproduces the marks of
    the lights with most of the weight at the pixel, and of most of the pixel's lights
    (:data:`processing.relief_shadows.TRUSTED_DISAGREEMENT`). Elsewhere the marks' edges
    are blended as signed distances (:mod:`processing.mark_distances`) as far as that
    predicted the measured images better than the faded marks. Pixel fields (one view) only.
    """

    field: ReflectanceField
    name: str
    residual: _Residual
    fits: _ReliefFits = default(default_factory=_ReliefFits)
    _unshadowed: _Model | None = None

    def _fit(self) -> tuple[ParametricFit, NDArray[np.float64]]:
        model = self.residual.base
        assert isinstance(model, _Model)
        fit = model.models.fit(model.name)
        assert isinstance(fit, ParametricFit)
        return fit, model.models.camera_frame

    def _image_shape(self) -> tuple[int, int]:
        shape = self.field.image_shape
        if shape is None or self.field.shape[0] != 1:
            raise NotApplicable("relief shadows need a field of pixels seen by one camera")
        return shape

    def heights(self, camera: int) -> NDArray[np.float32]:
        """The relief (H, W) fitted to ``camera``'s shadow marks, pixel units."""
        if camera not in self.fits.heights:
            fit, frame = self._fit()
            count = len(self.field.light_directions)
            visible = self.field.visibility[camera].reshape(self._image_shape())
            marks, normals = fit.lit[:, :count], fit.normals @ frame.T
            lights = self.field.light_directions @ frame.T
            with progress_bar(total=FIT_STEPS, desc="relief", unit="step") as bar:
                heights = relief_heights(
                    marks, normals, lights, visible, progress=lambda step, _: bar.update()
                )
            contradictions = relief_contradictions(heights, marks, normals, lights, visible)
            self.fits.heights[camera] = heights
            self.fits.trusted[camera] = relief_disagreement(contradictions) <= TRUSTED_DISAGREEMENT
            self.fits.reproduced[camera] = (contradictions != 1).T.astype(np.float32)
        return self.fits.heights[camera]

    def _unshadowed_model(self) -> _Model:
        """The model with every light reaching every pixel: shading without its marks."""
        if self._unshadowed is None:
            model = self.residual.base
            assert isinstance(model, _Model)
            fit, _ = self._fit()
            lit = replace(fit, lit=np.ones_like(fit.lit))
            self._unshadowed = _Model(
                self.field, model.name, replace(model.models, fits={model.name: lit})
            )
        return self._unshadowed

    def moved_marks(self, camera: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """The measured marks' signed distances (T, P) and, per pixel (P,), their weight.

        The weight is the share of the two blends' errors (:mod:`processing.mark_distances`)
        when each measured image is predicted from the others, the model and its residual
        as this rung predicts: the images', not the marks', since marks mistaken for
        shadows (a brushed highlight) matter only as far as they change the image.
        """
        if camera not in self.fits.moved:
            shape = self._image_shape()
            fit, _ = self._fit()
            measured = self.field.light_directions
            lit = (fit.lit[:, : len(measured)].T >= 0.5).astype(np.float32)
            distances = mark_distances(lit, shape)
            unshadowed = self._unshadowed_model().predict(camera, measured)
            residual = self.residual._residual_of(camera)
            # One leave-one-out pass (T triangulations) for the residual, marks and distances.
            stacked = np.concatenate([residual, lit[:, :, None], distances[:, :, None]], axis=2)
            held_out = leave_one_out_barycentric(measured, stacked)
            rest = held_out[:, :, :3] - self.field.camera_slab(camera)
            faded, moved = held_out[:, :, 3], distance_marks(held_out[:, :, 4])
            errors = [np.sum((unshadowed * m[:, :, None] + rest) ** 2, axis=(0, 2))
                      for m in (faded, moved)]  # fmt: skip
            self.fits.moved[camera] = (distances, distance_share(*errors))
        return self.fits.moved[camera]

    def visibility(
        self, camera: int, directions: NDArray[np.floating]
    ) -> tuple[NDArray[np.float32], DirectionWeights]:
        """Each pixel's visibility (P, Q) of the lights (Q, 3), and their barycentric weights.

        The measured marks at a measured light; between them, the relief's cast shadows where
        they decide, the marks' moved edges elsewhere (the class's docstring).
        """
        shape = self._image_shape()
        fit, frame = self._fit()
        measured = self.field.light_directions
        d = np.asarray(directions, dtype=np.float64)
        weights = interpolation_weights(measured, d, "barycentric", policy="clamp")
        marks = weights.apply(fit.lit[:, : len(measured)].T.astype(np.float32)).T
        seen = d @ frame.T
        # The relief decides where the shadow moves far between the measured lights around,
        # they disagree, the pixel is trusted and the relief reproduces most of their marks
        # (all: an ideal block's error 0.26x the marks', not 0.11x); elsewhere it casts none.
        around = measured[weights.indices] @ frame.T
        travel = shadow_travel(seen, around, weights.weights > _NEGLIGIBLE)
        decisive = np.flatnonzero(travel > DECISIVE_TRAVEL)
        # Between the lights the marks' edges move (their blended distances) where that
        # predicted the measured images better than fading them.
        distances, share = self.moved_marks(camera)
        moved = distance_marks(weights.apply(distances).T)
        visibility = (share[:, None] * moved + (1.0 - share[:, None]) * marks).astype(np.float32)
        if len(decisive):
            # Fitted only now: the choices' scores at the measured lights cost no fit.
            heights = self.heights(camera)
            interpolated = marks[:, decisive]
            reproduced = weights.apply(self.fits.reproduced[camera]).T[:, decisive] > 0.5
            torn = (
                (interpolated > _UNANIMOUS[0]) & (interpolated < _UNANIMOUS[1]) & reproduced
                & self.fits.trusted[camera][:, None]
            )  # fmt: skip
            visible = self.field.visibility[camera].reshape(shape)
            cast = relief_visibility(heights, seen[decisive], visible)
            between = np.where(torn, cast, visibility[:, decisive])
            visibility[:, decisive] = despeckled(between, torn, shape)
        return visibility, weights

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        d = np.asarray(directions, dtype=np.float64)
        visibility, weights = self.visibility(camera, d)
        unshadowed = self._unshadowed_model().predict(camera, d)
        correction = weights.apply(self.residual._residual_of(camera))
        return _bounded(self.field, camera, unshadowed * visibility.T[:, :, None] + correction)


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
            # One leave-one-out pass (T triangulations) for the images and the residual.
            held_out = leave_one_out_barycentric(measured, np.concatenate([data, residual], 2))
            alone, helped = held_out[:, :, :3], fitted + held_out[:, :, 3:]
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
