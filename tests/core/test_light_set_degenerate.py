"""Measured light sets that no fit can use are named; every real layout passes (issue 28).

All lights in one direction, and all at or below a blocking horizon, were fitted (``pinv``
answers any design) or relit without a word.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from core.directions import direction_from_angles_deg, hemisphere_layout
from core.errors import DatasetError
from core.light_set import check_measured_lights, measured_lights_problem
from core.lp_format import read_lp
from core.sample_data import rti_capture_path

FAST = settings(max_examples=60, deadline=None)


def _problem(lights: NDArray[np.float64], *, blocked: bool = True) -> str | None:
    return measured_lights_problem(lights, blocked_below=blocked)


def _ring(count: int, inclination_deg: float, azimuth0: float = 0.0) -> NDArray[np.float64]:
    azimuths = azimuth0 + np.arange(count) * 360.0 / count
    return direction_from_angles_deg(azimuths, np.full(count, inclination_deg))


def _rotated_z(lights: NDArray[np.float64], degrees: float) -> NDArray[np.float64]:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return lights @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


# --- every real layout passes --------------------------------------------------------------


def test_the_bundled_rti_capture_passes() -> None:
    lp = rti_capture_path()
    assert _problem(read_lp(lp).directions) is None  # camera frame: z is the elevation


@pytest.mark.parametrize("layout", ["grid", "fibonacci"])
@pytest.mark.parametrize("count", [2, 3, 6, 12, 60, 240])
def test_hemisphere_layouts_pass(layout: str, count: int) -> None:
    assert _problem(hemisphere_layout(count, layout)) is None


@pytest.mark.parametrize(
    "lights",
    [
        _ring(8, 85.0),  # raking light: one ring 5 degrees above the horizon
        _ring(12, 45.0),  # a single ring (a PTM's constant and squared terms share it)
        np.vstack([_ring(6, 10.0), _ring(6, 15.0)]),  # a handheld capture's small cone
        direction_from_angles_deg([0.0, 90.0], [3.0, 3.0]),  # two lights 4 degrees apart
        # one arc over the object (a single view's normals across it are undetermined, yet
        # interpolation and the least-squares fits relight along it)
        direction_from_angles_deg([0.0] * 6 + [180.0] * 6, np.abs(np.linspace(-75, 75, 12))),
    ],
    ids=["raking ring", "one ring", "small cone", "two close lights", "one arc"],
)
def test_narrow_but_real_captures_pass(lights: NDArray[np.float64]) -> None:
    assert _problem(lights) is None


# --- what cannot work is named --------------------------------------------------------------


@FAST
@given(
    azimuth=st.floats(0.0, 360.0),
    inclination=st.floats(0.0, 180.0),
    spread_deg=st.floats(0.0, 0.7),
    count=st.integers(2, 50),
    seed=st.integers(0, 2**32 - 1),
)
def test_lights_in_one_direction_are_named(
    azimuth: float, inclination: float, spread_deg: float, count: int, seed: int
) -> None:
    centre = direction_from_angles_deg(azimuth, inclination)
    jitter = np.random.default_rng(seed).normal(size=(count, 3))
    jitter -= np.outer(jitter @ centre, centre)
    jitter *= np.tan(np.radians(spread_deg)) / np.maximum(
        np.linalg.norm(jitter, axis=1, keepdims=True), 1e-300
    )
    lights = centre + jitter
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    for blocked in (True, False):
        problem = _problem(lights, blocked=blocked)
        assert problem is not None
        assert problem.startswith(f"all {count} lights are within 1 degree of one direction")
        assert "a relightable fit needs lights spread over the dome" in problem


@FAST
@given(
    count=st.integers(2, 40),
    below_deg=st.floats(-80.0, 0.9),
    seed=st.integers(0, 2**32 - 1),
)
def test_no_light_above_a_blocking_horizon_is_named(
    count: int, below_deg: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    azimuths = rng.uniform(0.0, 360.0, count)
    azimuths[:2] = (0.0, 180.0)  # never one direction
    elevations = rng.uniform(-80.0, below_deg, count)
    elevations[0] = below_deg
    lights = direction_from_angles_deg(azimuths, 90.0 - elevations)
    problem = _problem(lights)
    assert problem is not None
    assert f"every one of the {count} lights is at or below the horizon (elevation <= 0" in problem
    # Nothing blocks them: a point field lit from below is a capture (the simulator's).
    assert _problem(lights, blocked=False) is None


@pytest.mark.parametrize("count", [2, 12, 240])
def test_lights_on_the_horizon_are_named(count: int) -> None:
    problem = _problem(_ring(count, 90.0))
    assert problem is not None and "at or below the horizon" in problem
    assert "the highest at 0.0 deg" in problem


@FAST
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(6, 80), yaw=st.floats(-720, 720))
def test_spread_lights_pass_and_yaw_changes_nothing(seed: int, count: int, yaw: float) -> None:
    # Lights spread over the upper dome (elevations 10..80 degrees, any azimuth, at least
    # three quadrants): what an RTI dome or a handheld capture measures.
    rng = np.random.default_rng(seed)
    azimuths = rng.uniform(0.0, 360.0, count)
    azimuths[:3] = (0.0, 120.0, 240.0)
    lights = direction_from_angles_deg(azimuths, rng.uniform(10.0, 80.0, count))
    assert _problem(lights) is None
    assert _problem(_rotated_z(lights, yaw)) is None


def test_check_names_the_file_and_keeps_shapes_to_their_own_checks(tmp_path: Path) -> None:
    where = tmp_path / "one.lp"
    with pytest.raises(DatasetError, match=rf"^{where}: all 5 lights are within 1 degree"):
        check_measured_lights(where, np.tile([0.0, 0.0, 1.0], (5, 1)), blocked_below=True)
    # One light, NaN and a wrong shape are refused elsewhere (fit: "at least 2 lights").
    for lights in (np.array([[0.0, 0.0, 1.0]]), np.full((4, 3), np.nan), np.ones((4, 2))):
        assert _problem(lights) is None
