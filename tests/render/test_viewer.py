from __future__ import annotations

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.errors import InputError
from render.splat import plan_splats, splat
from render.viewer import pyvista_picture
from sim.scenes import build_scene


def test_vtk_draws_the_same_object_as_the_splatter() -> None:
    samples = build_scene("textured-torus", 20_000)
    camera = PinholeCamera(30.0, 50.0, width=96, height=72)
    colours = (samples.rho_d * 255).astype(np.uint8)
    picture = pyvista_picture(samples.points, samples.normals, colours, camera, samples.spacing)
    plan = plan_splats(samples.points, samples.normals, camera, samples.spacing)
    ours = splat(plan, colours.astype(np.float32))
    drawn = picture.max(axis=2) > 0
    overlap = (drawn & plan.coverage).sum() / (drawn | plan.coverage).sum()
    assert picture.shape == (72, 96, 3) and overlap > 0.85
    both = drawn & plan.coverage
    np.testing.assert_allclose(picture[both].mean(axis=0), ours[both].mean(axis=0), rtol=0.1)


def test_colours_must_match_the_points() -> None:
    samples = build_scene("diffuse-sphere", 100)
    with pytest.raises(InputError, match=r"\(100, 3\) uint8"):
        pyvista_picture(samples.points, samples.normals, np.zeros((99, 3), np.uint8),
                        PinholeCamera(0.0, 30.0, width=8, height=8), samples.spacing)  # fmt: skip
