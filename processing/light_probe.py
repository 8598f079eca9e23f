"""Light directions from a mirror sphere (chrome ball), as RTI tools find them.

Each image shows the sphere lit by one light; the light's reflection is a small bright
highlight. Its centroid (intensity-weighted, above the sphere's dim background) is a pixel; the
ray through it meets the sphere at a point whose normal n reflects the view ray v into the
direction toward the light: ``l = v - 2 (v . n) n``. Unlike the orthographic shortcut of
RTI tools, the ray is cast through the calibrated camera (perspective, distortion), and the
sphere's place and radius in the rig frame are known (it stands at the object's place), so the
result is exact up to the centroid's error.

For a point light at a known distance the reflected ray is followed to that distance: the
direction then runs from the origin (the object's centre) to the light, not from the sphere's
surface point.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from core.calibrated_camera import CalibratedCamera, as_calibrated
from core.camera_model import PinholeCamera
from core.errors import InputError
from processing.calibration import ImageInput, linear_luminance, load_image

__all__ = ["MirrorSphere", "find_highlight", "light_directions_from_mirror_sphere"]

F64 = NDArray[np.float64]
#: Part of the sphere's image radius searched for the highlight: the limb mixes sphere and
#: background in one pixel and the mapping from pixels to normals is singular there.
SEARCH_RADIUS = 0.97


@dataclass(frozen=True)
class MirrorSphere:
    """A mirror sphere of ``radius`` (scene units) centred at ``centre`` in the rig frame."""

    radius: float
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise InputError(f"mirror sphere radius must be positive, got {self.radius}")

    def hit(self, origin: F64, rays: F64) -> tuple[NDArray[np.bool_], F64, F64]:
        """Where rays (N, 3) from ``origin`` (3,) meet the sphere.

        Returns
        -------
        hit : (N,) bool
        miss : (N,) float, closest approach of the ray to the centre over the radius
        points : (N, 3) float, first intersection (the origin where there is none)
        """
        offset = origin - np.asarray(self.centre, dtype=np.float64)
        b = rays @ offset
        closest2 = np.maximum(offset @ offset - b * b, 0.0)
        disc = self.radius**2 - closest2
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        hit = (disc >= 0) & (t > 0)
        points = origin + np.where(hit, t, 0.0)[:, None] * rays
        return hit, np.sqrt(closest2) / self.radius, points


def _sphere_window(
    camera: CalibratedCamera, sphere: MirrorSphere
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Rows, cols of a pixel window holding the sphere and its search mask (window-shaped)."""
    width, height = camera.intrinsics.width, camera.intrinsics.height
    rows, cols = np.mgrid[0:height, 0:width]
    rays = camera.rays(cols.ravel() + 0.5, rows.ravel() + 0.5)
    hit, miss, _ = sphere.hit(camera.position, rays)
    inside = (hit & (miss <= SEARCH_RADIUS)).reshape(height, width)
    if not inside.any():
        raise InputError(
            f"the mirror sphere (radius {sphere.radius} at {sphere.centre}) is not in the "
            f"camera's view"
        )
    r, c = np.nonzero(inside)
    r0, r1, c0, c1 = r.min(), r.max() + 1, c.min(), c.max() + 1
    window_rows = np.arange(r0, r1)
    window_cols = np.arange(c0, c1)
    return window_rows, window_cols, inside[r0:r1, c0:c1]


