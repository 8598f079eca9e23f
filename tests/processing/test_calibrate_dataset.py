"""Calibration through the real capture path on the simulated rig.

``rig capture --sim --calibrate`` (3 cameras x 5 lights on the grid layout, 160-pixel images),
``rig calibrate`` and ``rig process``: the simulated rig has no kinematic error, so the
calibrated camera poses and light directions must agree with the commanded ones within the
calibration's own accuracy (``docs/calibration.md``, "Through the capture path").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.cli.calibrate import add_calibrate
from app.cli.process import add_process
from capture.dataset import Dataset
from core.camera_model import RigCamera
from core.directions import direction_from_angles_deg
from core.errors import DatasetError
from core.field_store import ReflectanceField
from processing.calibrate_dataset import DEFAULT_BOARD, DEFAULT_SPHERE, calibrate_dataset
from processing.calibration import Calibration
from sim import simulated_camera

#: Tolerances (measured: direction <= 0.18 deg, orientation <= 0.21 deg, distance <= 0.004 of
#: 4, lights <= 0.40 deg, relative intensities within 0.2 %).
CAMERA_DIRECTION_DEG = 0.3
CAMERA_ORIENTATION_DEG = 0.35
CAMERA_DISTANCE = 0.01
LIGHT_DEG = 0.6
INTENSITY = 0.01


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="rig")
    commands = parser.add_subparsers(dest="command", required=True)
    add_calibrate(commands)
    add_process(commands)
    args = parser.parse_args(argv)
    status: int = args.handler(args)
    return status


@pytest.fixture(scope="module")
def captured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("calibration") / "dataset"
    argv = ["capture", "--sim", "--calibrate", "--cameras", "3", "--lights", "5"]
    argv += ["--layout", "grid", "--size", "160", "--points", "1500", "--speed", "20"]
    argv += ["--exposure-ms", "40"]  # the targets well exposed (the default suits the sphere)
    assert main([*argv, "--quiet", "-o", str(path)]) == 0
    return path


def test_the_simulators_targets_are_the_default_ones() -> None:
    squares_x, squares_y, square, marker, dictionary = simulated_camera.BOARD
    board = DEFAULT_BOARD
    assert (board.squares_x, board.squares_y, board.square_length) == (squares_x, squares_y, square)
    assert (board.marker_length, board.dictionary) == (marker, dictionary)
    assert DEFAULT_SPHERE.radius == simulated_camera.MIRROR_SPHERE_RADIUS


def test_calibrate_recovers_the_simulated_rig(
    captured: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert run(["calibrate", str(captured)]) == 0
    out = capsys.readouterr().out
    assert "camera 2: direction" in out and "light 4: direction" in out and "problem" not in out
    dataset = Dataset.open(captured)
    calibration = Calibration.from_dict(dataset.calibration)
    plan = dataset.plan
    assert len(calibration.cameras) == 3 and len(calibration.lights) == 5
    for (azimuth, inclination), pose in zip(plan["cameras"], calibration.cameras, strict=True):
        assert pose.disagreement is not None
        assert pose.disagreement.direction_error_deg < CAMERA_DIRECTION_DEG
        assert pose.disagreement.orientation_error_deg < CAMERA_ORIENTATION_DEG
        assert abs(pose.distance - 4.0) < CAMERA_DISTANCE
        true = 4.0 * direction_from_angles_deg(azimuth, inclination)
        assert np.linalg.norm(np.asarray(pose.position) - true) < 0.03
    for (azimuth, inclination), light in zip(plan["lights"], calibration.lights, strict=True):
        true = direction_from_angles_deg(azimuth, inclination)
        angle = np.degrees(np.arccos(np.clip(np.dot(light.direction, true), -1.0, 1.0)))
        assert angle < LIGHT_DEG
        assert light.intensity is not None and abs(light.intensity - 1.0) < INTENSITY

    # rig process uses it: the store says so, and its geometry is the calibrated one.
    field = captured.parent / "field.zarr"
    assert run(["process", str(captured), "-o", str(field)]) == 0
    store = ReflectanceField.open(field)
    assert store.provenance["calibrated"] == ["cameras", "lights"]
    np.testing.assert_allclose(
        store.light_directions, calibration.light_directions(), rtol=0, atol=1e-6
    )


def test_the_library_function_reports_and_falls_back(captured: Path) -> None:
    dataset = Dataset.open(captured)
    nominal = RigCamera(4.0, 40.0, 160, 160)
    # Three flat-board views at one inclination do not fix the intrinsics (fx comes out about
    # 30 % off): below 6 views "auto" keeps the nominal camera.
    report = calibrate_dataset(dataset, nominal_camera=nominal, intrinsics="board")
    assert report.intrinsics_source == "board" and report.calibration.intrinsics is not None
    assert report.calibration.intrinsics.views == 3
    nominal_report = calibrate_dataset(dataset, nominal_camera=nominal)
    assert nominal_report.intrinsics_source == "nominal" and not nominal_report.problems
    assert set(nominal_report.cameras) == {0, 1, 2}
    assert max(nominal_report.light_errors_deg.values()) < LIGHT_DEG
    # A board of another size finds nothing: every camera stays nominal, each one named.
    from processing.charuco import ChArUcoTarget

    other = ChArUcoTarget(7, 5, 0.25, 0.18, "DICT_5X5_100")
    failed = calibrate_dataset(dataset, nominal_camera=nominal, board=other, intrinsics="nominal")
    assert not failed.cameras and sum("camera" in p for p in failed.problems) == 3
    json.dumps(failed.calibration.to_dict())


def test_a_dataset_without_calibration_images_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "plain"
    argv = ["capture", "--sim", "--cameras", "1", "--lights", "2", "--size", "32"]
    assert main([*argv, "--points", "300", "--speed", "20", "--quiet", "-o", str(path)]) == 0
    with pytest.raises(DatasetError, match="no calibration images"):
        calibrate_dataset(Dataset.open(path), nominal_camera=RigCamera(4.0, 40.0, 32, 32))
