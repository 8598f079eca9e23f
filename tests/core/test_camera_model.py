from __future__ import annotations

import numpy as np
import pytest

from core.camera_model import PinholeCamera, rig_to_camera
from core.directions import direction_from_angles_deg
from core.errors import InputError


def test_origin_projects_to_the_centre_and_up_is_z() -> None:
    cam = PinholeCamera(30.0, 60.0, 4.0, 40.0, 320, 240)
    col, row, depth = cam.project(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]]))
    assert (col[0], row[0], depth[0]) == pytest.approx((160.0, 120.0, 4.0))
    assert row[1] < row[0]  # +z is up in the image
    assert col[1] == pytest.approx(160.0)


def test_not_mirrored() -> None:
    # From +x looking at the origin with +z up, +y is on the right.
    cam = PinholeCamera(0.0, 90.0, 4.0)
    col, _, _ = cam.project(np.array([[0.0, 0.5, 0.0]]))
    assert col[0] > cam.width / 2


def test_straight_above_takes_up_from_the_azimuth() -> None:
    cam = PinholeCamera(90.0, 0.0, 4.0)  # azimuth +y, looking down
    near = PinholeCamera(90.0, 1e-4, 4.0)
    np.testing.assert_allclose(cam.axes(), near.axes(), atol=1e-5)
    _, row, _ = cam.project(np.array([[0.0, -0.5, 0.0]]))
    assert row[0] < cam.height / 2  # away from the azimuth direction is up


def test_focal_length_matches_the_field_of_view() -> None:
    cam = PinholeCamera(0.0, 90.0, 4.0, fov_deg=90.0, width=200, height=100)
    assert cam.focal_px == pytest.approx(100.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"distance": 0.0}, "distance"),
        ({"fov_deg": 180.0}, "field of view"),
        ({"fov_deg": 0.0}, "field of view"),
        ({"width": 0}, "image size"),
    ],
)
def test_bad_cameras(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(InputError, match=message):
        PinholeCamera(0.0, 45.0, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("camera", "light", "expected"),
    [
        # Camera on +x looking at the object: image right is +y, image up is +z.
        ((0.0, 90.0), (90.0, 90.0), (1.0, 0.0, 0.0)),
        ((0.0, 90.0), (0.0, 0.0), (0.0, 1.0, 0.0)),
        ((0.0, 90.0), (0.0, 90.0), (0.0, 0.0, 1.0)),
        ((0.0, 90.0), (180.0, 90.0), (0.0, 0.0, -1.0)),
        # Camera straight above (the RTI set-up): image right is +y, image up is -x.
        ((0.0, 0.0), (90.0, 90.0), (1.0, 0.0, 0.0)),
        ((0.0, 0.0), (180.0, 90.0), (0.0, 1.0, 0.0)),
        ((0.0, 0.0), (0.0, 0.0), (0.0, 0.0, 1.0)),
        # A light where the camera is points at the camera, whatever the pose.
        ((137.0, 61.0), (137.0, 61.0), (0.0, 0.0, 1.0)),
    ],
)
def test_known_directions_of_lights_in_the_camera_frame(
    camera: tuple[float, float], light: tuple[float, float], expected: tuple[float, ...]
) -> None:
    # The camera frame of a light (the frame of .lp files), as capture.lp_export uses it.
    towards = direction_from_angles_deg(*light)
    np.testing.assert_allclose(rig_to_camera(towards, PinholeCamera(*camera)), expected, atol=1e-12)
