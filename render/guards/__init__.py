"""Plain-language warnings for the cases where relighting is known to go wrong.

Each guard looks at the inputs only (the field's light and camera layout, its fitted lobes, the
view, the panorama) and says what to expect and what fixes it. Where the fix might be to relight
through the per-sample models, the advice follows the field's own held-out comparison
(:class:`render.engines.modes.HeldOutComparison`): the models are advised only where they predicted
lights they never saw better than interpolation did, and the figures are quoted. On a world no
model contains, the old unconditional advice made results worse where it fired (``python -m
bench.guard_advice``, docs/evaluation.md). The thresholds come from the
accuracy study (docs/models.md, ``python -m bench.relight``): interpolating a GGX lobe of
roughness 0.2 (full width about 30 degrees in light direction) from 30 lights (spacing about
26 degrees) misses it by 24-41 %; from 400 lights (about 7 degrees) by 2 % under light from
above.

Modules: ``warning`` (:class:`RelightWarning`, the lobe's width, the models' advice),
``lighting`` (the panorama's guards), ``capture`` (the capture's and the view's guards);
:func:`relight_warnings` asks every one that applies.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.directions import angle_between
from core.field_store import ReflectanceField
from processing.sample_models import SampleModels
from render.engines.modes import HeldOutComparison, RelightMode
from render.guards.capture import (
    CEILING_TOLERANCE,
    CLIPPED_OBSERVATIONS,
    GHOST_SPACING,
    GRAZING_INCLINATION_DEG,
    NOISY_LOO,
    clipped_observation_share,
    empty_camera_warning,
    empty_cameras,
    fitted_lobe_alpha,
    ghosting_warning,
    grazing_view_warning,
    noisy_capture_warning,
    saturated_capture_warning,
    view_warning,
)
from render.guards.lighting import (
    CLIPPED_SHARE,
    LDR_CEILING,
    OUTSIDE_ROWS,
    OUTSIDE_SHARE,
    SUN_CAP_DEG,
    SUN_DIFFUSE_SPACING_DEG,
    SUN_GHOST_SPACING,
    SUN_SHARE,
    SUN_VIEW_OFFSET,
    clipped_panorama_warning,
    outside_light_share,
    outside_light_warning,
    sun_share,
    sun_warning,
)
from render.guards.warning import RelightWarning, lobe_width_deg, model_advice

__all__ = [
    "CEILING_TOLERANCE",
    "CLIPPED_OBSERVATIONS",
    "CLIPPED_SHARE",
    "GHOST_SPACING",
    "GRAZING_INCLINATION_DEG",
    "LDR_CEILING",
    "NOISY_LOO",
    "OUTSIDE_ROWS",
    "OUTSIDE_SHARE",
    "SUN_CAP_DEG",
    "SUN_DIFFUSE_SPACING_DEG",
    "SUN_GHOST_SPACING",
    "SUN_SHARE",
    "SUN_VIEW_OFFSET",
    "RelightWarning",
    "clipped_observation_share",
    "clipped_panorama_warning",
    "empty_camera_warning",
    "empty_cameras",
    "fitted_lobe_alpha",
    "ghosting_warning",
    "grazing_view_warning",
    "lobe_width_deg",
    "model_advice",
    "noisy_capture_warning",
    "outside_light_share",
    "outside_light_warning",
    "relight_warnings",
    "saturated_capture_warning",
    "sun_share",
    "sun_warning",
    "view_warning",
]

#: Cameras nearest the view whose slabs :func:`relight_warnings` reads for the saturation check
#: (the ones a barycentric view blend reads anyway; a whole large field would take minutes).
CHECKED_CAMERAS = 3


def relight_warnings(
    field: ReflectanceField,
    camera: PinholeCamera,
    rgb: NDArray[np.floating],
    mode: RelightMode,
    models: SampleModels | None,
    comparison: HeldOutComparison | None = None,
) -> list[RelightWarning]:
    """Every warning that applies to relighting ``field`` under ``rgb`` at ``camera``.

    The panorama and capture guards apply to every mode; the ones about interpolating the
    measured lights and cameras (sun, ghosting, views outside or grazing, noise, light from
    outside the measured lights) only to the modes that interpolate (``not mode.uses_models``),
    since the per-sample models evaluate the fitted BRDF at any light and view and average the
    noise (bench.stability).

    Parameters
    ----------
    field : ReflectanceField
    camera : PinholeCamera, the wanted view
    rgb : ndarray, shape (H, 2H, 3), the panorama as relit (after yaw and exposure)
    mode : RelightMode
    models : SampleModels or None, the field's fit (its lobe and LOO error inform the guards)
    comparison : HeldOutComparison, optional, the models against interpolation on held-out
        lights (:class:`render.engines.modes.ModeChoice`): the advice to relight through the
        models is given only where they won
    """
    found = [clipped_panorama_warning(rgb), empty_camera_warning(field)]
    nearest = np.argsort(angle_between(field.camera_directions, camera.direction[None, :]))
    found.append(saturated_capture_warning(field, [int(s) for s in nearest[:CHECKED_CAMERAS]]))
    if not mode.uses_models:
        alpha = None if models is None else fitted_lobe_alpha(models)
        points = field.sample_kind == "points"
        if points:
            found += [
                view_warning(field.camera_directions, camera, comparison),
                grazing_view_warning(field.camera_directions, camera, comparison),
            ]
        if models is not None:
            found.append(noisy_capture_warning(models, comparison))
        if alpha is not None:
            found.append(ghosting_warning(field.light_directions, alpha, comparison))
        found.append(outside_light_warning(rgb, field.light_directions))
        # A pixel field has one fixed view: nothing to interpolate between cameras.
        views = (field.camera_directions, camera) if points else (None, None)
        found.append(
            sun_warning(
                rgb,
                field.light_directions,
                alpha,
                interpolation=mode.predictors()[0][1],
                camera_directions=views[0],
                camera=views[1],
                comparison=comparison,
            )
        )
    return [w for w in found if w is not None]
