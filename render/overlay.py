"""Pictures of sampled environments: samples and Voronoi cells over the panorama."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from core.directions import panorama_pixel_from_direction
from core.errors import InputError
from core.light_set import LightSet
from render.tonemap import tone_mapped_8bit

__all__ = ["cell_borders", "disassembled_picture", "sample_overlay"]

BORDER_RGB = (0, 230, 255)
SAMPLE_RGB = (255, 0, 200)


def cell_borders(labels: NDArray[np.integer]) -> NDArray[np.bool_]:
    """Pixels of an (H, W) label map whose right or lower neighbour has another label.

    The right neighbour wraps around the panorama's seam.
    """
    right = labels != np.roll(labels, -1, axis=1)
    below = np.zeros_like(right)
    below[:-1] = labels[:-1] != labels[1:]
    return right | below


def sample_overlay(
    rgb: NDArray[np.floating], lights: LightSet, *, exposure: float | None = None
) -> NDArray[np.uint8]:
    """The tone-mapped panorama with Voronoi cell borders and sample points; (H, W, 3) uint8."""
    height, width = rgb.shape[:2]
    picture = tone_mapped_8bit(rgb, exposure=exposure)
    if lights.labels is None:
        raise InputError("the lights have no cells to draw: they did not come from a panorama")
    picture[cell_borders(lights.labels)] = BORDER_RGB
    rows, cols = panorama_pixel_from_direction(lights.directions, height, width)
    radius = max(2, round(height / 170))
    for r, c in zip(rows, cols, strict=True):
        centre = (round(float(c)), round(float(r)))
        cv2.circle(picture, centre, radius + 1, (0, 0, 0), -1, cv2.LINE_AA)
        cv2.circle(picture, centre, radius, SAMPLE_RGB, -1, cv2.LINE_AA)
    return picture


def disassembled_picture(lights: LightSet, *, exposure: float) -> NDArray[np.uint8]:
    """Each Voronoi cell filled with its light's mean radiance, tone-mapped; (H, W, 3) uint8."""
    return tone_mapped_8bit(lights.to_panorama(), exposure=exposure)
