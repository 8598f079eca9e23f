"""The motion-time model (rig.motion_time): trapezoids, the gantry's straight move, paths."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from rig.config import simulated_config
from rig.hardware import ServoArm
from rig.motion_time import move_seconds, move_seconds_matrix, path_seconds, pose_row, trapezoid_s
from rig.pose import RigPose


def test_motion_model_mirrors_the_hardware() -> None:
    config = simulated_config("/dev/ttyServos", "/dev/ttyGantry")
    servo = config.axes["camera_azimuth"]
    start = RigPose(0, 45, 0, 45)
    # A servo move alone: the driver's trapezoid.
    expected = float(trapezoid_s(100.0, servo.velocity_deg_s, servo.acceleration_deg_s2))
    assert move_seconds(config, start, RigPose(100, 45, 0, 45)) == pytest.approx(expected)
    # The servo arm allows the same time before a move times out.
    arm = ServoArm(config)
    end = {"camera_azimuth": 100.0, "camera_inclination": 45.0}
    assert arm.seconds_to(dict(start.items()), end) == pytest.approx(expected)
    # A diagonal gantry move: one straight move along its length at the feed.
    feed = config.axes["light_azimuth"].feed_deg_min / 60.0
    length = math.hypot(30.0, 40.0)
    acceleration = 360.0 * length / 40.0  # the axis carrying the most of the move limits it
    gantry = length / feed + feed / acceleration
    assert move_seconds(config, start, RigPose(0, 45, 30, 85)) == pytest.approx(gantry)
    # Together: the slower part.
    both = move_seconds(config, start, RigPose(100, 45, 30, 85))
    assert both == pytest.approx(max(expected, gantry))
    assert move_seconds(config, start, start) == 0.0


def test_a_trapezoid_cruises_or_stays_a_triangle() -> None:
    # v = 10 deg/s, a = 20 deg/s^2: the ramp covers v^2 / a = 5 degrees.
    np.testing.assert_allclose(trapezoid_s([0.0, 1.25, 5.0, 25.0], 10.0, 20.0),
                               [0.0, 0.5, 1.0, 3.0], rtol=1e-15)  # fmt: skip
    assert trapezoid_s(0.0, 10.0, 0.0) == 0.0  # a zero move takes no time, whatever a is


def test_paths_sum_their_moves() -> None:
    config = simulated_config("/dev/ttyServos", "/dev/ttyGantry")
    poses = [RigPose(0, 45, 0, 45), RigPose(30, 60, 10, 50), RigPose(-20, 30, 90, 20)]
    moves = [move_seconds(config, a, b) for a, b in itertools.pairwise(poses)]
    assert path_seconds(config, poses) == pytest.approx(sum(moves))
    assert path_seconds(config, poses[:1]) == 0.0
    rows = np.array([pose_row(p) for p in poses])
    matrix = move_seconds_matrix(config, rows, rows)
    assert matrix.shape == (3, 3) and np.all(np.diag(matrix) == 0.0)
    assert matrix[0, 1] == pytest.approx(moves[0]) and matrix[1, 2] == pytest.approx(moves[1])
