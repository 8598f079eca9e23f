from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from core.errors import InputError
from sim.materials import Material
from sim.mesh import sample_mesh
from sim.scenes import SCENES, TORUS_MAJOR, TORUS_MINOR, build_scene


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scenes_are_well_formed_and_deterministic(name: str) -> None:
    s = build_scene(name, 4000)
    assert s.count == 4000
    assert s.points.dtype == np.float32 and s.normals.shape == (4000, 3)
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1.0, rtol=1e-6)
    assert np.all((s.rho_d >= 0) & (s.rho_d <= 1)) and np.all(s.alpha > 0)
    np.testing.assert_array_equal(s.points, build_scene(name, 4000).points)


@pytest.mark.parametrize("name", ["diffuse-sphere", "glossy-sphere"])
def test_spheres(name: str) -> None:
    s = build_scene(name, 2000)
    np.testing.assert_allclose(np.linalg.norm(s.points, axis=1), 1.0, rtol=1e-6)
    np.testing.assert_allclose(s.normals, s.points, atol=1e-6)
    assert abs(s.points[:, 2].mean()) < 1e-3  # uniform by area: z is uniform in [-1, 1]


def test_torus_is_on_its_surface_and_uniform_by_area() -> None:
    s = build_scene("textured-torus", 20_000).points.astype(np.float64)
    ring = np.hypot(s[:, 0], s[:, 1])
    np.testing.assert_allclose((ring - TORUS_MAJOR) ** 2 + s[:, 2] ** 2, TORUS_MINOR**2, rtol=1e-5)
    outer = np.mean(ring > TORUS_MAJOR)  # area share of the outer half of the tube
    assert outer == pytest.approx(0.5 + TORUS_MINOR / (np.pi * TORUS_MAJOR), abs=0.01)
    albedos = {tuple(np.round(a, 3)) for a in build_scene("textured-torus", 2000).rho_d}
    assert len(albedos) == 2  # the checker texture


def test_bad_arguments() -> None:
    with pytest.raises(InputError, match="known scenes: diffuse-sphere"):
        build_scene("teapot", 100)
    with pytest.raises(InputError, match="points must be"):
        build_scene("diffuse-sphere", 0)


def test_cli_lists_scenes_as_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "scenes", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in listed] == list(SCENES)
    glossy = next(s for s in listed if s["name"] == "glossy-sphere")
    assert glossy["geometry"] == {"type": "sphere", "center": [0, 0, 0], "radius": 1.0}
    assert set(glossy["material"]) == {"rho_d", "f0", "alpha"}


def test_mesh_sampling(tmp_path: Path) -> None:
    import pyvista as pv

    pv.Sphere(radius=2.0, theta_resolution=60, phi_resolution=60).save(tmp_path / "s.ply")
    s = sample_mesh(tmp_path / "s.ply", 3000, Material(rho_d=(0.5, 0.5, 0.5)))
    assert s.count == 3000
    assert np.all(np.abs(np.linalg.norm(s.points, axis=1) - 2.0) < 0.02)
    assert np.all(np.sum(s.normals * s.points, axis=1) > 0)  # outward


def test_mesh_errors(tmp_path: Path) -> None:
    material = Material(rho_d=(0.5, 0.5, 0.5))
    with pytest.raises(InputError, match="no such mesh"):
        sample_mesh(tmp_path / "none.ply", 10, material)
    (tmp_path / "bad.ply").write_text("this is not a mesh")
    with pytest.raises(InputError, match=r"bad\.ply"):
        sample_mesh(tmp_path / "bad.ply", 10, material)
