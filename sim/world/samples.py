"""The surface samples of a Mitsuba world: where a reflectance field of it is measured."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.point_spacing import point_spacing
from sim.scenes import MAX_POINTS
from sim.world.files import World
from sim.world.mesh import sample_surface

__all__ = ["WorldSamples", "world_samples"]


@dataclass(frozen=True, eq=False)
class WorldSamples:
    """Surface samples of a world, rig frame.

    Attributes
    ----------
    points : ndarray, shape (P, 3), float64, on the world's triangles, scene units
    normals : ndarray, shape (P, 3), float64, unit shading normals (interpolated vertex normals)
    spacing : float, sqrt(area per sample) as :func:`core.point_spacing.point_spacing` estimates
        it from the points (what splatting the field will assume), scene units
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    spacing: float

    @property
    def count(self) -> int:
        """Number of samples, P."""
        return int(self.points.shape[0])


def world_samples(world: World, points: int, seed: int = 0) -> WorldSamples:
    """``points`` samples placed uniformly by area on the mesh Mitsuba renders.

    Parameters
    ----------
    world : World
    points : int, 2 .. MAX_POINTS
    seed : int, of the placement (the same seed gives the same samples)

    Returns
    -------
    WorldSamples

    Raises
    ------
    InputError
        ``points`` out of range.
    """
    if not 2 <= points <= MAX_POINTS:
        raise InputError(f"points must be between 2 and {MAX_POINTS}, got {points}")
    positions, normals = sample_surface(world.mesh, points, seed)
    return WorldSamples(positions, normals, point_spacing(positions))
