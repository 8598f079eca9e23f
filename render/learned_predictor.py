"""The learned rungs' predictor: a network trained on the field, told its shadows or not.

``learned`` and ``learned+residual`` (:mod:`render.light_prediction`) train
:class:`processing.learned_rti.LearnedRTI` on the field's measured images; ``learned+relief``
tells it the relief rung's visibility of each light at each pixel
(:mod:`render.prediction_methods`), so it learns each pixel lit and in shadow and the relief
places the shadows between the lights. A trained network is kept while its field lives.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from dataclasses import field as default

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.field_store import ReflectanceField
from core.progress import progress_bar
from processing.learned_rti import LearnedRTI
from processing.learned_rti_training import TrainingSettings, train_learned_rti
from render.prediction_methods import _basis_frame_directions, _bounded, _Relief

__all__ = ["TRAINED", "LearnedPredictor", "TrainedKey"]

#: Trained networks by field (while it lives), so ``learned`` and ``learned+residual`` of one
#: field train once.
TrainedKey = tuple[int, TrainingSettings, bool]
TRAINED: weakref.WeakKeyDictionary[ReflectanceField, dict[TrainedKey, LearnedRTI]]
TRAINED = weakref.WeakKeyDictionary()


@dataclass
class LearnedPredictor:
    """The learned model of a field, a :class:`render.prediction_methods.LightPredictor`.

    One network for a field of points (lights in the rig frame, every camera's samples), one
    per camera for a field of pixels (lights in its frame). With ``shadows`` (a field of
    pixels), the network is told each light's visibility at each pixel, the relief rung's
    (``_Relief.visibility``): it learns the pixel lit and in shadow, the relief says where
    the shadow falls between the measured lights.
    """

    field: ReflectanceField
    name: str
    settings: TrainingSettings
    shadows: _Relief | None = None
    _codes: dict[int, NDArray[np.float32]] = default(default_factory=dict)

    def _train(self, cameras: list[int], lights: NDArray[np.float64]) -> LearnedRTI:
        # At most the samples training reads, drawn evenly from the cameras: a large field of
        # points is never gathered whole.
        rng = np.random.default_rng(self.settings.seed)
        share = -(-self.settings.max_samples // len(cameras))
        parts, shadows = [], []
        for s in cameras:
            seen = np.flatnonzero(self.field.visibility[s])
            if seen.size > share:
                seen = np.sort(rng.choice(seen, size=share, replace=False))
            parts.append(self.field.camera_slab(s)[:, seen])
            if self.shadows is not None:
                lit, _ = self.shadows.visibility(s, self.field.light_directions)
                shadows.append(lit[seen].T)
        values = np.concatenate(parts, axis=1)
        visibility = np.concatenate(shadows, axis=1) if shadows else None
        if values.shape[1] == 0:
            raise InputError(f"{self.field.path}: no camera sees any sample; nothing to learn")
        bar = progress_bar(desc="training", unit="step")

        def advance(step: int, planned: int) -> None:
            # The steps foreseen change as training learns its pace (a time budget).
            if bar.total != planned:
                bar.set_total(planned)
            bar.update(step - bar.n)

        try:
            return train_learned_rti(values, lights, self.settings, advance, visibility=visibility)
        finally:
            bar.close()

    def model(self, camera: int) -> LearnedRTI:
        """The model that predicts ``camera``'s view (trained on first use)."""
        key = (
            camera if self.field.sample_kind == "pixels" else -1,
            self.settings,
            self.shadows is not None,
        )
        trained = TRAINED.setdefault(self.field, {})
        if key not in trained:
            cameras = [camera] if key[0] >= 0 else list(range(self.field.shape[0]))
            lights = _basis_frame_directions(self.field, camera, self.field.light_directions)
            trained[key] = self._train(cameras, lights)
        return trained[key]

    def predict(self, camera: int, directions: NDArray[np.floating]) -> NDArray[np.float32]:
        """``camera``'s samples (Q, P, 3) under the lights ``directions`` (Q, 3), rig frame."""
        model = self.model(camera)
        seen = self.field.visibility[camera]
        if camera not in self._codes:
            self._codes[camera] = model.encode(self.field.camera_slab(camera)[:, seen])
        frame = _basis_frame_directions(self.field, camera, directions)
        visibility = None
        if self.shadows is not None:
            lit, _ = self.shadows.visibility(camera, directions)
            visibility = lit[seen].T
        out = np.zeros((len(frame), self.field.shape[2], 3), dtype=np.float32)
        out[:, seen] = model.decode(self._codes[camera], frame, visibility)
        return _bounded(self.field, camera, out)
