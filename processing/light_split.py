"""Which part of a panorama's light the light-stage sum gathers well, and which needs predicting.

The light-stage sum (Debevec et al. 2000) weights each measured image by the panorama's light
over that light's Voronoi cell. It is a quadrature of the sphere: exact for light that varies
slowly over a cell (its errors cancel between neighbouring cells), wrong for light concentrated
within a cell (a sun or a lamp is moved to the cell's measured light, and its highlight and
shadows with it) and for light outside the region the measured lights surround (handed to the
lowest lights). The split gives each part to what relights it well:

``smooth``
    each pixel's radiance up to ``contrast`` x the mean radiance of its cell, inside the
    measured region: the sum's;
``sharp``
    the excess above that, and all of the light outside the measured region: predicted at its
    own direction by a rung that models the lights between and beyond the measured ones.

``smooth + sharp`` is the panorama, so no light is lost or counted twice. A uniform sky is all
``smooth`` (the relighting is the sum itself); a sky with a sun is mostly ``sharp``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from core.directions import panorama_directions, panorama_row_solid_angles
from core.errors import InputError
from processing.lights import gather_cells, nearest_sample_labels
from processing.measured_region import MeasuredRegion

__all__ = ["CONTRAST", "LightSplit", "LightSplitter", "outside_pixels", "split_light"]

#: A pixel brighter than this many times its cell's mean radiance holds concentrated light:
#: above it a cell's light no longer averages out over the cell. 2 and 4 were measured on the
#: path-traced scenes of docs/evaluation.md: 2 as good or better in most cases (by up to 0.9
#: points of relative error under the studio's low lamps), the two within 0.1 points under the
#: broad skies on the Fibonacci domes.
CONTRAST = 2.0


@dataclass(frozen=True)
class LightSplit:
    """A panorama split between the light-stage sum and a prediction (see the module).

    Attributes
    ----------
    smooth : ndarray, shape (H, 2H, 3), float32, linear radiance for the sum
    sharp : ndarray, shape (H, 2H, 3), float32, linear radiance to predict
    smooth_cells : ndarray, shape (N, 3), float64, the smooth light gathered into each
        measured light's Voronoi cell (radiance x sr): the light-stage sum's weights
    sharp_share : float, the sharp part's share of the light (solid-angle weighted), in [0, 1]
    """

    smooth: NDArray[np.float32]
    sharp: NDArray[np.float32]
    smooth_cells: NDArray[np.float64]
    sharp_share: float


def outside_pixels(directions: NDArray[np.floating], height: int) -> NDArray[np.bool_]:
    """Which pixels of an H x 2H panorama lie outside the region the measured lights surround.

    Parameters
    ----------
    directions : ndarray, shape (N, 3), float64, the measured lights (the panorama's frame)
    height : int, the panorama's rows

    Returns
    -------
    ndarray, shape (H, 2H), bool
    """
    towards = panorama_directions(height, 2 * height).reshape(-1, 3)
    region = MeasuredRegion.build(np.asarray(directions, dtype=np.float64))
    return region.outside(towards).reshape(height, 2 * height)


class LightSplitter:
    """Splits H x 2H panoramas over one set of measured lights (see the module).

    The cells and the region are found once: a relighting that turns a panorama splits it
    anew for every yaw.

    Parameters
    ----------
    directions : ndarray, shape (N, 3), float64, the measured lights (unit vectors, the
        panorama's frame)
    height : int, the panoramas' rows
    contrast : float, > 1, keyword-only; the brightness over a cell's mean above which light
        counts as concentrated
    """

    def __init__(
        self, directions: NDArray[np.floating], height: int, *, contrast: float = CONTRAST
    ) -> None:
        if not contrast > 1.0:
            raise InputError(f"the contrast of concentrated light must be above 1, got {contrast}")
        self.shape = (height, 2 * height)
        self.contrast = contrast
        self.count = len(np.asarray(directions))
        self.labels = nearest_sample_labels(directions, height, 2 * height)
        self.outside = outside_pixels(directions, height)
        self.omega = panorama_row_solid_angles(height, 2 * height)

    def split(self, rgb: NDArray[np.floating]) -> LightSplit:
        """Split ``rgb`` (H, 2H, 3), linear radiance, non-negative."""
        image = np.asarray(rgb, dtype=np.float32)
        if image.shape != (*self.shape, 3):
            raise InputError(f"the panorama is {image.shape}, the splitter's {(*self.shape, 3)}")
        # A cell's mean over all of it: light filling only part of a cell (a cell at a blocked
        # horizon, at the edge of a bright window) is uneven within it, which the sum misplaces.
        # Per channel: a coloured lamp is concentrated in its own channel.
        gathered, area = gather_cells(image, self.labels, self.count)
        ceiling = (self.contrast * gathered / np.maximum(area, 1e-300)[:, None]).astype(np.float32)
        smooth = np.empty_like(image)
        sharp = np.empty_like(image)
        smooth_cells = np.zeros((self.count, 3), dtype=np.float64)
        total, kept = _split_pixels(
            np.ascontiguousarray(image),
            self.labels,
            ceiling,
            self.outside,
            self.omega,
            smooth,
            sharp,
            smooth_cells,
        )
        return LightSplit(
            smooth,
            sharp,
            smooth_cells,
            min(max(kept / total if total > 0 else 0.0, 0.0), 1.0),
        )


@numba.njit(cache=True)
def _split_pixels(
    image: NDArray[np.float32],
    labels: NDArray[np.int32],
    ceiling: NDArray[np.float32],
    outside: NDArray[np.bool_],
    omega: NDArray[np.float64],
    smooth: NDArray[np.float32],
    sharp: NDArray[np.float32],
    smooth_cells: NDArray[np.float64],
) -> tuple[float, float]:
    """Fill ``smooth`` and ``sharp`` (H, W, 3) and gather ``smooth_cells`` (N, 3) in one pass.

    ``ceiling`` (N, 3): each cell's highest smooth radiance; ``omega`` (H,): a pixel's solid
    angle per row. Returns the whole panorama's and the sharp part's radiance x sr, summed over
    the channels (one pass: a turning panorama is split anew every frame).
    """
    total = 0.0
    kept = 0.0
    height, width = labels.shape
    for i in range(height):
        w = omega[i]
        for j in range(width):
            cell = labels[i, j]
            for c in range(3):
                value = image[i, j, c]
                part = np.float32(0.0) if outside[i, j] else min(value, ceiling[cell, c])
                smooth[i, j, c] = part
                sharp[i, j, c] = value - part
                smooth_cells[cell, c] += part * w
                total += value * w
                kept += (value - part) * w
    return total, kept

def split_light(
    rgb: NDArray[np.floating],
    directions: NDArray[np.floating],
    *,
    contrast: float = CONTRAST,
) -> LightSplit:
    """Split a panorama's light between the light-stage sum and a prediction.

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), linear radiance, non-negative
    directions : ndarray, shape (N, 3), float64, the measured lights (unit vectors, the
        panorama's frame)
    contrast : float, > 1, keyword-only; the brightness over a cell's mean above which light
        counts as concentrated

    Returns
    -------
    LightSplit
    """
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[1] != 2 * image.shape[0]:
        raise InputError(f"a panorama must have shape (H, 2H, 3), got {image.shape}")
    return LightSplitter(directions, image.shape[0], contrast=contrast).split(image)
