"""Relit sequences: the environment turning around the object, or the object on a turntable.

One display exposure serves the whole sequence (the first frame's, unless given), so frames do
not flicker; :func:`render.output.write_sequence` writes the frames as GIF or MP4.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.progress import progress_bar
from processing.panorama import Panorama
from render.output import display_picture
from render.relight_mode import RelightEngine
from render.tonemap import auto_exposure

__all__ = ["SEQUENCES", "SequenceKind", "relight_sequence"]

SequenceKind = Literal["environment", "turntable"]
#: What turns: the environment about +z (yaw), or the camera about the object (azimuth).
SEQUENCES: tuple[SequenceKind, ...] = get_args(SequenceKind)


def relight_sequence(
    engine: RelightEngine,
    panorama: Panorama,
    camera: PinholeCamera,
    *,
    kind: SequenceKind = "environment",
    frames: int = 36,
    yaw_deg: float = 0.0,
    exposure: float = 1.0,
    modulation: NDArray[np.floating] | None = None,
    display_exposure: float | None = None,
) -> list[NDArray[np.uint8]]:
    """Tone-mapped frames of a full turn in ``frames`` equal steps.

    Parameters
    ----------
    engine : RelightEngine of the field
    panorama : Panorama, the environment
    camera : PinholeCamera, the first frame's view
    kind : {"environment", "turntable"}
        ``environment``: the yaw grows by 360 / frames degrees a frame (the view stays);
        ``turntable``: the camera's azimuth does (the lighting stays).
    frames : int, >= 1
    yaw_deg, exposure, modulation : the lighting controls of the first frame
    display_exposure : float, optional, the tone-mapping exposure (default: the first frame's
        :func:`render.tonemap.auto_exposure`)

    Returns
    -------
    list of ndarray, shape (H, W, 3), uint8
    """
    if kind not in SEQUENCES:
        raise InputError(f"unknown sequence {kind!r}; use one of {', '.join(SEQUENCES)}")
    if frames < 1:
        raise InputError(f"a sequence needs at least 1 frame, got {frames}")
    # What stays fixed is set once; what turns is set every frame.
    if kind == "environment":
        engine.set_view(camera)
    else:
        engine.set_lighting(panorama, yaw_deg=yaw_deg, exposure=exposure, modulation=modulation)
    pictures = []
    for frame in progress_bar(range(frames), desc="frames", unit="frame"):
        step = 360.0 * frame / frames
        if kind == "environment":
            engine.set_lighting(
                panorama, yaw_deg=yaw_deg + step, exposure=exposure, modulation=modulation
            )
        else:
            engine.set_view(replace(camera, azimuth_deg=(camera.azimuth_deg + step) % 360.0))
        image = engine.render()
        if display_exposure is None:
            covered = image.rgb[image.coverage]
            display_exposure = auto_exposure(covered) if covered.size else 1.0
        pictures.append(display_picture(image.rgb, image.coverage, display_exposure))
    return pictures
