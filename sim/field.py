"""A reflectance field straight from the simulator, skipping image capture.

For every light t (directional, unit irradiance) and camera s, the radiance of every surface
sample toward the camera, and each camera's visibility mask, written to the store of
:mod:`core.field_store`. Each light's shadow map is computed once and reused for every camera.
"""

from __future__ import annotations

import os
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.directions import angles_deg_from_direction, hemisphere_layout
from core.field_store import SAMPLE_CHUNK, FieldStoreWriter
from core.progress import progress_bar
from sim.scenes import build_scene, get_scene
from sim.synthetic_camera import (
    DirectionalLight,
    camera_visibility,
    light_visibility,
    shade_points,
)

__all__ = ["field_cameras", "simulate_field"]


def field_cameras(
    count: int,
    layout: str = "grid",
    *,
    distance: float = 4.0,
    fov_deg: float = 40.0,
    width: int = 512,
    height: int = 512,
) -> list[PinholeCamera]:
    """``count`` cameras over the upper hemisphere in ``layout``, all looking at the origin."""
    azimuth, inclination = angles_deg_from_direction(hemisphere_layout(count, layout))
    return [
        PinholeCamera(float(a), float(i), distance, fov_deg, width, height)
        for a, i in zip(azimuth, inclination, strict=True)
    ]


def simulate_field(
    path: str | os.PathLike[str],
    scene: str,
    *,
    lights: int | NDArray[np.floating],
    cameras: list[PinholeCamera],
    points: int = 100_000,
    layout: str = "grid",
    dtype: str = "float32",
    overwrite: bool = False,
    sample_chunk: int = SAMPLE_CHUNK,
) -> Path:
    """Write the simulated field of ``scene`` to a new store at ``path``; returns the path.

    ``lights`` is a count (directions of ``layout``) or the directions themselves (T, 3),
    unit vectors in the rig frame: held-out test lights, say. ``overwrite`` replaces a store
    already there (and the model fit saved beside it). ``sample_chunk``: samples per stored
    chunk (:class:`core.field_store.FieldStoreWriter`).
    """
    spec = get_scene(scene)
    samples = build_scene(scene, points)
    if isinstance(lights, int):
        light_directions = hemisphere_layout(lights, layout)
    else:
        light_directions = np.asarray(lights, dtype=np.float64)
        layout = "given"
    store = FieldStoreWriter(
        path,
        overwrite=overwrite,
        points=samples.points,
        normals=samples.normals,
        light_directions=light_directions,
        cameras=cameras,
        dtype=dtype,
        sample_chunk=sample_chunk,
        provenance={
            "source": "simulator",
            "scene": spec.to_json(),
            "points": points,
            "layout": layout,
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
        },
    )
    try:
        for s, camera in enumerate(cameras):
            store.write_visibility(s, camera_visibility(samples, camera))
        total = len(light_directions) * len(cameras)
        steps = progress_bar(total=total, desc="field", unit="slab")
        for t, direction in enumerate(light_directions):
            toward = (float(direction[0]), float(direction[1]), float(direction[2]))
            light = DirectionalLight(toward)
            lit = light_visibility(samples, light)[:, None]
            for s, camera in enumerate(cameras):
                radiance = shade_points(samples, camera.position, light, shadows=False) * lit
                store.write_slab(s, t, radiance.astype(np.float32))
                steps.update()
        steps.close()
    except BaseException:
        store.abort()
        raise
    return store.finish()
