from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

from app.cli import main
from core.brdf import brdf
from core.camera_model import PinholeCamera
from core.directions import panorama_solid_angles
from core.light_set import LightSet, grid_lights
from sim.ground_truth import render_environment, shade_environment
from sim.scenes import build_scene


def test_kernel_evaluates_the_material_model() -> None:
    s = build_scene("glossy-sphere", 400)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(30, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    light = rng.random((30, 3))
    viewpoint = np.array([0.5, 3.0, 1.0])
    got = shade_environment(s, viewpoint, LightSet(d, light), shadows=False)
    view = viewpoint - s.points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    expected = sum(
        brdf(s.normals, d[j], view, s.rho_d, s.f0, s.alpha)
        * np.maximum(s.normals @ d[j], 0)[:, None]
        * light[j]
        for j in range(30)
    )
    expected[np.sum(s.normals * view, axis=1) <= 0] = 0
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("grid", [None, 16, 8])
def test_grid_lights_keep_all_light(grid: int | None) -> None:
    rgb = np.random.default_rng(1).random((32, 64, 3))
    light = grid_lights(rgb, grid).rgb
    total = (rgb * panorama_solid_angles(32, 64)[:, :, None]).sum((0, 1))
    np.testing.assert_allclose(light.sum(0), total, rtol=1e-12)


@pytest.mark.parametrize(("grid", "tolerance"), [(None, 1e-3), (16, 5e-3)])
def test_white_furnace(grid: int | None, tolerance: float) -> None:
    sphere = build_scene("diffuse-sphere", 3000)
    white = replace(sphere, rho_d=np.ones_like(sphere.rho_d))
    lights = grid_lights(np.ones((64, 128, 3)), grid)
    viewpoint = np.array([0.0, 0.0, 10.0])
    radiance = shade_environment(white, viewpoint, lights, shadows=False)
    seen = np.sum(white.normals * (viewpoint - white.points), axis=1) > 0
    np.testing.assert_allclose(radiance[seen], 1.0, atol=tolerance)


def test_prefilter_error_is_small_against_exact() -> None:
    from core.sample_data import panorama_path
    from processing.panorama import read_panorama

    full = read_panorama(panorama_path("courtyard")).rgb
    pano = cv2.resize(full, (128, 64), interpolation=cv2.INTER_AREA)
    glossy = build_scene("glossy-sphere", 20_000)
    camera = PinholeCamera(20.0, 70.0, 4.0, 40.0, 96, 96)
    exact = render_environment(glossy, pano, camera, grid_height=None, shadows=False)
    coarse = render_environment(glossy, pano, camera, grid_height=32, shadows=False)
    m = exact.coverage
    error = np.sqrt(np.mean((coarse.rgb[m] - exact.rgb[m]) ** 2) / np.mean(exact.rgb[m] ** 2))
    assert error < 0.01


def test_self_shadowing_darkens_the_torus() -> None:
    torus = build_scene("textured-torus", 20_000)
    lights = grid_lights(np.ones((16, 32, 3)), 8)
    viewpoint = np.array([0.0, 0.0, 5.0])
    lit = shade_environment(torus, viewpoint, lights, shadows=False)
    shadowed = shade_environment(torus, viewpoint, lights, shadows=True)
    assert np.all(shadowed <= lit + 1e-12)
    inner = np.hypot(torus.points[:, 0], torus.points[:, 1]) < 0.55  # inside of the ring
    seen = inner & (lit[:, 0] > 0)
    assert np.mean(shadowed[seen, 0] / lit[seen, 0]) < 0.9


def _render_args(tmp_path: Path, size: str, points: str, grid: str, out: Path) -> list[str]:
    env = tmp_path / "env.png"
    cv2.imwrite(str(env), np.full((16, 32, 3), 200, dtype=np.uint8))
    return ["sim", "render", "--scene", "diffuse-sphere", "--env", str(env), "--view", "0,60",
            "--size", size, "--points", points, "--grid", grid, "-o", str(out)]  # fmt: skip


def test_cli_render_writes_rgb_and_alpha(tmp_path: Path) -> None:
    out = tmp_path / "gt.exr"
    assert main(_render_args(tmp_path, "64x48", "5000", "8", out)) == 0
    with OpenEXR.File(str(out), separate_channels=True) as exr:
        channels = {k: v.pixels for k, v in exr.channels().items()}
    assert set(channels) == {"R", "G", "B", "A"} and channels["A"].shape == (48, 64)
    assert 0.1 < channels["A"].mean() < 0.9 and channels["R"].max() > 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--scene", "teapot"], "unknown scene"),
        (["--fov", "0"], "argument --fov: must be positive"),
        (["--distance", "0.5"], "inside the object"),
        (["--points", "0"], "argument --points: must be at least 1"),
    ],
)
def test_cli_render_refuses_bad_arguments(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    args = _render_args(tmp_path, "32x32", "1000", "4", tmp_path / "o.exr")
    assert main(args + extra) == 2
    assert message in capsys.readouterr().err
