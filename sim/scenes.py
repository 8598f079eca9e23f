"""Synthetic objects: dense point clouds with normals and per-point materials.

Every scene is described by plain parameters (``rig sim scenes --json``) so it can be rebuilt in
another renderer. Points are placed deterministically and uniformly by area (spherical Fibonacci
lattice on spheres, a rank-1 lattice through the area CDF on the torus), so a given point count
always gives the same cloud.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.directions import fibonacci_sphere
from core.errors import InputError
from sim.materials import Material

__all__ = ["MAX_POINTS", "SCENES", "SceneSpec", "SurfaceSamples", "build_scene", "get_scene"]

MAX_POINTS = 20_000_000
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class SurfaceSamples:
    """Surface samples of an object, rig frame.

    Attributes
    ----------
    points, normals : ndarray, shape (P, 3), float32 (normals unit, pointing outward)
    rho_d, f0 : ndarray, shape (P, 3), float32
    alpha : ndarray, shape (P,), float32
    spacing : float
        Mean distance between neighbouring points, sqrt(surface area / P): sizes splats.
    """

    points: NDArray[np.float32]
    normals: NDArray[np.float32]
    rho_d: NDArray[np.float32]
    f0: NDArray[np.float32]
    alpha: NDArray[np.float32]
    spacing: float

    @property
    def count(self) -> int:
        """Number of points, P."""
        return int(self.points.shape[0])

    @cached_property
    def bounding_radius(self) -> float:
        """Largest distance of a point from the origin."""
        return float(np.linalg.norm(self.points, axis=1).max())


def uniform_material(count: int, material: Material) -> dict[str, NDArray[np.float32]]:
    """Per-point arrays of one material repeated ``count`` times."""
    return {
        "rho_d": np.tile(np.asarray(material.rho_d, dtype=np.float32), (count, 1)),
        "f0": np.tile(np.asarray(material.f0, dtype=np.float32), (count, 1)),
        "alpha": np.full(count, material.alpha, dtype=np.float32),
    }


@dataclass(frozen=True)
class SceneSpec:
    """A named synthetic object: its parameters and how to sample it."""

    name: str
    description: str
    geometry: dict[str, Any]
    material: Material
    builder: Callable[[int], SurfaceSamples] = field(repr=False)
    texture: str | None = None
    convex: bool = False  # no point shadows another: visibility is n . w > 0

    def to_json(self) -> dict[str, Any]:
        """The scene as plain JSON: name, description, geometry and material (and its texture)."""
        material: dict[str, Any] = dict(self.material.to_json())
        if self.texture is not None:
            material["texture"] = self.texture
        return {
            "name": self.name,
            "description": self.description,
            "geometry": self.geometry,
            "material": material,
        }


def _sphere(
    center: tuple[float, float, float], radius: float, material: Material
) -> Callable[[int], SurfaceSamples]:
    def build(count: int) -> SurfaceSamples:
        normals = fibonacci_sphere(count)
        points = np.asarray(center) + radius * normals
        return SurfaceSamples(
            points=points.astype(np.float32),
            normals=normals.astype(np.float32),
            spacing=float(np.sqrt(4.0 * np.pi * radius**2 / count)),
            **uniform_material(count, material),
        )

    return build


TORUS_MAJOR, TORUS_MINOR = 0.7, 0.3
CHECKER_U, CHECKER_V = 12, 6
CHECKER_A = (0.80, 0.55, 0.30)
CHECKER_B = (0.20, 0.30, 0.70)
TORUS_MATERIAL = Material(rho_d=CHECKER_A, f0=(0.04, 0.04, 0.04), alpha=0.35)


def _torus_tube_angle(fraction: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tube angle v in [0, 2 pi) whose area CDF (R v + r sin v) / (2 pi R) is ``fraction``."""
    target = 2.0 * np.pi * fraction
    v = target.copy()
    ratio = TORUS_MINOR / TORUS_MAJOR
    for _ in range(30):  # Newton on v + ratio sin v = target; monotone since ratio < 1
        v -= (v + ratio * np.sin(v) - target) / (1.0 + ratio * np.cos(v))
    return v


def _torus(count: int) -> SurfaceSamples:
    i = np.arange(count, dtype=np.float64)
    u = 2.0 * np.pi * (i + 0.5) / count
    v = _torus_tube_angle(np.mod(i * GOLDEN + 0.5 / count, 1.0))
    ring = TORUS_MAJOR + TORUS_MINOR * np.cos(v)
    points = np.stack([ring * np.cos(u), ring * np.sin(u), TORUS_MINOR * np.sin(v)], axis=1)
    normals = np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], axis=1)
    cell = np.floor(CHECKER_U * u / (2 * np.pi)) + np.floor(CHECKER_V * v / (2 * np.pi))
    rho_d = np.where((cell % 2 == 0)[:, None], CHECKER_A, CHECKER_B).astype(np.float32)
    arrays = uniform_material(count, TORUS_MATERIAL)
    arrays["rho_d"] = rho_d
    return SurfaceSamples(
        points=points.astype(np.float32),
        normals=normals.astype(np.float32),
        spacing=float(np.sqrt(4.0 * np.pi**2 * TORUS_MAJOR * TORUS_MINOR / count)),
        **arrays,
    )


DIFFUSE = Material(rho_d=(0.75, 0.60, 0.45))
GLOSSY = Material(rho_d=(0.30, 0.40, 0.60), f0=(0.25, 0.25, 0.25), alpha=0.2)

SCENES: dict[str, SceneSpec] = {
    spec.name: spec
    for spec in (
        SceneSpec(
            name="diffuse-sphere",
            description="Lambertian sphere",
            geometry={"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0},
            material=DIFFUSE,
            builder=_sphere((0.0, 0.0, 0.0), 1.0, DIFFUSE),
            convex=True,
        ),
        SceneSpec(
            name="glossy-sphere",
            description="diffuse plus GGX specular lobe sphere",
            geometry={"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0},
            material=GLOSSY,
            builder=_sphere((0.0, 0.0, 0.0), 1.0, GLOSSY),
            convex=True,
        ),
        SceneSpec(
            name="textured-torus",
            description="non-convex torus with a checker albedo: self-shadowing inside the ring",
            geometry={
                "type": "torus",
                "center": [0.0, 0.0, 0.0],
                "axis": [0.0, 0.0, 1.0],
                "major_radius": TORUS_MAJOR,
                "minor_radius": TORUS_MINOR,
            },
            material=TORUS_MATERIAL,
            builder=_torus,
            texture=(
                f"checkerboard of {CHECKER_U} x {CHECKER_V} cells over the torus angles u (around "
                "+z, counter-clockwise from +x) and v (around the tube, from the outer equator "
                f"toward +z); cells with even floor({CHECKER_U} u / 2 pi) + floor({CHECKER_V} v / "
                f"2 pi) have rho_d {list(CHECKER_A)}, odd cells {list(CHECKER_B)}"
            ),
        ),
    )
}


def get_scene(name: str) -> SceneSpec:
    """The scene called ``name``; an unknown name lists the known ones."""
    try:
        return SCENES[name]
    except KeyError:
        raise InputError(f"unknown scene {name!r}; known scenes: {', '.join(SCENES)}") from None


def build_scene(name: str, points: int) -> SurfaceSamples:
    """Sample the scene ``name`` with ``points`` surface points (1 .. MAX_POINTS)."""
    spec = get_scene(name)
    if not 1 <= points <= MAX_POINTS:
        raise InputError(f"points must be between 1 and {MAX_POINTS}, got {points}")
    return spec.builder(points)
