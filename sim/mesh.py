"""Surface samples from a user's triangle mesh (PLY, OBJ, STL, ... through pyvista/VTK)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from core.errors import InputError
from sim.materials import Material
from sim.scenes import MAX_POINTS, SurfaceSamples, uniform_material

__all__ = ["sample_mesh"]


def sample_mesh(
    path: str | os.PathLike[str], points: int, material: Material, *, seed: int = 0
) -> SurfaceSamples:
    """Sample ``points`` surface points uniformly by area from a triangle mesh file.

    Normals are the triangles' geometric normals, oriented as the file's vertex order says
    (counter-clockwise seen from outside for a well-formed closed mesh).

    Raises
    ------
    InputError
        Missing or unreadable file, no triangles, degenerate area, or a bad point count.
    """
    import pyvista as pv  # VTK is heavy; load it only when a mesh is asked for

    file = Path(path)
    if not 1 <= points <= MAX_POINTS:
        raise InputError(f"points must be between 1 and {MAX_POINTS}, got {points}")
    if not file.is_file():
        raise InputError(f"{file}: no such mesh file")
    try:
        mesh = pv.read(str(file))
    except Exception as error:  # VTK readers raise a variety of types
        raise InputError(f"{file}: cannot read as a mesh: {error}") from error
    if isinstance(mesh, pv.MultiBlock):
        mesh = mesh.combine()
    if not isinstance(mesh, pv.PolyData):
        mesh = mesh.extract_surface(algorithm="dataset_surface")
    surface = mesh.triangulate()
    if surface.n_cells == 0:
        raise InputError(f"{file}: the mesh has no triangles")
    triangles = np.asarray(surface.faces).reshape(-1, 4)[:, 1:]
    corners = np.asarray(surface.points, dtype=np.float64)[triangles]  # (T, 3, 3)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    doubled_area = np.linalg.norm(cross, axis=1)
    if not doubled_area.sum() > 0:
        raise InputError(f"{file}: the mesh has zero surface area")
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(triangles), size=points, p=doubled_area / doubled_area.sum())
    # Uniform barycentric coordinates (sqrt trick).
    r1 = np.sqrt(rng.random(points))
    r2 = rng.random(points)
    a, b, c = corners[chosen, 0], corners[chosen, 1], corners[chosen, 2]
    samples = (1 - r1)[:, None] * a + (r1 * (1 - r2))[:, None] * b + (r1 * r2)[:, None] * c
    normals = cross[chosen] / doubled_area[chosen, None]
    return SurfaceSamples(
        points=samples.astype(np.float32),
        normals=normals.astype(np.float32),
        spacing=float(np.sqrt(0.5 * doubled_area.sum() / points)),
        **uniform_material(points, material),
    )
