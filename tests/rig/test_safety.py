from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import ConfigError, SafetyError
from rig.config import RigConfig, load_config
from rig.pose import RigPose
from rig.safety import (
    ForbiddenZone,
    SafetyConfig,
    check_path,
    check_pose,
    path_is_safe,
    path_violation,
    pose_violation,
    relative_azimuth_deg,
    separation_deg,
    unsafe_poses,
)

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "rig.example.toml"
CONFIG = load_config(EXAMPLE)
SAFE = RigPose(0.0, 45.0, 180.0, 45.0)


def test_the_park_pose_is_safe() -> None:
    check_pose(CONFIG, CONFIG.park)
    assert pose_violation(CONFIG, CONFIG.park) is None


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (
            {"camera_inclination_deg": 2.0},
            r"camera_inclination_deg = 2 is below axes\.camera_inclination\.min_deg = 5",
        ),
        (
            {"light_inclination_deg": 81.5},
            r"light_inclination_deg = 81\.5 is above axes\.light_inclination\.max_deg = 80",
        ),
        ({"turntable_deg": 3.0}, r"turntable_deg = 3 but the rig has no turntable axis"),
        (
            {"light_azimuth_deg": 10.0, "light_inclination_deg": 45.0},
            r"camera and light are 7\.0\d* deg apart, closer than safety\.min_separation_deg = 12",
        ),
        (
            {"camera_azimuth_deg": 100.0, "light_inclination_deg": 20.0},
            r"the pose is in forbidden zone 'drag chain' \(camera_azimuth_deg in \[90, 110\], "
            r"light_inclination_deg in \[0, 30\]\)",
        ),
        (
            {
                "camera_inclination_deg": 70.0,
                "light_inclination_deg": 70.0,
                "light_azimuth_deg": 20.0,
                "camera_azimuth_deg": 0.0,
            },
            r"the pose is in forbidden zone 'light arm under camera arm'",
        ),
    ],
)
def test_unsafe_poses_name_the_axis_limit_or_zone(changes: dict[str, float], message: str) -> None:
    pose = dataclasses.replace(SAFE, **changes)
    with pytest.raises(SafetyError, match=r"^refused to move to camera az .*: " + message):
        check_pose(CONFIG, pose)


def test_relative_azimuth_wraps() -> None:
    assert relative_azimuth_deg(RigPose(170.0, 45.0, -170.0, 45.0)) == pytest.approx(20.0)
    assert relative_azimuth_deg(RigPose(-170.0, 45.0, 170.0, 45.0)) == pytest.approx(-20.0)
    assert relative_azimuth_deg(RigPose(0.0, 45.0, 180.0, 45.0)) == pytest.approx(-180.0)


def test_a_wrapping_zone_covers_the_far_side() -> None:
    zone = ForbiddenZone("behind", relative_azimuth_deg=(170.0, -170.0))
    assert zone.contains(RigPose(0.0, 45.0, 175.0, 45.0))
    assert zone.contains(RigPose(0.0, 45.0, -175.0, 45.0))
    assert zone.contains(RigPose(10.0, 45.0, -175.0, 45.0))  # relative 175
    assert not zone.contains(RigPose(0.0, 45.0, 160.0, 45.0))


def test_separation_is_the_angle_between_directions() -> None:
    assert separation_deg(RigPose(0.0, 90.0, 90.0, 90.0)) == pytest.approx(90.0)
    assert separation_deg(RigPose(123.0, 0.0, 300.0, 0.0)) == pytest.approx(0.0, abs=1e-9)
    assert separation_deg(RigPose(0.0, 30.0, 180.0, 30.0)) == pytest.approx(60.0)


def test_a_move_through_a_zone_is_refused_though_both_ends_are_safe() -> None:
    start = RigPose(60.0, 45.0, 180.0, 20.0)
    end = RigPose(140.0, 45.0, 180.0, 20.0)  # camera sweeps through the drag chain zone
    check_pose(CONFIG, start)
    check_pose(CONFIG, end)
    assert not path_is_safe(CONFIG, start, end)
    problem = path_violation(CONFIG, start, end)
    assert problem is not None and "38% of the way" in problem and "'drag chain'" in problem
    with pytest.raises(SafetyError, match=r"^refused: the move from .* is unsafe"):
        check_path(CONFIG, start, end)
    # The same sweep with the light raised out of the zone passes.
    assert path_is_safe(
        CONFIG,
        dataclasses.replace(start, light_inclination_deg=45.0),
        dataclasses.replace(end, light_inclination_deg=45.0),
    )