def find_highlight(
    luminance: NDArray[np.floating],
    mask: NDArray[np.bool_],
    *,
    name: str = "image",
    min_contrast: float = 4.0,
) -> tuple[float, float]:
    """Centroid of the brightest highlight inside ``mask``.

    Parameters
    ----------
    luminance : ndarray (H, W), linear
    mask : ndarray (H, W), bool, where to look (the sphere)
    name : str, how errors name the image
    min_contrast : float
        The highlight's peak must exceed the masked region's median by this factor (and by a
        margin above noise), or there is no highlight.

    Returns
    -------
    col, row : float, pixel coordinates (pixel (i, j) centred at (j + 0.5, i + 0.5))
    """
    values = np.where(mask, luminance, -np.inf)
    background = float(np.median(luminance[mask]))
    peak_index = np.unravel_index(int(np.argmax(values)), values.shape)
    peak = float(values[peak_index])
    spread = float(np.percentile(luminance[mask], 75) - np.percentile(luminance[mask], 25))
    if not peak > max(min_contrast * background, background + 10.0 * spread, 1e-6):
        raise InputError(
            f"{name}: no highlight on the mirror sphere (brightest {peak:.4g} against a "
            f"background of {background:.4g}); is the light on and reflected toward the camera?"
        )
    # The highlight is the bright blob holding the peak; one pixel of dilation keeps the
    # partly covered pixels of its rim, whose weights carry the sub-pixel position.
    threshold = background + 0.25 * (peak - background)
    bright = ((values > threshold) & mask).astype(np.uint8)
    _, labels = cv2.connectedComponents(bright, connectivity=8)
    blob = (labels == labels[peak_index]).astype(np.uint8)
    blob = cv2.dilate(blob, np.ones((3, 3), np.uint8)).astype(bool) & mask
    weights = np.where(blob, np.maximum(luminance - background, 0.0), 0.0)
    rows, cols = np.nonzero(weights)
    w = weights[rows, cols]
    return float((cols + 0.5) @ w / w.sum()), float((rows + 0.5) @ w / w.sum())


def light_directions_from_mirror_sphere(
    images: Sequence[ImageInput],
    camera: CalibratedCamera | PinholeCamera,
    sphere: MirrorSphere,
    *,
    light_distance: float | None = None,
    names: Sequence[str] | None = None,
    min_contrast: float = 4.0,
) -> F64:
    """Directions toward the lights, one per image of the mirror sphere.

    Parameters
    ----------
    images : sequence of arrays (H, W) or (H, W, 3) or paths
        One light each; uint8 is sRGB-decoded, uint16 and floats are linear.
    camera : CalibratedCamera or PinholeCamera, the camera that took them
    sphere : MirrorSphere, its place and radius in the rig frame
    light_distance : float, optional
        For point lights at this distance from the origin: the direction from the origin to the
        light; None for distant lights (the direction of the reflected ray).
    names : sequence of str, optional, how errors name the images
    min_contrast : float, see :func:`find_highlight`

    Returns
    -------
    ndarray, shape (T, 3), float64, unit vectors in the rig frame

    Raises
    ------
    InputError
        An image without a highlight (named), or the sphere out of view.
    """
    cam = as_calibrated(camera)
    labels = [f"mirror-sphere image {i}" for i in range(len(images))] if names is None else names
    if len(labels) != len(images):
        raise InputError(f"got {len(labels)} names for {len(images)} images")
    window_rows, window_cols, mask = _sphere_window(cam, sphere)
    r0, c0 = int(window_rows[0]), int(window_cols[0])
    window = (slice(r0, r0 + mask.shape[0]), slice(c0, c0 + mask.shape[1]))
    directions = np.empty((len(images), 3))
    for t, (image, label) in enumerate(zip(images, labels, strict=True)):
        array = load_image(image, label)
        if (array.shape[1], array.shape[0]) != (cam.intrinsics.width, cam.intrinsics.height):
            raise InputError(
                f"{label}: size {array.shape[1]}x{array.shape[0]} differs from the camera's"
            )
        luminance = linear_luminance(array, label)[window]
        col, row = find_highlight(luminance, mask, name=label, min_contrast=min_contrast)
        ray = cam.rays([col + c0], [row + r0])
        hit, _, point = sphere.hit(cam.position, ray)
        if not hit[0]:
            raise InputError(
                f"{label}: the highlight at ({col + c0:.1f}, {row + r0:.1f}) is off the sphere"
            )
        normal = (point[0] - np.asarray(sphere.centre)) / sphere.radius
        reflected = ray[0] - 2.0 * float(ray[0] @ normal) * normal
        if light_distance is not None:
            reflected = _toward_light(point[0], reflected, light_distance, label)
        directions[t] = reflected / np.linalg.norm(reflected)
    return directions


def _toward_light(point: F64, direction: F64, distance: float, name: str) -> F64:
    """Where the ray ``point + s direction`` (s > 0) is ``distance`` from the origin."""
    b = float(point @ direction)
    disc = b * b - (float(point @ point) - distance * distance)
    if not distance > float(np.linalg.norm(point)) or disc < 0:
        raise InputError(f"{name}: light distance {distance} is inside the mirror sphere's reach")
    return point + (-b + math.sqrt(disc)) * direction
