"""Directional lights standing for an environment: the one light-set type every engine takes.

An environment panorama becomes K directional lights, each carrying the light of one cell of
the panorama (radiance x solid angle, summed): the Voronoi cells of sampled directions
(``processing.lights.disassemble_lights``) or the blocks of a pre-filter grid
(:func:`grid_lights`). Lights of another origin (held-out measured lights) carry no cells.

The lights a capture MEASURED under are checked here too (:func:`measured_lights_problem`): a
set that no fit or relighting can use (every light in one direction, every light at or below
the horizon of a base that blocks it) is refused where an ``.lp`` capture is imported, a field
is opened for relighting and a fit starts.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from core.directions import (
    angle_between,
    angles_deg_from_direction,
    panorama_azimuths,
    panorama_directions,
    panorama_inclinations,
    panorama_row_solid_angles,
    panorama_solid_angles,
)
from core.errors import DatasetError, InputError

__all__ = [
    "HORIZON_DEG",
    "ONE_DIRECTION_DEG",
    "LightSet",
    "check_measured_lights",
    "grid_lights",
    "measured_lights_problem",
]

#: Measured lights all within this angle (degrees) of their mean direction are one direction.
#: A handheld RTI capture's narrowest cone is tens of degrees wide; a light source that did not
#: move (a wrong ``.lp`` file, a stuck gantry) repeats one direction to within its noise.
ONE_DIRECTION_DEG = 1.0
#: A light must rise more than this (degrees) above the horizon to light a surface lying on
#: a base: grazing at less, it gives the surface almost nothing (cos 89 deg = 0.017) and from
#: below the base blocks it. Real raking-light captures put some lights at 5-15 degrees, never
#: all of them under one.
HORIZON_DEG = 1.0


@dataclass(frozen=True)
class LightSet:
    """K directional lights that together carry the light of an environment.

    Attributes
    ----------
    directions : ndarray, shape (K, 3), float64
        Unit vectors toward each light, rig frame.
    rgb : ndarray, shape (K, 3), float64
        Light of each direction: the sum of radiance x solid angle over its cell (radiance x sr).
    solid_angle_sr : ndarray, shape (K,), float64, or None
        Solid angle of each light's cell (the cells of a whole panorama sum to 4 pi); None for
        lights that did not come from a panorama.
    labels : ndarray, shape (H, W), int32, or None
        Index of the light that owns each panorama pixel; -1 for pixels of cells dropped by
        :meth:`nonempty` (they hold no light). None for lights not from a panorama.
    """

    directions: NDArray[np.float64]
    rgb: NDArray[np.float64]
    solid_angle_sr: NDArray[np.float64] | None = None
    labels: NDArray[np.int32] | None = None

    def __post_init__(self) -> None:
        if self.directions.ndim != 2 or self.directions.shape[1] != 3:
            raise InputError(f"light directions must be (K, 3), got {self.directions.shape}")
        if self.rgb.shape != self.directions.shape:
            raise InputError(
                f"light rgb {self.rgb.shape} does not match directions {self.directions.shape}"
            )

    @property
    def k(self) -> int:
        """Number of lights."""
        return int(self.directions.shape[0])

    def mean_radiance(self) -> NDArray[np.float64]:
        """Mean radiance of each cell, rgb / solid angle; shape (K, 3) (zero for empty cells)."""
        if self.solid_angle_sr is None:
            raise InputError("these lights have no cells: they did not come from a panorama")
        area = self.solid_angle_sr[:, None]
        return np.divide(self.rgb, area, out=np.zeros_like(self.rgb), where=area > 0)

    def to_panorama(self) -> NDArray[np.float32]:
        """The disassembled environment: each pixel filled with its cell's mean radiance."""
        if self.labels is None:
            raise InputError("these lights have no cells: they did not come from a panorama")
        # Row K is for the pixels of dropped (empty) cells, labelled -1.
        filled = np.vstack([self.mean_radiance(), np.zeros((1, 3))]).astype(np.float32)
        return filled[self.labels]

    def nonempty(self) -> LightSet:
        """The lights that carry any light (the others add nothing to any sum over lights)."""
        keep = self.rgb.sum(axis=1) > 0
        if keep.all():
            return self
        labels = None
        if self.labels is not None:
            index = np.full(self.k + 1, -1, dtype=np.int32)
            index[np.flatnonzero(keep)] = np.arange(int(keep.sum()), dtype=np.int32)
            labels = index[self.labels]
        return LightSet(
            np.ascontiguousarray(self.directions[keep]),
            np.ascontiguousarray(self.rgb[keep]),
            None if self.solid_angle_sr is None else self.solid_angle_sr[keep],
            labels,
        )