def test_arms_passing_through_each_other_are_refused() -> None:
    start = RigPose(-40.0, 45.0, 40.0, 45.0)
    end = RigPose(40.0, 45.0, -40.0, 45.0)  # camera and light swap sides
    assert pose_violation(CONFIG, start) is None and pose_violation(CONFIG, end) is None
    problem = path_violation(CONFIG, start, end)
    assert problem is not None and "closer than safety.min_separation_deg" in problem


def test_an_unsafe_start_is_reported() -> None:
    start = RigPose(0.0, 2.0, 180.0, 45.0)
    problem = path_violation(CONFIG, start, SAFE)
    assert problem is not None and "unsafe at its start" in problem


def test_a_zero_length_move_is_the_pose_check() -> None:
    assert path_is_safe(CONFIG, SAFE, SAFE)
    with pytest.raises(SafetyError, match="step must be positive"):
        path_violation(CONFIG, SAFE, SAFE, step_deg=0.0)


def test_safety_config_validates() -> None:
    with pytest.raises(ConfigError, match="duplicate zone name 'a'"):
        SafetyConfig(
            forbidden=(
                ForbiddenZone("a", camera_azimuth_deg=(0.0, 1.0)),
                ForbiddenZone("a", camera_azimuth_deg=(2.0, 3.0)),
            )
        )
    with pytest.raises(ConfigError, match=r"path_step_deg = 0\.0 must be positive"):
        SafetyConfig(path_step_deg=0.0)


def _no_limits() -> RigConfig:
    wide = {
        role: dataclasses.replace(axis, min_deg=-400.0, max_deg=400.0)
        for role, axis in CONFIG.axes.items()
    }
    return dataclasses.replace(CONFIG, axes=wide)


angles = st.floats(-180.0, 180.0, allow_nan=False)
poses = st.builds(RigPose, angles, st.floats(5.0, 85.0), angles, st.floats(0.0, 80.0))


@settings(max_examples=60)
@given(start=poses, end=poses)
def test_a_safe_path_has_safe_ends_and_check_pose_agrees(start: RigPose, end: RigPose) -> None:
    for pose in (start, end):
        problem = pose_violation(CONFIG, pose)
        if problem is None:
            check_pose(CONFIG, pose)
        else:
            with pytest.raises(SafetyError):
                check_pose(CONFIG, pose)
    if path_is_safe(CONFIG, start, end, step_deg=5.0):
        assert pose_violation(CONFIG, start) is None and pose_violation(CONFIG, end) is None


def test_limits_checks_are_pure_and_need_no_device() -> None:
    config = _no_limits()
    before = config.to_toml()
    pose = RigPose(350.0, 45.0, 170.0, 45.0)
    assert pose_violation(config, pose) is None
    assert pose_violation(CONFIG, pose) is not None
    assert config.to_toml() == before


wide_angles = st.floats(-200.0, 200.0, allow_nan=False)
any_poses = st.builds(RigPose, wide_angles, st.floats(0.0, 95.0), wide_angles,
                      st.floats(-5.0, 95.0))  # fmt: skip


@settings(max_examples=200)
@given(pose_list=st.lists(any_poses, min_size=1, max_size=20))
def test_the_array_check_agrees_with_the_pose_check(pose_list: list[RigPose]) -> None:
    # The dry run screens thousands of path samples at once with unsafe_poses; it must
    # flag exactly what pose_violation refuses (limits, separation and every zone kind).
    degrees = np.array([[value for _, value in pose.items()] for pose in pose_list])
    flagged = unsafe_poses(CONFIG, degrees)
    assert CONFIG.safety.forbidden and CONFIG.safety.min_separation_deg > 0
    assert list(flagged) == [pose_violation(CONFIG, pose) is not None for pose in pose_list]
