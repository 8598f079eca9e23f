"""The simulator's calibration scenes: geometry and radiometry against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.errors import InputError
from processing.charuco import ChArUcoTarget, detect_board
from sim.calibration_targets import (
    BoardPlacement,
    DiscLight,
    LensDistortion,
    WhiteTarget,
    record,
    render_charuco,
    render_mirror_sphere,
    render_white_target,
)
from sim.sensor import Sensor

OVERHEAD = PinholeCamera(0.0, 0.0, 4.0, 40.0, 320, 240)


def _true_corners(
    target: ChArUcoTarget,
    placement: BoardPlacement,
    camera: PinholeCamera,
    lens: LensDistortion,
    object_points: np.ndarray,
) -> np.ndarray:
    """OpenCV pixel coordinates (N, 2) of board points, by the forward lens model."""
    rotation = placement.matrix
    half = 0.5 * target.square_length * np.array([target.squares_x, target.squares_y, 0.0])
    points = object_points @ rotation.T + (np.asarray(placement.centre) - rotation @ half)
    right, up, forward = camera.axes()
    relative = points - camera.position
    x = relative @ right / (relative @ forward)
    y = -(relative @ up) / (relative @ forward)
    r2 = x * x + y * y
    scale = 1.0 + lens.k1 * r2 + lens.k2 * r2 * r2
    f = camera.focal_px
    return np.stack(
        [f * x * scale + camera.width / 2 - 0.5, f * y * scale + camera.height / 2 - 0.5], 1
    )


@pytest.mark.parametrize(
    ("placement", "lens"),
    [
        (BoardPlacement(), LensDistortion()),
        (BoardPlacement.tilted(30.0, 60.0, 15.0, (0.1, -0.1, 0.2)), LensDistortion(-0.1, 0.04)),
    ],
)
def test_board_corners_land_where_the_camera_model_puts_them(
    placement: BoardPlacement, lens: LensDistortion
) -> None:
    target = ChArUcoTarget()
    camera = PinholeCamera(20.0, 25.0, 4.0, 40.0, 640, 480)
    image = render_charuco(target.board(), camera, placement, distortion=lens)
    assert image.shape == (480, 640, 3) and image.dtype == np.float32
    view = detect_board(image, target)
    truth = _true_corners(target, placement, camera, lens, view.object_points.astype(np.float64))
    error = np.linalg.norm(view.image_points - truth, axis=1)
    assert len(error) >= 20
    assert np.sqrt(np.mean(error**2)) < 0.15


def test_board_radiance_levels() -> None:
    target = ChArUcoTarget()
    image = render_charuco(target.board(), OVERHEAD, white=0.8, black=0.04, background=0.15)
    values = np.unique(np.round(image[..., 0], 6))
    for level in (0.8, 0.04, 0.15):
        assert np.isclose(values, level).any()
    assert image.min() >= 0.04 - 1e-6 and image.max() <= 0.8 + 1e-6
    assert np.array_equal(image[..., 0], image[..., 2])


def test_lens_distortion_inverts_the_forward_model() -> None:
    lens = LensDistortion(-0.15, 0.06)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-0.4, 0.4, (2, 1000))
    r2 = x * x + y * y
    scale = 1.0 + lens.k1 * r2 + lens.k2 * r2 * r2
    ux, uy = lens.undistort(x * scale, y * scale)
    assert np.allclose(ux, x, atol=1e-12) and np.allclose(uy, y, atol=1e-12)


def test_mirror_sphere_highlight_and_levels() -> None:
    light = DiscLight((0.0, 0.0, 1.0), angular_size_deg=4.0, irradiance=2.0)
    image = render_mirror_sphere(
        OVERHEAD, light, radius=0.6, reflectance=0.7, environment=0.02, supersample=1
    )
    # Camera and light both overhead: the highlight is at the image centre.
    assert np.isclose(image[120, 160, 0], 0.7 * light.radiance, rtol=1e-6)
    assert np.isclose(light.radiance * 2 * math.pi * (1 - math.cos(math.radians(2.0))), 2.0)
    # A corner pixel sees the dim surround directly (looking down: 0.6 - 0.4 cos).
    assert 0.02 * 0.2 <= image[0, 0, 0] <= 0.02 * 0.6
    # Off the highlight the sphere reflects the surround, dimmed by the reflectance.
    assert 0.7 * 0.02 * 0.2 <= image[120, 160 + 40, 0] <= 0.7 * 0.02
    assert image.max() == pytest.approx(0.7 * light.radiance)


def test_mirror_sphere_point_light_seen_in_reflection() -> None:
    light = DiscLight((0.0, 0.0, 1.0), distance=3.0, angular_size_deg=4.0)
    image = render_mirror_sphere(OVERHEAD, light, radius=0.6)
    row, col = np.unravel_index(np.argmax(image[..., 0]), image.shape[:2])
    assert abs(row - 119.5) <= 1 and abs(col - 159.5) <= 1


def test_white_target_cosine_and_inverse_square() -> None:
    target = WhiteTarget(albedo=0.5, half_size=2.0)
    tilted = (math.sin(math.radians(60)), 0.0, math.cos(math.radians(60)))
    directional = render_white_target(OVERHEAD, DiscLight(tilted, irradiance=3.0), target)
    # Centre pixel: rho / pi x E cos(60).
    assert directional[120, 160, 0] == pytest.approx(0.5 / math.pi * 3.0 * 0.5, rel=1e-6)
    assert np.allclose(directional[5:-5, 5:-5], directional[120, 160, 0])
    near = render_white_target(OVERHEAD, DiscLight((0, 0, 1), distance=2.0), target)
    # Straight below the light the irradiance is E0 (defined at the origin).
    assert near[120, 160, 0] == pytest.approx(0.5 / math.pi, rel=1e-3)
    # Off axis: point x at distance r from the light gets E0 D^2 cos / r^2 with cos = D / r.
    ray_col = 300.5
    x = (ray_col - 160) / OVERHEAD.focal_px * 4.0  # the pixel centre's ground position
    r = math.hypot(x, 2.0)
    expected = 0.5 / math.pi * 4.0 * (2.0 / r) / r**2
    assert near[120, 300, 0] == pytest.approx(expected, rel=1e-5)  # row centre 0.5 px off
    assert near[0, 0, 0] > 0 and near.shape == (240, 320, 3)


def test_record_through_the_sensor() -> None:
    image = render_white_target(OVERHEAD, DiscLight((0, 0, 1)))
    sensor = Sensor(noise=False)
    linear = record(image, sensor)
    srgb = record(image, sensor, output="srgb8")
    assert linear.dtype == np.uint16 and srgb.dtype == np.uint8
    assert linear.shape == srgb.shape == (240, 320, 3)
    expected = image[120, 160, 0] / sensor.saturation_radiance * 65535
    assert abs(int(linear[120, 160, 0]) - expected) <= 10
    with pytest.raises(InputError, match="unknown output"):
        record(image, sensor, output="jpeg")  # type: ignore[arg-type]


def test_invalid_targets_are_refused() -> None:
    with pytest.raises(InputError, match="angular size"):
        DiscLight((0, 0, 1), angular_size_deg=0.0)
    with pytest.raises(InputError, match="distance"):
        DiscLight((0, 0, 1), distance=-1.0)
    with pytest.raises(InputError):
        DiscLight((0, 0, 0))
    with pytest.raises(InputError, match="inside the mirror sphere"):
        render_mirror_sphere(PinholeCamera(0, 0, 0.5), DiscLight((0, 0, 1)), radius=0.6)
    with pytest.raises(InputError, match="supersample"):
        render_white_target(OVERHEAD, DiscLight((0, 0, 1)), supersample=0)
