"""The built-in shapes of the Mitsuba worlds, as triangle meshes that fit the unit sphere.

Each has unit vertex normals (smooth shading) and texture coordinates; with their defaults:

``torus-knot``
    A tube of radius ``tube_radius`` around the (p, q) torus-knot curve (R + r cos q t) (cos p t,
    sin p t) + r sin q t z, R = ``major_radius``, r = ``knot_radius``: self-occlusion, concave
    crossings. u runs along the curve (``uv_repeats`` times over one loop), v around the tube.
``bowl``
    A hemispherical shell of outer radius ``radius`` and wall ``thickness`` with a rounded rim,
    open toward +z: a concave cavity (interreflections). u around the axis, v along the profile
    from the outer pole over the rim to the inner pole.
``relief``
    A bas-relief: a square slab of side ``size`` whose top is a procedural height field
    (bumps, a ring groove, a raised bar with steep walls, a pit) up to ``height`` high, on a
    base ``base`` thick. u, v span the top; sides and bottom are flat (their uv are 0).
``sphere``
    A latitude-longitude sphere of ``radius``; u = azimuth / 2 pi, v = inclination / pi.
``cylinder``
    An upright closed cylinder of ``radius`` and ``height`` about +z, centred on the origin, with
    flat caps whose rims are sharp (the caps have vertices of their own). u around the axis, v
    along each part's profile.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from sim.world.mesh import TriangleMesh, oriented_faces, unit_normals, vertex_normals

__all__ = [
    "bowl_mesh",
    "cylinder_mesh",
    "join_meshes",
    "relief_heights",
    "relief_mesh",
    "sphere_mesh",
    "torus_knot_mesh",
]


def _grid_faces(rows: int, cols: int) -> NDArray[np.int64]:
    """Two triangles per cell of a rows x cols vertex grid indexed row * cols + col."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a, b = r * cols + c, (r + 1) * cols + c
    quads = np.stack([a, b, b + 1, a + 1], axis=-1).reshape(-1, 4)
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int64)


def torus_knot_mesh(
    *,
    p: int = 2,
    q: int = 3,
    major_radius: float = 0.6,
    knot_radius: float = 0.25,
    tube_radius: float = 0.13,
    curve_segments: int = 600,
    tube_segments: int = 32,
    uv_repeats: int = 8,
) -> TriangleMesh:
    """A tube around the (p, q) torus knot (module docstring); p and q coprime.

    The tube's frame is parallel-transported along the curve and its closing twist spread over
    the loop, so the tube has no seam in shading and u, v are continuous but for one seam each
    (its vertices duplicated there).
    """
    if math.gcd(p, q) != 1:
        raise InputError(f"torus-knot p and q must be coprime, got p={p}, q={q}")
    t = 2.0 * np.pi * np.arange(curve_segments) / curve_segments

    def curve(at: NDArray[np.float64]) -> NDArray[np.float64]:
        ring = major_radius + knot_radius * np.cos(q * at)
        return np.stack(
            [ring * np.cos(p * at), ring * np.sin(p * at), knot_radius * np.sin(q * at)], -1
        )

    centre = curve(t)
    tangent = curve(t + 1e-5) - curve(t - 1e-5)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.empty_like(centre)
    start = np.cross(tangent[0], [0.0, 0.0, 1.0])
    if np.linalg.norm(start) < 1e-3:
        start = np.cross(tangent[0], [1.0, 0.0, 0.0])
    normal[0] = start / np.linalg.norm(start)
    for k in range(1, curve_segments):
        v = normal[k - 1] - np.dot(normal[k - 1], tangent[k]) * tangent[k]
        normal[k] = v / np.linalg.norm(v)
    # Transported once round, the frame comes back turned by the loop's twist: spreading the
    # opposite turn over the loop closes it without a kink.
    back = normal[-1] - np.dot(normal[-1], tangent[0]) * tangent[0]
    twist = np.arctan2(np.dot(back, np.cross(tangent[0], normal[0])), np.dot(back, normal[0]))
    binormal = np.cross(tangent, normal)
    turn = (-twist * np.arange(curve_segments) / curve_segments)[:, None]
    normal, binormal = (np.cos(turn) * normal + np.sin(turn) * binormal,
                        -np.sin(turn) * normal + np.cos(turn) * binormal)  # fmt: skip
    ring_index = np.arange(curve_segments + 1) % curve_segments
    phi = 2.0 * np.pi * np.arange(tube_segments + 1) / tube_segments
    outward = (np.cos(phi)[None, :, None] * normal[ring_index][:, None, :]
               + np.sin(phi)[None, :, None] * binormal[ring_index][:, None, :])  # fmt: skip
    vertices = (centre[ring_index][:, None, :] + tube_radius * outward).reshape(-1, 3)
    normals = outward.reshape(-1, 3)
    u, v = np.meshgrid(
        uv_repeats * np.arange(curve_segments + 1) / curve_segments,
        np.arange(tube_segments + 1) / tube_segments,
        indexing="ij",
    )
    faces = _grid_faces(curve_segments + 1, tube_segments + 1)
    return TriangleMesh(
        vertices,
        oriented_faces(vertices, faces, normals),
        normals,
        np.stack([u, v], -1).reshape(-1, 2),
    )


