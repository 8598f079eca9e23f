"""Simulated fields the tests of fitting and relighting share, and what their fits can know.

One home for the simulated field a module's fixture opens (:func:`simulated_field`) and for
the samples whose GGX lobe the field's lights and cameras show (:func:`peak_seen`): the
tests of the fits and of relighting from them judge the same samples by the same rule.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.field_store import CACHED_SLABS, ReflectanceField
from sim.field import field_cameras, simulate_field

__all__ = ["peak_seen", "simulated_field"]


def simulated_field(
    path: Path,
    scene: str,
    *,
    lights: int,
    cameras: int,
    size: int,
    points: int,
    cached_slabs: int = CACHED_SLABS,
) -> ReflectanceField:
    """``scene`` simulated at ``path`` (``cameras`` views of ``size`` x ``size``), opened."""
    simulate_field(
        path,
        scene,
        lights=lights,
        cameras=field_cameras(cameras, width=size, height=size),
        points=points,
    )
    return ReflectanceField.open(path, cached_slabs=cached_slabs)


def peak_seen(field: ReflectanceField, alpha: float, fraction: float = 0.02) -> np.ndarray:
    """Samples (P,) with a camera and a light whose half vector sees a GGX lobe of ``alpha``
    at ``fraction`` of its peak or more (the fit's identifiability rule, with a margin)."""
    assert field.points is not None and field.normals is not None
    normals = field.normals.astype(np.float64)
    best = np.zeros(field.shape[2])
    for s, camera in enumerate(field.cameras):
        view = camera.position - field.points.astype(np.float64)
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        for light in field.light_directions:
            half = view + light
            half /= np.linalg.norm(half, axis=1, keepdims=True)
            cos_h = np.sum(half * normals, axis=1)
            ratio = alpha**4 / (cos_h**2 * (alpha**2 - 1) + 1) ** 2
            lit = (normals @ light > 0) & field.visibility[s]
            best = np.maximum(best, np.where(lit, ratio, 0.0))
    return best >= fraction
