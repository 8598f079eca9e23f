"""Calibration end to end on the simulator: intrinsics, camera poses, light directions and
intensities recovered from rendered ChArUco boards, mirror spheres and white targets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from core.calibrated_camera import CalibratedCamera, CameraPose, Intrinsics
from core.camera_model import PinholeCamera
from core.directions import angle_between, direction_from_angles_deg, hemisphere_layout
from core.errors import DatasetError, InputError
from processing.calibration import Calibration
from processing.charuco import ChArUcoTarget, board_extrinsics, calibrate_intrinsics
from processing.light_falloff import WhiteReference, light_intensity_and_falloff
from processing.light_probe import MirrorSphere, light_directions_from_mirror_sphere
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
from tests.full_disk import writes_under_limit

TARGET = ChArUcoTarget()
LENS = LensDistortion(-0.12, 0.05)
CAMERA = PinholeCamera(0.0, 0.0, 4.0, 40.0, 640, 480)
#: Board poses for intrinsics: tilted 25-40 degrees every way, yawed, shifted.
INTRINSICS_POSES = [
    BoardPlacement.tilted(35.0, 0.0, 0.0, (0.2, 0.1, 0.0)),
    BoardPlacement.tilted(35.0, 90.0, 10.0, (-0.3, 0.0, 0.0)),
    BoardPlacement.tilted(35.0, 180.0, -10.0, (0.0, 0.3, 0.2)),
    BoardPlacement.tilted(35.0, 270.0, 20.0, (0.3, -0.2, 0.0)),
    BoardPlacement.tilted(25.0, 45.0, 90.0, (0.0, 0.0, 0.5)),
    BoardPlacement.tilted(40.0, 225.0, -30.0, (0.1, 0.1, -0.3)),
    BoardPlacement.tilted(40.0, 135.0, 45.0, (-0.2, 0.2, 0.3)),
    BoardPlacement.tilted(40.0, 315.0, -45.0, (0.2, -0.2, 0.3)),
]
SENSOR = Sensor(exposure_s=1.0 / 60.0)


@pytest.fixture(scope="module")
def intrinsics() -> Intrinsics:
    images = [
        record(render_charuco(TARGET.board(), CAMERA, pose, distortion=LENS), SENSOR, seed=i)
        for i, pose in enumerate(INTRINSICS_POSES)
    ]
    return calibrate_intrinsics(images, TARGET, zero_tangential=True)


def test_intrinsics_recovered(intrinsics: Intrinsics) -> None:
    f = CAMERA.focal_px
    assert abs(intrinsics.fx / f - 1) < 0.005 and abs(intrinsics.fy / f - 1) < 0.005
    # About 0.1 pixel of corner noise over 8 x 24 corners pins the principal point to ~1 pixel.
    assert abs(intrinsics.cx - 320.0) < 1.5 and abs(intrinsics.cy - 240.0) < 1.5
    assert intrinsics.rms_px < 0.5
    assert intrinsics.views == 8 and (intrinsics.width, intrinsics.height) == (640, 480)
    # The lens: compare where the model puts the image corner, not the correlated coefficients.
    calibrated = CalibratedCamera(intrinsics, CameraPose.from_pinhole(CAMERA))
    lens = (LENS.k1, LENS.k2, 0.0, 0.0, 0.0)
    truth = CalibratedCamera(
        Intrinsics(640, 480, f, f, 320.0, 240.0, lens), CameraPose.from_pinhole(CAMERA)
    )
    rays = truth.rays([20.5, 600.5], [20.5, 400.5])
    col, row, _ = calibrated.project(CAMERA.position + rays)
    # Within the principal point's error plus the lens's at the image's edge.
    assert np.allclose(col, [20.5, 600.5], atol=2.5) and np.allclose(row, [20.5, 400.5], atol=2.5)


@pytest.mark.parametrize(
    ("true_view", "nominal_view"),
    [((30.0, 30.0), (30.0, 30.0)), ((200.0, 50.0), (200.0, 50.0)), ((121.0, 64.0), (120.0, 65.0))],
)
def test_extrinsics_recovered(
    intrinsics: Intrinsics, true_view: tuple[float, float], nominal_view: tuple[float, float]
) -> None:
    truth = PinholeCamera(*true_view, 4.0, 40.0, 640, 480)
    nominal = PinholeCamera(*nominal_view, 4.05, 40.0, 640, 480)
    image = record(render_charuco(TARGET.board(), truth, distortion=LENS), SENSOR, seed=7)
    pose = board_extrinsics(image, intrinsics, TARGET, nominal=nominal)
    direction_error = np.degrees(angle_between(pose.position, truth.position))
    assert direction_error < 0.2
    assert abs(pose.distance / truth.distance - 1) < 0.01
    assert np.degrees(angle_between(pose.viewing_direction, -truth.direction)) < 0.2
    assert abs(pose.azimuth_deg - true_view[0]) < 0.3
    assert abs(pose.inclination_deg - true_view[1]) < 0.2
    assert pose.rms_px < 0.5 and pose.corners >= 20
    # The disagreement with the kinematics' camera is the offset put in, within the accuracy.
    assert pose.disagreement is not None
    expected = np.degrees(angle_between(truth.position, nominal.position))
    assert abs(pose.disagreement.direction_error_deg - expected) < 0.2
    assert abs(pose.disagreement.distance_error - (-0.05)) < 0.04


def test_no_board_names_the_image(intrinsics: Intrinsics) -> None:
    blank = np.full((480, 640, 3), 0.2, dtype=np.float32)
    with pytest.raises(InputError, match=r"board-at-pose-3\.png: found 0 ChArUco corners"):
        board_extrinsics(blank, intrinsics, TARGET, name="board-at-pose-3.png")
    views = [blank] * 3
    with pytest.raises(InputError, match="view-b"):
        calibrate_intrinsics(views, TARGET, names=["view-b", "view-a", "view-c"])


# --- light directions ---------------------------------------------------------------------------

SPHERE_CAMERA = PinholeCamera(0.0, 0.0, 4.0, 25.0, 320, 240)
SPHERE = MirrorSphere(radius=0.6)
#: Lights over the hemisphere up to 75 degrees from the zenith.
LIGHTS = hemisphere_layout(10)


def test_light_directions_from_mirror_sphere() -> None:
    sensor = Sensor(exposure_s=1.0 / 1200.0)  # the highlight saturates, as in a real capture
    images = [
        record(render_mirror_sphere(SPHERE_CAMERA, DiscLight(tuple(d)), radius=0.6), sensor, seed=i)
        for i, d in enumerate(LIGHTS)
    ]
    found = light_directions_from_mirror_sphere(images, SPHERE_CAMERA, SPHERE)
    assert found.shape == (len(LIGHTS), 3)
    assert np.degrees(angle_between(found, LIGHTS)).max() < 0.5


def test_point_light_directions_from_an_oblique_camera() -> None:
    camera = PinholeCamera(100.0, 30.0, 4.0, 25.0, 320, 240)
    lights = direction_from_angles_deg([0.0, 90.0, 250.0], [20.0, 60.0, 45.0])
    images = [
        render_mirror_sphere(camera, DiscLight(tuple(d), distance=3.0), radius=0.6) for d in lights
    ]
    found = light_directions_from_mirror_sphere(images, camera, SPHERE, light_distance=3.0)
    assert np.degrees(angle_between(found, lights)).max() < 0.5
    # Without the distance the directions are those from the highlight point: off by ~r / D.
    distant = light_directions_from_mirror_sphere(images, camera, SPHERE)
    assert np.degrees(angle_between(distant, lights)).max() > 1.0


def test_no_highlight_names_the_image() -> None:
    dark = render_mirror_sphere(SPHERE_CAMERA, DiscLight((0, 0, 1), irradiance=0.0), radius=0.6)
    lit = render_mirror_sphere(SPHERE_CAMERA, DiscLight((0, 0, 1)), radius=0.6)
    with pytest.raises(InputError, match=r"sphere-007\.tif: no highlight"):
        light_directions_from_mirror_sphere(
            [lit, dark], SPHERE_CAMERA, SPHERE, names=["sphere-006.tif", "sphere-007.tif"]
        )
    with pytest.raises(InputError, match="not in the camera's view"):
        light_directions_from_mirror_sphere([lit], SPHERE_CAMERA, MirrorSphere(0.1, (9, 9, 0)))


# --- intensities --------------------------------------------------------------------------------


@pytest.mark.parametrize("distance", [None, 3.0])
def test_light_intensities_and_falloff(distance: float | None) -> None:
    lights = LIGHTS[::2]
    strengths = np.array([0.8, 1.0, 1.1, 0.9, 1.2])
    reference = WhiteTarget(albedo=0.8, half_size=1.5)
    images = [
        record(
            render_white_target(CAMERA, DiscLight(tuple(d), distance, irradiance=e), reference),
            SENSOR,
            seed=i,
        )
        for i, (d, e) in enumerate(zip(lights, strengths, strict=True))
    ]
    result = light_intensity_and_falloff(
        images, CAMERA, lights, distances=distance, target=WhiteReference(0.8, 1.5)
    )
    assert np.allclose(result.relative, strengths / strengths.mean(), rtol=0.01)
    # Absolute: irradiance in 16-bit units (65535 = the sensor's saturation radiance).
    assert np.allclose(result.irradiance * SENSOR.saturation_radiance, strengths, rtol=0.01)
    if distance is None:
        assert np.isnan(result.falloff_exponent).all()
    else:
        assert np.allclose(result.falloff_exponent, 2.0, atol=0.02)
    assert (result.residual < 0.02).all() and (result.pixels > 1000).all()


# --- the calibration record ---------------------------------------------------------------------


def test_calibration_round_trips_through_json(intrinsics: Intrinsics) -> None:
    nominal = PinholeCamera(30.0, 30.0, 4.0, 40.0, 640, 480)
    pose = CameraPose.from_pinhole(nominal)
    pose = CameraPose(pose.position, pose.axes, 0.1, 24, pose.compare(nominal))
    calibration = Calibration.from_arrays(
        intrinsics,
        [pose, CameraPose.from_pinhole(CAMERA)],
        LIGHTS[:3],
        intensities=[0.9, 1.0, 1.1],
        positions=LIGHTS[:3] * 3.0,
        falloff_exponents=[2.0, np.nan, 1.98],
    )
    data = json.loads(json.dumps(calibration.to_dict(), allow_nan=False))
    assert data["schema"] == 1 and data["cameras"][0]["azimuth_deg"] == pytest.approx(30.0)
    assert data["lights"][1]["falloff_exponent"] is None
    again = Calibration.from_dict(data)
    assert again == calibration
    assert np.allclose(again.light_directions(), LIGHTS[:3])
    assert np.allclose(again.light_intensities(), [0.9, 1.0, 1.1])
    camera = again.camera(0)
    col, row, depth = camera.project([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1]])
    # The calibrated camera differs from the ideal pinhole by its principal point's error.
    ideal_col, ideal_row, ideal_depth = nominal.project([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1]])
    assert abs(col[0] - ideal_col[0]) < 2.0 and abs(row[0] - ideal_row[0]) < 2.0
    assert np.allclose(depth, ideal_depth)
    assert Calibration.from_dict({}) == Calibration()


def test_calibration_from_bad_data_is_refused() -> None:
    with pytest.raises(DatasetError, match="schema"):
        Calibration.from_dict({"schema": 99})
    with pytest.raises(DatasetError, match="intrinsics is missing"):
        Calibration.from_dict({"schema": 1, "intrinsics": {"width": 640}})
    with pytest.raises(DatasetError, match="axes"):
        Calibration.from_dict(
            {"schema": 1, "cameras": [{"position": [0, 0, 4], "axes": [[1, 0, 0]] * 3}]}
        )


def test_pinhole_camera_rays_and_projection_agree() -> None:
    camera = PinholeCamera(75.0, 40.0, 3.0, 50.0, 320, 200)
    calibrated = CalibratedCamera.from_pinhole(camera)
    points = np.random.default_rng(3).uniform(-0.5, 0.5, (20, 3))
    col, row, depth = calibrated.project(points)
    expected = camera.project(points)
    assert np.allclose(col, expected[0]) and np.allclose(row, expected[1])
    assert np.allclose(depth, expected[2])
    rays = calibrated.rays(col, row)
    towards = points - camera.position
    assert np.degrees(angle_between(rays, towards)).max() < 1e-6


def test_saving_a_calibration_on_a_full_disk_keeps_the_old_file(tmp_path: Path) -> None:
    # Written checked and atomically (a child under a real file size limit, tests/full_disk.py).
    target = tmp_path / "calibration.json"
    Calibration().save(target)
    before = target.read_bytes()
    lights = ", ".join(f"LightCalibration(({i / 100}, 0.0, 1.0))" for i in range(50))
    found = writes_under_limit(
        "from processing.calibration import Calibration, LightCalibration\n"
        f"attempt('save', lambda: Calibration(lights=({lights},)).save({str(target)!r}))\n",
        limit=len(before) + 10,
    )["save"]
    assert found["project"] and found["message"].startswith(f"{target}: cannot write"), found
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.json"]