def _revolve(
    profile: NDArray[np.float64], profile_normals: NDArray[np.float64], segments: int
) -> TriangleMesh:
    """The surface of revolution about +z of a profile (N, 2) of (r, z) with normals (N, 2)."""
    phi = 2.0 * np.pi * np.arange(segments + 1) / segments
    cos, sin = np.cos(phi)[None, :], np.sin(phi)[None, :]
    r, z = profile[:, :1], profile[:, 1:]
    nr, nz = profile_normals[:, :1], profile_normals[:, 1:]
    vertices = np.stack([r * cos, r * sin, np.broadcast_to(z, r.shape[:1] + phi.shape)], -1)
    normals = np.stack([nr * cos, nr * sin, np.broadcast_to(nz, r.shape[:1] + phi.shape)], -1)
    step = np.linalg.norm(np.diff(profile, axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(step)]) / step.sum()
    u, v = np.meshgrid(phi / (2.0 * np.pi), along, indexing="xy")
    vertices, normals = vertices.reshape(-1, 3), normals.reshape(-1, 3)
    faces = _grid_faces(len(profile), segments + 1)
    return TriangleMesh(
        vertices,
        oriented_faces(vertices, faces, normals),
        normals,
        np.stack([u, v], -1).reshape(-1, 2),
    )


def bowl_mesh(
    *,
    radius: float = 0.85,
    thickness: float = 0.08,
    rings: int = 48,
    rim_segments: int = 12,
    segments: int = 96,
) -> TriangleMesh:
    """A hemispherical shell open toward +z with a rounded rim (module docstring).

    One profile runs from the outer pole up to the rim, over the rim's half circle and down the
    inside to the inner pole, so the normals are continuous everywhere; the bowl is centred on
    its bounding box's centre along z.
    """
    if not 0.0 < thickness < radius:
        raise InputError(f"bowl thickness must be in (0, radius = {radius}), got {thickness}")
    inner, half = radius - thickness, 0.5 * thickness
    theta = 0.5 * np.pi * np.arange(rings + 1) / rings  # from the pole to the rim
    arc = np.pi * np.arange(1, rim_segments) / rim_segments  # from outside over the top
    outer_side = np.stack([radius * np.sin(theta), -radius * np.cos(theta)], -1)
    outer_normal = np.stack([np.sin(theta), -np.cos(theta)], -1)
    rim = np.stack([radius - half + half * np.cos(arc), half * np.sin(arc)], -1)
    rim_normal = np.stack([np.cos(arc), np.sin(arc)], -1)
    inner_side = np.stack([inner * np.sin(theta), -inner * np.cos(theta)], -1)[::-1]
    inner_normal = -np.stack([np.sin(theta), -np.cos(theta)], -1)[::-1]
    profile = np.concatenate([outer_side, rim, inner_side])
    profile[:, 1] += 0.5 * (radius - half)  # z from -radius .. half to symmetric about 0
    normals = np.concatenate([outer_normal, rim_normal, inner_normal])
    return _revolve(profile, normals, segments)


def sphere_mesh(*, radius: float = 0.9, rings: int = 64, segments: int = 128) -> TriangleMesh:
    """A latitude-longitude sphere about the origin (module docstring)."""
    theta = np.pi * np.arange(rings + 1) / rings
    profile = np.stack([radius * np.sin(theta), radius * np.cos(theta)], -1)
    normals = np.stack([np.sin(theta), np.cos(theta)], -1)
    return _revolve(profile, normals, segments)


def join_meshes(parts: list[TriangleMesh]) -> TriangleMesh:
    """One mesh of several (vertices appended, faces re-indexed).

    Texture coordinates are kept when every part has them; a part without uv gets zeros when
    another has them, and the result has none when no part has them.
    """
    if len(parts) == 1:
        return parts[0]
    offsets = np.cumsum([0] + [len(part.vertices) for part in parts[:-1]])
    uv = None
    if any(part.uv is not None for part in parts):
        uv = np.concatenate([
            np.zeros((len(part.vertices), 2)) if part.uv is None else part.uv for part in parts
        ])  # fmt: skip
    return TriangleMesh(
        np.concatenate([part.vertices for part in parts]),
        np.concatenate([part.faces + offset for part, offset in zip(parts, offsets, strict=True)]),
        np.concatenate([part.normals for part in parts]),
        uv,
    )


def cylinder_mesh(
    *, radius: float = 0.3, height: float = 0.8, rings: int = 8, segments: int = 96
) -> TriangleMesh:
    """An upright closed cylinder about +z, centred on the origin (module docstring).

    The side has ``rings`` rows of quads along its height; each cap is a fan of ``rings``
    concentric rows, so the triangles stay near equal in size for the surface samples.
    """
    top, steps = 0.5 * height, np.arange(rings + 1) / rings
    side = np.stack([np.full(rings + 1, radius), top * (2.0 * steps - 1.0)], -1)
    side_normals = np.tile([1.0, 0.0], (rings + 1, 1))
    # Caps run from the rim inward: the pole collapses to a point (degenerate faces dropped).
    cap_r = radius * (1.0 - steps)
    upper = np.stack([cap_r, np.full(rings + 1, top)], -1)
    lower = np.stack([cap_r[::-1], np.full(rings + 1, -top)], -1)
    return join_meshes([
        _revolve(side, side_normals, segments),
        _revolve(upper, np.tile([0.0, 1.0], (rings + 1, 1)), segments),
        _revolve(lower, np.tile([0.0, -1.0], (rings + 1, 1)), segments),
    ])  # fmt: skip