def grid_lights(rgb: NDArray[np.floating], grid_height: int | None = None) -> LightSet:
    """The panorama summed exactly into ``grid_height`` x 2 ``grid_height`` blocks.

    Each block becomes one light at its energy-weighted centroid direction carrying the block's
    radiance x solid angle: the ground truth's pre-filter, and the grid lighting of the models.
    Blocks are as equal as integer rows and columns allow.

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), linear radiance
    grid_height : int, optional
        Rows of blocks, >= 1; None, or H and more, for every pixel as its own light.

    Returns
    -------
    LightSet
        Every block, empty ones included (:meth:`LightSet.nonempty` drops those).
    """
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[1] != 2 * image.shape[0]:
        raise InputError(f"a panorama must have shape (H, 2H, 3), got {image.shape}")
    height, width = image.shape[:2]
    if grid_height is None or grid_height >= height:
        omega = panorama_solid_angles(height, width)
        energy = image.astype(np.float64) * omega[:, :, None]
        labels = np.arange(height * width, dtype=np.int32).reshape(height, width)
        directions = panorama_directions(height, width).reshape(-1, 3)
        return LightSet(directions, energy.reshape(-1, 3), omega.ravel(), labels)
    if grid_height < 1:
        raise InputError(f"grid height must be at least 1, got {grid_height}")
    if image.dtype not in (np.float32, np.float64):
        image = image.astype(np.float64)
    rows = (np.arange(grid_height + 1) * height) // grid_height
    cols = (np.arange(2 * grid_height + 1) * width) // (2 * grid_height)
    theta = panorama_inclinations(height)
    phi = panorama_azimuths(width)
    light, moments, area = _grid_blocks(
        np.ascontiguousarray(image),
        rows,
        cols,
        panorama_row_solid_angles(height, width),
        np.sin(theta),
        np.cos(theta),
        np.cos(phi),
        np.sin(phi),
    )
    centroids = moments / np.linalg.norm(moments, axis=1, keepdims=True)
    block_rows = np.repeat(np.arange(grid_height, dtype=np.int32), np.diff(rows))
    block_cols = np.repeat(np.arange(2 * grid_height, dtype=np.int32), np.diff(cols))
    labels = block_rows[:, None] * np.int32(2 * grid_height) + block_cols[None, :]
    return LightSet(centroids, light, area, labels)


