from __future__ import annotations

import numpy as np
import pytest

from core.brdf import brdf
from core.camera_model import PinholeCamera
from core.directions import direction_from_angles_deg
from core.errors import InputError
from sim.scenes import TORUS_MAJOR, TORUS_MINOR, build_scene
from sim.synthetic_camera import (
    DirectionalLight,
    PointLight,
    light_visibility,
    render_under_light,
    shade_points,
)

RHO = np.array([0.75, 0.60, 0.45])  # diffuse-sphere


@pytest.fixture(scope="module")
def sphere():  # type: ignore[no-untyped-def]
    return build_scene("diffuse-sphere", 60_000)


def _towards(az: float, incl: float) -> tuple[float, float, float]:
    x, y, z = direction_from_angles_deg(az, incl)
    return (float(x), float(y), float(z))


def test_light_along_the_normal_gives_rho_over_pi(sphere) -> None:  # type: ignore[no-untyped-def]
    cam = PinholeCamera(30.0, 60.0, 4.0, 40.0, 128, 128)
    image = render_under_light(sphere, cam, DirectionalLight(_towards(30.0, 60.0)))
    np.testing.assert_allclose(image.rgb[64, 64], RHO / np.pi, rtol=2e-3)


def test_shading_kernel_evaluates_the_material_model() -> None:
    s = build_scene("glossy-sphere", 2000)
    light = PointLight((1.5, 2.0, 2.5), intensity=3.0)
    viewpoint = np.array([0.5, 3.0, 1.0])
    got = shade_points(s, viewpoint, light, shadows=False)
    offset = np.array(light.position) - s.points
    distance = np.linalg.norm(offset, axis=1, keepdims=True)
    towards, view = offset / distance, viewpoint - s.points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    cosine = np.maximum(np.sum(s.normals * towards, axis=1, keepdims=True), 0)
    expected = brdf(s.normals, towards, view, s.rho_d, s.f0, s.alpha) * cosine * 3.0 / distance**2
    assert (expected > 0).any(axis=1).mean() > 0.2
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)


def test_point_light_falls_off_with_distance_squared(sphere) -> None:  # type: ignore[no-untyped-def]
    cam = PinholeCamera(0.0, 90.0, 4.0, 40.0, 64, 64)
    near = render_under_light(sphere, cam, PointLight(tuple(3.0 * np.array(_towards(0.0, 90.0)))))
    far = render_under_light(sphere, cam, PointLight(tuple(5.0 * np.array(_towards(0.0, 90.0)))))
    # The lit pole is at distance 2 and 4 from the lights.
    np.testing.assert_allclose(near.rgb[32, 32], RHO / np.pi / 4.0, rtol=5e-3)
    np.testing.assert_allclose(far.rgb[32, 32], RHO / np.pi / 16.0, rtol=5e-3)


def test_silhouette_has_no_holes(sphere) -> None:  # type: ignore[no-untyped-def]
    cam = PinholeCamera(10.0, 70.0, 4.0, 40.0, 256, 256)
    image = render_under_light(sphere, cam, DirectionalLight(_towards(0.0, 0.0)))
    i, j = np.mgrid[0:256, 0:256]
    r = np.hypot(i + 0.5 - 128, j + 0.5 - 128)
    # Angular radius of a unit sphere at distance 4: asin(1/4).
    disc = cam.focal_px * np.tan(np.arcsin(0.25))
    assert image.coverage[r < disc - 1.5].all()
    assert not image.coverage[r > disc + 1.5].any()


def test_no_self_shadow_on_a_convex_sphere(sphere) -> None:  # type: ignore[no-untyped-def]
    light = DirectionalLight(_towards(200.0, 35.0))
    facing = sphere.normals @ np.asarray(light.direction) > 0
    assert light_visibility(sphere, light)[facing].all()


def test_torus_shadows_match_ray_marching() -> None:
    torus = build_scene("textured-torus", 100_000)
    light = DirectionalLight(_towards(0.0, 80.0))  # grazing: the ring shadows itself
    lit = light_visibility(torus, light)
    points, towards = torus.points.astype(np.float64), np.asarray(light.direction)
    occluded = np.zeros(len(points), dtype=bool)
    for step in np.linspace(0.01, 2.0, 400):
        q = points + step * towards
        inside = (np.hypot(q[:, 0], q[:, 1]) - TORUS_MAJOR) ** 2 + q[
            :, 2
        ] ** 2 < TORUS_MINOR**2 - 1e-4
        occluded |= inside
    facing = torus.normals @ towards > 0.05
    assert (facing & occluded).sum() > 0.1 * facing.sum()  # real self-shadowing here
    disagree = (facing & (occluded == lit)).sum()
    assert disagree < 0.01 * facing.sum()


def test_deterministic(sphere) -> None:  # type: ignore[no-untyped-def]
    cam = PinholeCamera(45.0, 45.0, 4.0, 40.0, 64, 64)
    light = DirectionalLight(_towards(90.0, 30.0))
    a = render_under_light(sphere, cam, light)
    np.testing.assert_array_equal(a.rgb, render_under_light(sphere, cam, light).rgb)


def test_camera_or_light_inside_the_object(sphere) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match="inside the object"):
        render_under_light(sphere, PinholeCamera(0.0, 90.0, 0.9), DirectionalLight((0, 0, 1)))
    with pytest.raises(InputError, match="inside the object"):
        render_under_light(sphere, PinholeCamera(0.0, 90.0, 4.0), PointLight((0.5, 0.0, 0.0)))