def _inside(margin: NDArray[np.float64], wall: float = 0.08) -> NDArray[np.float64]:
    """A step from 0 outside to 1 inside, smooth over ``wall`` (in the relief's [-1, 1] units).

    A wall a few grid cells wide keeps every triangle's normal near its vertices' normals; a
    one-cell cliff would be shaded as a slope and sampled with normals far from its own.
    """
    ramp = np.clip(0.5 + margin / wall, 0.0, 1.0)
    return ramp * ramp * (3.0 - 2.0 * ramp)


def relief_heights(resolution: int, seed: int) -> NDArray[np.float64]:
    """A procedural bas-relief in [0, 1]; shape (resolution, resolution), rows along y.

    Gaussian bumps (placed by ``seed``), a concave ring groove, a raised bar with steep walls
    and a deep pit (walls of :func:`_inside`): the concavities and walls are where
    interreflection and cast shadows live.
    """
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(*(2 * [np.linspace(-1.0, 1.0, resolution)]), indexing="xy")
    heights = np.zeros_like(x)
    for _ in range(7):
        cx, cy = rng.uniform(-0.7, 0.7, 2)
        width = rng.uniform(0.08, 0.2)
        heights += rng.uniform(0.3, 1.0) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width**2))
    heights -= 0.5 * np.exp(-((np.hypot(x, y) - 0.6) ** 2) / (2 * 0.05**2))
    heights += 0.4 * _inside(0.08 - np.abs(x + 0.2)) * _inside(0.45 - np.abs(y))
    heights -= 0.6 * _inside(0.15 - np.hypot(x - 0.35, y + 0.35))
    heights -= heights.min()
    return heights / heights.max()


def relief_mesh(
    *,
    size: float = 1.36,
    height: float = 0.25,
    base: float = 0.1,
    resolution: int = 160,
    seed: int = 1,
) -> TriangleMesh:
    """A closed slab whose top is :func:`relief_heights` (module docstring), centred on its box.

    The top's normals come from the height field's gradient (smooth); the four sides and the
    bottom are flat with vertices of their own, so their edges stay sharp.
    """
    axis = np.linspace(-0.5 * size, 0.5 * size, resolution)
    x, y = np.meshgrid(axis, axis, indexing="xy")
    z = height * relief_heights(resolution, seed)
    top = np.stack([x, y, z], -1)
    top_vertices = top.reshape(-1, 3)
    # Normals from the triangles themselves, not from the height field's finite differences:
    # at the steep walls these disagree, and the samples' normals must be the shading's.
    top_faces = oriented_faces(top_vertices, _grid_faces(resolution, resolution),
                          np.tile([0.0, 0.0, 1.0], (len(top_vertices), 1)))  # fmt: skip
    parts = [
        (
            top_vertices,
            vertex_normals(top_vertices, top_faces),
            np.stack([(x / size) + 0.5, (y / size) + 0.5], -1).reshape(-1, 2),
            top_faces,
        )
    ]
    edges = ((top[0, :], (0.0, -1.0, 0.0)), (top[-1, ::-1], (0.0, 1.0, 0.0)),
             (top[::-1, 0], (-1.0, 0.0, 0.0)), (top[:, -1], (1.0, 0.0, 0.0)))  # fmt: skip
    for rim, outward in edges:
        bottom = rim.copy()
        bottom[:, 2] = -base
        wall = np.stack([rim, bottom], 1).reshape(-1, 3)
        parts.append((wall, np.tile(outward, (len(wall), 1)), np.zeros((len(wall), 2)),
                      _grid_faces(len(rim), 2)))  # fmt: skip
    half = 0.5 * size
    floor = np.array([[-half, -half, -base], [half, -half, -base], [-half, half, -base],
                      [half, half, -base]])  # fmt: skip
    parts.append((floor, np.tile([0.0, 0.0, -1.0], (4, 1)), np.zeros((4, 2)), _grid_faces(2, 2)))
    vertices, normals, uv, faces, offset = [], [], [], [], 0
    for part_vertices, part_normals, part_uv, part_faces in parts:
        unit = unit_normals(part_normals, "relief")
        faces.append(oriented_faces(part_vertices, part_faces, unit) + offset)
        vertices.append(part_vertices)
        normals.append(unit)
        uv.append(part_uv)
        offset += len(part_vertices)
    all_vertices = np.concatenate(vertices)
    all_vertices -= 0.5 * (all_vertices.max(axis=0) + all_vertices.min(axis=0))
    return TriangleMesh(all_vertices, np.concatenate(faces), np.concatenate(normals),
                        np.concatenate(uv))  # fmt: skip
