"""The simulator's fields and ground truths as the benchmarks use them.

A simulated field cached under the output directory (:func:`field_path`), a view halfway
between two captured cameras (:func:`between_view`), the simulator's ground truth of a view
under a panorama (:func:`truth_of`, :func:`truths_of_views`) and a relit image's errors
against it (:func:`image_errors`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.light_set import grid_lights
from processing.image_quality import relative_rmse_values
from render.engines.interpolated import RelitImage
from sim.field import field_cameras, simulate_field
from sim.ground_truth import shade_environment, shade_environment_views
from sim.scenes import SurfaceSamples
from sim.synthetic_camera import SyntheticImage, camera_visibility, image_of_points

__all__ = [
    "TRUTH_GRID",
    "Truth",
    "between_view",
    "field_path",
    "image_errors",
    "truth_of",
    "truths_of_views",
]

#: Rows of the ground truth's panorama grid (a 64 x 128 pre-filter of the panorama).
TRUTH_GRID = 64


def field_path(
    out: Path, scene: str, cameras: int, lights: int, points: int, size: int, dtype: str
) -> Path:
    """Path of the simulated field of ``scene`` under ``out/fields/``, simulated if not there.

    Parameters
    ----------
    out : Path, the benchmark's output directory
    scene : str, a scene name of :mod:`sim.scenes`
    cameras, lights : int, the field's camera poses (S) and lights (T)
    points : int, surface samples
    size : int, each camera's image side, pixels
    dtype : str, the store's radiance dtype (``"float32"`` or ``"float16"``)
    """
    path = out / "fields" / f"{scene}-S{cameras}-T{lights}-{points}-{size}px-{dtype}.zarr"
    if not path.exists():
        layout = field_cameras(cameras, width=size, height=size)
        simulate_field(path, scene, lights=lights, cameras=layout, points=points, dtype=dtype)
    return path


def between_view(cameras: list[PinholeCamera], index: int) -> PinholeCamera:
    """A view halfway in azimuth between camera ``index`` and its ring neighbour."""
    ring = sorted(
        c.azimuth_deg
        for c in cameras
        if abs(c.inclination_deg - cameras[index].inclination_deg) < 1e-6
    )
    step = 360.0 / len(ring) if len(ring) > 1 else 30.0
    return replace(cameras[index], azimuth_deg=(cameras[index].azimuth_deg + step / 2) % 360.0)


def image_errors(image: RelitImage, truth: Truth) -> dict[str, Any]:
    """Relative RMSE and PSNR of a relit image over the pixels both it and the truth cover.

    Also the relative RMSE of its relit samples against the true ones (``sample_relative_rmse``).
    """
    mask = image.coverage & truth.image.coverage
    mse = float(np.mean((image.rgb[mask] - truth.image.rgb[mask]) ** 2))
    peak = float(truth.image.rgb[mask].max())
    # The relit samples against the true ones: the relighting's error without the splatting's
    # (the renderer estimates the point spacing, the simulator knows it; their splats differ).
    shown = image.needed & truth.shown
    return {
        "relative_rmse": relative_rmse_values(image.rgb, truth.image.rgb, mask),
        "sample_relative_rmse": relative_rmse_values(image.radiance, truth.radiance, shown),
        "psnr_db": 10 * np.log10(peak**2 / mse) if mse > 0 else None,
    }


@dataclass(frozen=True)
class Truth:
    """The simulator's ground truth of one view: the image and every sample's radiance."""

    image: SyntheticImage
    radiance: NDArray[np.float64]
    shown: NDArray[np.bool_]


def truth_of(
    samples: SurfaceSamples, rgb: NDArray[np.float32], camera: PinholeCamera, shadows: bool
) -> Truth:
    """The simulator's ground truth of ``samples`` seen from ``camera`` under the panorama ``rgb``.

    The panorama is pre-filtered to a grid of lights ``TRUTH_GRID`` rows high; ``shadows``
    casts the scene's shadows (needed when it is not convex).
    """
    lights = grid_lights(rgb, TRUTH_GRID)
    radiance = shade_environment(samples, camera.position, lights, shadows=shadows)
    image = image_of_points(samples, camera, radiance)
    return Truth(image, radiance, camera_visibility(samples, camera))


def truths_of_views(
    samples: SurfaceSamples,
    rgb: NDArray[np.float32],
    cameras: list[PinholeCamera],
    shadows: bool,
) -> list[Truth]:
    """:func:`truth_of` for several views of one lighting, sharing the shadow maps.

    Shadow maps are made once for all the views (``truth_of`` would redo them per view).
    """
    radiances = shade_environment_views(
        samples, [c.position for c in cameras], grid_lights(rgb, TRUTH_GRID), shadows=shadows
    )
    truths = []
    for camera, radiance in zip(cameras, radiances, strict=True):
        image = image_of_points(samples, camera, radiance)
        truths.append(Truth(image, radiance, camera_visibility(samples, camera)))
    return truths