@numba.njit(cache=True, parallel=True)
def _grid_blocks(
    image: NDArray[np.floating],
    rows: NDArray[np.int64],
    cols: NDArray[np.int64],
    omega: NDArray[np.float64],
    sin_theta: NDArray[np.float64],
    cos_theta: NDArray[np.float64],
    cos_phi: NDArray[np.float64],
    sin_phi: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per block: radiance x sr (B, 3), the energy-weighted direction sum (B, 3), sr (B,).

    One pass over the pixels, a row of blocks per thread (rows of blocks share no block);
    the directions are :func:`core.directions.panorama_directions`' from per-row and
    per-column sines, so no (H, W, 3) array is made. A pixel without light weighs 1e-30 x its
    solid angle: an empty block's centroid is its geometric centre.
    """
    grid_rows = rows.size - 1
    grid_cols = cols.size - 1
    light = np.zeros((grid_rows * grid_cols, 3))
    moments = np.zeros((grid_rows * grid_cols, 3))
    area = np.zeros(grid_rows * grid_cols)
    for block_row in numba.prange(grid_rows):
        for i in range(rows[block_row], rows[block_row + 1]):
            w = omega[i]
            for block_col in range(grid_cols):
                b = block_row * grid_cols + block_col
                area[b] += w * (cols[block_col + 1] - cols[block_col])
                for j in range(cols[block_col], cols[block_col + 1]):
                    r = image[i, j, 0] * w
                    g = image[i, j, 1] * w
                    u = image[i, j, 2] * w
                    light[b, 0] += r
                    light[b, 1] += g
                    light[b, 2] += u
                    weight = r + g + u + 1e-30 * w
                    moments[b, 0] += weight * sin_theta[i] * cos_phi[j]
                    moments[b, 1] += weight * sin_theta[i] * sin_phi[j]
                    moments[b, 2] += weight * cos_theta[i]
    return light, moments, area


def measured_lights_problem(directions: NDArray[np.floating], *, blocked_below: bool) -> str | None:
    """Why a capture's measured lights cannot be fitted or relit, or None when they can.

    Only what truly cannot work is named (the thresholds are far from any real capture):

    - every light within :data:`ONE_DIRECTION_DEG` of one direction (two lights or more): a
      sample's answer to any other light is unknown;
    - with ``blocked_below`` (the base hides what lies below the horizon), every light at
      most :data:`HORIZON_DEG` above the horizon (rig z = 0): no light reaches the object.

    Narrow sets that still answer something pass: a single ring of lights (one elevation; a
    PTM's constant and squared terms share it), a handheld capture's small cone, lights along
    one arc (a single view's normals across the arc's plane are undetermined, yet
    interpolation among the lights and the least-squares fits still relight along it).

    Parameters
    ----------
    directions : ndarray, shape (T, 3)
        Unit vectors toward the lights, rig frame (z up: the horizon is z = 0).
    blocked_below : bool, the base blocks the light from below the horizon

    Returns
    -------
    str or None
        The problem in words (the light count, the direction or the highest light, what is
        needed).
    """
    lights = np.asarray(directions, dtype=np.float64)
    count = int(lights.shape[0])
    if lights.ndim != 2 or lights.shape[1] != 3 or count < 2 or not np.isfinite(lights).all():
        return None  # shapes, a single light and NaN are refused by their own checks
    lights = lights / np.linalg.norm(lights, axis=1, keepdims=True)
    mean = lights.sum(axis=0)
    if np.linalg.norm(mean) > 0.5 * count:  # opposite lights have no mean direction
        widest = float(np.rad2deg(angle_between(lights, mean).max()))
        if widest <= ONE_DIRECTION_DEG:
            azimuth, inclination = angles_deg_from_direction(mean)
            return (
                f"all {count} lights are within {ONE_DIRECTION_DEG:g} degree of one direction "
                f"(azimuth {float(azimuth):.1f}, inclination {float(inclination):.1f} deg; the "
                f"farthest {widest:.2f} deg from it): a relightable fit needs lights spread "
                "over the dome"
            )
    highest = float(np.rad2deg(np.arcsin(np.clip(lights[:, 2].max(), -1.0, 1.0))))
    if blocked_below and highest <= HORIZON_DEG:
        return (
            f"every one of the {count} lights is at or below the horizon (elevation <= 0; the "
            f"highest at {round(highest, 1) + 0.0:.1f} deg): the base blocks the light from below "
            "(below_horizon 'blocked'), so none reaches the object; capture lights above the "
            "horizon, or state --below-horizon open if nothing blocks the light from below"
        )
    return None


def check_measured_lights(
    where: str | os.PathLike[str],
    directions: NDArray[np.floating],
    *,
    blocked_below: bool,
) -> None:
    """:func:`measured_lights_problem` as a DatasetError naming ``where`` (a file, a store).

    Raises
    ------
    DatasetError
        The lights cannot be fitted or relit (one direction, none above a blocking horizon).
    """
    problem = measured_lights_problem(directions, blocked_below=blocked_below)
    if problem is not None:
        raise DatasetError(f"{os.fspath(where)}: {problem}")
