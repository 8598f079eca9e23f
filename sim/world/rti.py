"""RTI-style captures of a path-traced world: one overhead view, a dome of directional lights.

The pixel-field counterpart of :func:`sim.world.mitsuba.render_world_field`: what an RTI dome
records of a flat or relief object (a camera straight above, one photograph per light), from
the same Mitsuba worlds, so held-out-light evaluation can be run the way the RTI literature
runs it (e.g. 49 lights to fit, 20 others to predict). Writing the images and ``.lp`` files is
the application's job (``rig sim rti``): this module returns arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.directions import hemisphere_layout
from core.errors import InputError
from core.progress import progress_bar
from sim.world.mitsuba import DEFAULT_FIELD_SPP, DEFAULT_MAX_DEPTH, World, load_world
from sim.world.render import WorldRenderer

__all__ = ["RtiCapture", "overhead_camera", "render_world_rti"]


def overhead_camera(
    width: int, height: int, distance: float = 4.0, fov_deg: float = 32.0
) -> PinholeCamera:
    """The camera of an RTI dome: straight above the object at the origin."""
    return PinholeCamera(0.0, 0.0, distance, fov_deg, width, height)


@dataclass(frozen=True)
class RtiCapture:
    """An RTI capture of a world.

    Attributes
    ----------
    camera : PinholeCamera, straight above the object
    directions : ndarray, shape (T, 3), float64, unit vectors toward each light, rig frame
    images : ndarray, shape (T, H, W, 3), float32, linear radiance under unit irradiance
    alpha : ndarray, shape (H, W), float32, the fraction of each pixel the object covers
    """

    camera: PinholeCamera
    directions: NDArray[np.float64]
    images: NDArray[np.float32]
    alpha: NDArray[np.float32]


def render_world_rti(
    world: World | str,
    lights: int | NDArray[np.floating],
    *,
    width: int = 128,
    height: int = 96,
    spp: int = DEFAULT_FIELD_SPP,
    max_depth: int = DEFAULT_MAX_DEPTH,
    layout: str = "fibonacci",
    seed: int = 0,
) -> RtiCapture:
    """Path-trace one overhead image per light.

    Parameters
    ----------
    world : World, or a bundled name or world file
    lights : int (``layout`` over the upper hemisphere) or ndarray (T, 3) of unit directions
        toward the lights, rig frame, above the horizon
    width, height : image size, pixels
    spp, max_depth : the path tracer's settings (noise: ``docs/world.md``)
    layout : "fibonacci" or "grid", when ``lights`` is a count
    seed : int, of the first image's sampler (each image has its own)

    Raises
    ------
    InputError
        A light at or below the horizon (a dome lights from above), a bad count or size.
    """
    scene = load_world(world) if isinstance(world, str) else world
    if isinstance(lights, int):
        if lights < 1:
            raise InputError(f"an RTI capture needs at least one light, got {lights}")
        directions = hemisphere_layout(lights, layout)
    else:
        directions = np.asarray(lights, dtype=np.float64)
        if directions.ndim != 2 or directions.shape[1] != 3:
            raise InputError(f"light directions must be (T, 3), got {directions.shape}")
        directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    if np.any(directions[:, 2] <= 0.0):
        raise InputError("an RTI dome lights from above: every light needs z > 0")
    camera = overhead_camera(width, height)
    renderer = WorldRenderer(scene, camera, spp=spp, max_depth=max_depth)
    images = np.zeros((len(directions), height, width, 3), dtype=np.float32)
    alpha = np.zeros((height, width), dtype=np.float32)
    steps = progress_bar(directions, desc="rti", unit="image")
    for t, toward in enumerate(steps):
        image = renderer.render(toward, seed=(seed * 100_003 + t) % 2**32)
        images[t] = image.rgb
        alpha = np.maximum(alpha, image.alpha)
    return RtiCapture(camera=camera, directions=directions, images=images, alpha=alpha)
