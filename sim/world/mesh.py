"""The triangle mesh of a Mitsuba world, and what is done with any mesh.

Every world is one triangle mesh with unit vertex normals (smooth shading) and, where the shape
has a natural parameterisation, texture coordinates. The same arrays go to Mitsuba (as an
``mi.Mesh``, :func:`mitsuba_mesh`) and to the field's surface samples (:func:`sample_surface`),
so the samples lie on the very triangles Mitsuba renders, with the normals it shades with.
Meshes come from the built-in shapes (:mod:`sim.world.shapes`) or from PLY files
(:func:`read_mesh_file`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

__all__ = [
    "TriangleMesh",
    "mitsuba_mesh",
    "oriented_faces",
    "read_mesh_file",
    "sample_surface",
    "unit_normals",
    "vertex_normals",
]


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """An indexed triangle mesh, rig frame.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3), float64, scene units
    faces : ndarray, shape (F, 3), int64, vertex indices, counter-clockwise seen from outside
    normals : ndarray, shape (V, 3), float64, unit vertex normals (shading normals)
    uv : ndarray, shape (V, 2), float64, texture coordinates, or None when the shape has none
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    normals: NDArray[np.float64]
    uv: NDArray[np.float64] | None

    @cached_property
    def areas(self) -> NDArray[np.float64]:
        """Area of every triangle; shape (F,), float64, square scene units."""
        corners = self.vertices[self.faces]
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        return 0.5 * np.linalg.norm(cross, axis=1)

    @cached_property
    def bounding_radius(self) -> float:
        """Largest distance of a vertex from the origin, scene units."""
        return float(np.linalg.norm(self.vertices, axis=1).max())


def oriented_faces(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], normals: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Faces (F', 3) without degenerate ones, each wound so its normal agrees with its vertices'.

    Grids collapse to a point at poles; those zero-area triangles would only cost Mitsuba time
    and give the sampler nothing to place.
    """
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    keep = np.linalg.norm(cross, axis=1) > 1e-14
    faces, cross = faces[keep], cross[keep]
    agree = np.einsum("ij,ij->i", cross, normals[faces].sum(axis=1)) >= 0.0
    return np.where(agree[:, None], faces, faces[:, [0, 2, 1]])


def unit_normals(vectors: NDArray[np.float64], where: str) -> NDArray[np.float64]:
    """The vectors (N, 3) scaled to unit length; a zero vector is an InputError at ``where``."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    if not np.all(length > 0):
        raise InputError(f"{where}: {int((length == 0).sum())} vertex normals have zero length")
    return vectors / length


def vertex_normals(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], where: str = "mesh"
) -> NDArray[np.float64]:
    """Unit vertex normals (V, 3): the area-weighted mean of the faces' normals around each."""
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    summed = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(summed, faces[:, k], cross)
    return unit_normals(summed, where)


def read_mesh_file(path: str | os.PathLike[str], *, scale: float = 1.0) -> TriangleMesh:
    """A triangle mesh from a file VTK reads (PLY, OBJ, STL, ...), positions times ``scale``.

    Vertex normals are the file's when it has them, else area-weighted averages of the face
    normals (smooth shading across every edge); texture coordinates are the file's, or None.

    Raises
    ------
    InputError
        The file is missing or unreadable, or has no triangles.
    """
    import pyvista as pv  # VTK is heavy; load it only when a mesh file is asked for

    file = Path(path)
    if not file.is_file():
        raise InputError(f"{file}: no such mesh file")
    try:
        surface = pv.read(str(file))
    except Exception as error:  # VTK readers raise a variety of types
        raise InputError(f"{file}: cannot read as a mesh: {error}") from error
    if isinstance(surface, pv.MultiBlock):
        surface = surface.combine()
    if not isinstance(surface, pv.PolyData):
        surface = surface.extract_surface(algorithm="dataset_surface")
    if surface.n_cells == 0:
        raise InputError(f"{file}: the file holds no polygons")
    file_normals = surface.point_data.active_normals
    texture = surface.active_texture_coordinates
    surface = surface.triangulate()
    faces = np.asarray(surface.faces).reshape(-1, 4)[:, 1:].astype(np.int64)
    vertices = scale * np.asarray(surface.points, dtype=np.float64)
    if file_normals is not None:
        normals = unit_normals(np.asarray(file_normals, dtype=np.float64), str(file))
    else:
        normals = vertex_normals(vertices, faces, str(file))
    uv = None if texture is None else np.asarray(texture, dtype=np.float64)
    mesh = TriangleMesh(vertices, faces, normals, uv)
    if not np.any(mesh.areas > 0):
        raise InputError(f"{file}: every triangle has zero area")
    return TriangleMesh(vertices, faces[mesh.areas > 0], normals, uv)


def sample_surface(
    mesh: TriangleMesh, count: int, seed: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``count`` points uniformly by area on the mesh, with their interpolated unit normals.

    Parameters
    ----------
    mesh : TriangleMesh
    count : int, >= 1
    seed : int, of the random placement (the same seed gives the same samples)

    Returns
    -------
    points, normals : ndarray, shape (count, 3), float64; normals are the vertex normals
        interpolated barycentrically and normalised, as Mitsuba shades.
    """
    rng = np.random.default_rng(seed)
    areas = mesh.areas
    chosen = rng.choice(len(areas), size=count, p=areas / areas.sum())
    # Uniform barycentric coordinates by the square-root warp of the unit square.
    root = np.sqrt(rng.random(count))
    second = rng.random(count)
    weights = np.stack([1.0 - root, root * (1.0 - second), root * second], axis=1)
    corners = mesh.faces[chosen]
    points = np.einsum("pk,pkj->pj", weights, mesh.vertices[corners])
    normals = np.einsum("pk,pkj->pj", weights, mesh.normals[corners])
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def mitsuba_mesh(mi: Any, mesh: TriangleMesh, bsdf: Any, name: str = "world") -> Any:
    """The mesh as an ``mi.Mesh`` with vertex normals, uv (when present) and ``bsdf``.

    Parameters
    ----------
    mi : the ``mitsuba`` module with a variant set
    mesh : TriangleMesh
    bsdf : a loaded Mitsuba BSDF object
    name : the shape's name inside Mitsuba (shown in its messages)
    """
    properties = mi.Properties()
    properties["bsdf"] = bsdf
    shape = mi.Mesh(
        name, len(mesh.vertices), len(mesh.faces), properties,
        has_vertex_normals=True, has_vertex_texcoords=mesh.uv is not None,
    )  # fmt: skip
    params = mi.traverse(shape)
    # The buffer types differ between scalar and JIT variants: take them from the mesh itself.
    floats, indices = type(params["vertex_positions"]), type(params["faces"])
    params["vertex_positions"] = floats(np.ascontiguousarray(mesh.vertices, np.float32).ravel())
    params["faces"] = indices(np.ascontiguousarray(mesh.faces, np.uint32).ravel())
    params["vertex_normals"] = floats(np.ascontiguousarray(mesh.normals, np.float32).ravel())
    if mesh.uv is not None:
        params["vertex_texcoords"] = floats(np.ascontiguousarray(mesh.uv, np.float32).ravel())
    params.update()  # rebuilds the bounding box and the area distribution
    return shape
