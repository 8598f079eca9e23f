"""Surface samples from a user's triangle mesh (PLY, OBJ, STL, ... through pyvista/VTK)."""

from __future__ import annotations

import os

import numpy as np

from core.errors import InputError
from sim.materials import Material
from sim.scenes import MAX_POINTS, SurfaceSamples, uniform_material
from sim.world.mesh import read_mesh_file, sample_surface

__all__ = ["sample_mesh"]


def sample_mesh(
    path: str | os.PathLike[str], points: int, material: Material, *, seed: int = 0
) -> SurfaceSamples:
    """Sample ``points`` surface points uniformly by area from a triangle mesh file.

    The mesh is read and sampled as a path-traced world's (:mod:`sim.world.mesh`, the one home
    of meshes): normals are the file's vertex normals (else area-weighted face normals)
    interpolated across each triangle.

    Raises
    ------
    InputError
        Missing or unreadable file, no triangles, degenerate area, or a bad point count.
    """
    if not 1 <= points <= MAX_POINTS:
        raise InputError(f"points must be between 1 and {MAX_POINTS}, got {points}")
    mesh = read_mesh_file(path)
    samples, normals = sample_surface(mesh, points, seed)
    return SurfaceSamples(
        points=samples.astype(np.float32),
        normals=normals.astype(np.float32),
        spacing=float(np.sqrt(mesh.areas.sum() / points)),
        **uniform_material(points, material),
    )
