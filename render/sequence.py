"""Relit sequences: the environment turning around the object, or the object on a turntable.

Every frame's lighting goes through the controls' one adjustment
(:meth:`render.engines.panorama_lit.PanoramaControls.adjusted`, handed to the engine's
``take_lighting``): an environment sequence turns the yaw of the first frame's controls, the
visible panorama adjusted anew, never the engine's lights. A prepared request
(:func:`relight_prepared_sequence`) is its own frame 0: what ``prepare_relighting`` lit and set
is rendered as it stands. One display exposure serves the whole sequence (the first frame's,
unless given), so frames do not flicker; :func:`render.output.write_sequence` writes the frames
as GIF or MP4.
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
from render.engines.modes import RelightEngine
from render.engines.panorama_lit import AdjustedPanorama, PanoramaControls, PanoramaLitEngine
from render.output import display_picture
from render.relighting import PreparedRelighting
from render.tonemap import auto_exposure

__all__ = ["SEQUENCES", "SequenceKind", "relight_prepared_sequence", "relight_sequence"]

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
    """Tone-mapped frames of a full turn in ``frames`` equal steps, lit and set here.

    For an engine opened bare (``render.engines.modes.open_relighter``); an engine that
    :func:`render.relighting.prepare_relighting` lit and set is
    :func:`relight_prepared_sequence`'s.

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
    _check(kind, frames)
    lit = _panorama_lit(engine)
    controls = PanoramaControls(yaw_deg=yaw_deg, exposure=exposure, modulation=modulation)
    first = lit.adjust(panorama, controls)
    # The engine at frame 0, as prepare_relighting leaves one; the frames turn from there.
    engine.set_view(camera)
    lit.take_lighting(first)
    return _turn(engine, first, camera, kind, frames, display_exposure)


def relight_prepared_sequence(
    prepared: PreparedRelighting,
    *,
    kind: SequenceKind = "environment",
    frames: int = 36,
    display_exposure: float | None = None,
) -> list[NDArray[np.uint8]]:
    """Tone-mapped frames of a full turn from a prepared request (:func:`relight_sequence`).

    Frame 0 is the engine as prepared (its lighting and view, nothing redone); the next frames
    turn the request's controls (``environment``) or its camera (``turntable``).

    Parameters
    ----------
    prepared : PreparedRelighting, from :func:`render.relighting.prepare_relighting`, not yet
        lit or set otherwise
    kind, frames, display_exposure : as :func:`relight_sequence`

    Returns
    -------
    list of ndarray, shape (H, W, 3), uint8
    """
    _check(kind, frames)
    return _turn(
        prepared.engine, prepared.adjusted, prepared.camera, kind, frames, display_exposure
    )


def _check(kind: str, frames: int) -> None:
    if kind not in SEQUENCES:
        raise InputError(f"unknown sequence {kind!r}; use one of {', '.join(SEQUENCES)}")
    if frames < 1:
        raise InputError(f"a sequence needs at least 1 frame, got {frames}")


def _panorama_lit(engine: RelightEngine) -> PanoramaLitEngine:
    # Every mode's engine is lit through the shared base, where the controls apply once.
    assert isinstance(engine, PanoramaLitEngine)
    return engine


def _turn(
    engine: RelightEngine,
    first: AdjustedPanorama,
    camera: PinholeCamera,
    kind: SequenceKind,
    frames: int,
    display_exposure: float | None,
) -> list[NDArray[np.uint8]]:
    """The frames of ``engine``, lit by ``first`` and set to ``camera`` (frame 0) already."""
    lit = _panorama_lit(engine)
    controls = first.controls
    pictures = []
    for frame in progress_bar(range(frames), desc="frames", unit="frame"):
        step = 360.0 * frame / frames
        if kind == "environment" and frame > 0:
            # Each yaw adjusts the visible panorama once: its blocked copy, and a pre-filter
            # keyed on it, stand for the whole turn.
            turned = replace(controls, yaw_deg=controls.yaw_deg + step)
            lit.take_lighting(turned.adjusted(first.visible))
        elif kind == "turntable":
            view = replace(camera, azimuth_deg=(camera.azimuth_deg + step) % 360.0)
            if view != camera:  # frame 0's view is set, unless its azimuth wraps to [0, 360)
                engine.set_view(view)
        image = engine.render()
        if display_exposure is None:
            covered = image.rgb[image.coverage]
            display_exposure = auto_exposure(covered) if covered.size else 1.0
        pictures.append(display_picture(image.rgb, image.coverage, display_exposure))
    return pictures
