"""Relit point clouds through VTK (pyvista): off-screen pictures, and a window on a desktop.

The numba splatter (:mod:`render.splat`) is the product's renderer; this path draws the same
points with VTK's rasteriser, for users who want VTK's viewer or its exporters. Without a display,
VTK renders through EGL (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``, set here when no
``DISPLAY`` is present).
"""

from __future__ import annotations

import math
import os

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError

__all__ = ["pyvista_picture", "show_points"]


def _plotter(camera: PinholeCamera, off_screen: bool):  # type: ignore[no-untyped-def]
    if off_screen and not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    plotter = pv.Plotter(off_screen=off_screen, window_size=[camera.width, camera.height])
    plotter.background_color = pv.Color("black")
    _, up, _ = camera.axes()
    plotter.camera.position = tuple(camera.position)
    plotter.camera.focal_point = (0.0, 0.0, 0.0)
    plotter.camera.up = tuple(up)
    # VTK's view angle is vertical; ours is horizontal.
    half = math.atan(math.tan(math.radians(camera.fov_deg) / 2) * camera.height / camera.width)
    plotter.camera.view_angle = math.degrees(2 * half)
    plotter.camera.clipping_range = (camera.distance * 0.01, camera.distance * 4.0)
    return plotter


def _facing(
    points: NDArray[np.floating], normals: NDArray[np.floating], camera: PinholeCamera
) -> NDArray[np.bool_]:
    cloud = np.asarray(points, dtype=np.float64)
    return np.einsum("pk,pk->p", np.asarray(normals, np.float64), camera.position - cloud) > 0


def pyvista_picture(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    colours: NDArray[np.uint8],
    camera: PinholeCamera,
    spacing: float,
) -> NDArray[np.uint8]:
    """Draw points (P, 3) with 8-bit colours (P, 3) as VTK point sprites; (H, W, 3) uint8.

    Back-facing points are left out (a point cloud has no surface to hide them); points are
    squares of the splat size at the object's distance, ``spacing`` scene units wide.
    """
    if colours.shape != (len(points), 3) or colours.dtype != np.uint8:
        raise InputError(f"colours must be ({len(points)}, 3) uint8, got {colours.shape}")
    keep = _facing(points, normals, camera)
    if not keep.any():
        raise InputError("no point faces the camera")
    plotter = _plotter(camera, off_screen=True)
    try:
        size = max(2.0 * spacing * camera.focal_px / camera.distance, 1.0)
        plotter.add_points(
            np.asarray(points, dtype=np.float32)[keep],
            scalars=colours[keep],
            rgb=True,
            point_size=size,
            render_points_as_spheres=False,
        )
        plotter.render()  # VTK needs a render before a screenshot off screen
        picture = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    return np.ascontiguousarray(np.asarray(picture, dtype=np.uint8)[:, :, :3])


def show_points(
    points: NDArray[np.floating],
    normals: NDArray[np.floating],
    colours: NDArray[np.uint8],
    camera: PinholeCamera,
    spacing: float,
) -> None:  # pragma: no cover - needs a display and a person
    """Open an interactive VTK window on the relit points, starting at ``camera``.

    Every point is drawn (the view turns); ``normals`` are unused there but kept for symmetry
    with :func:`pyvista_picture`.
    """
    del normals
    plotter = _plotter(camera, off_screen=False)
    size = max(2.0 * spacing * camera.focal_px / camera.distance, 1.0)
    plotter.add_points(
        np.asarray(points, dtype=np.float32), scalars=colours, rgb=True, point_size=size
    )
    plotter.show()
