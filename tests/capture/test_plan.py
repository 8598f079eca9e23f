from __future__ import annotations

import dataclasses
import itertools
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from capture.grid_plan import grid_plan
from capture.journal import ImageKey
from capture.plan import IMAGE_OVERHEAD_S, CalibrationCapture, CaptureEvent, SweepPlan
from capture.plan_file import load_plan, parse_plan
from core.directions import direction_from_angles_deg
from core.errors import InputError
from rig.config import AxisConfig, LightConfig, RigConfig, load_config, simulated_config
from rig.motion_time import move_seconds
from rig.pose import RigPose
from rig.safety import ForbiddenZone, SafetyConfig, path_violation, pose_violation

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "plan.example.toml"
RIG_EXAMPLE = EXAMPLE.with_name("rig.example.toml")


def _config(**safety: object) -> RigConfig:
    config = simulated_config("/dev/ttyServos", "/dev/ttyGantry")
    if safety:
        config = dataclasses.replace(config, safety=SafetyConfig(**safety))  # type: ignore[arg-type]
    return config


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plan.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _check_events(plan: SweepPlan, config: RigConfig) -> tuple[CaptureEvent, ...]:
    """Properties every plan's events have, whatever the ordering."""
    events = plan.events(config)
    keys = [e.key for e in events]
    assert len(set(keys)) == len(keys)
    assert tuple(keys) == plan.planned_keys(config)
    assert len({e.name for e in events}) == len(events)
    previous = config.park
    for event in events:
        assert pose_violation(config, event.pose) is None
        assert path_violation(config, previous, event.pose) is None
        assert event.light_on == (event.key.kind == "light")
        previous = event.pose
    # Each pose's exposures are consecutive; each camera's images are contiguous, darks first.
    runs = [(e.key.kind, e.key.camera_index, e.key.light_index) for e in events]
    for i, event in enumerate(events):
        assert event.exposure_ms == plan.exposures_ms[event.key.exposure_index]
        if event.key.exposure_index > 0:
            assert runs[i - 1] == runs[i] and events[i - 1].pose == event.pose
    order = [c for c, _ in itertools_groupby(e.key.camera_index for e in events)]
    assert len(order) == len(set(order))  # each camera's images are contiguous
    if plan.dark_frames:
        for c in set(order):
            mine = [e for e in events if e.key.camera_index == c]
            darks = len(plan.exposures_ms)
            assert [e.key.kind for e in mine[:darks]] == ["dark"] * darks
    return events


def itertools_groupby(values: object) -> list[tuple[int, int]]:
    import itertools

    return [(k, len(list(g))) for k, g in itertools.groupby(values)]  # type: ignore[call-overload]


# -- plans as data --------------------------------------------------------------------------------


def test_serpentine_events_are_exactly_the_sweep() -> None:
    config = _config()
    plan = SweepPlan(
        cameras=((0.0, 30.0), (180.0, 30.0)),
        lights=((90.0, 45.0), (270.0, 45.0)),
        exposures_ms=(10.0, 20.0),
        ordering="serpentine",
    )

    def pose(c: int, t: int) -> RigPose:
        return RigPose(*plan.cameras[c], *plan.lights[t])

    def event(kind: str, c: int, t: int | None, e: int, at: RigPose) -> CaptureEvent:
        key = ImageKey(kind, c, t, e)
        return CaptureEvent(key, at, (10.0, 20.0)[e], kind == "light", key.stem())

    assert list(plan.events(config)) == [
        event("dark", 0, None, 0, pose(0, 0)),
        event("dark", 0, None, 1, pose(0, 0)),
        event("light", 0, 0, 0, pose(0, 0)),
        event("light", 0, 0, 1, pose(0, 0)),
        event("light", 0, 1, 0, pose(0, 1)),
        event("light", 0, 1, 1, pose(0, 1)),
        event("dark", 1, None, 0, pose(1, 1)),
        event("dark", 1, None, 1, pose(1, 1)),
        event("light", 1, 1, 0, pose(1, 1)),
        event("light", 1, 1, 1, pose(1, 1)),
        event("light", 1, 0, 0, pose(1, 0)),
        event("light", 1, 0, 1, pose(1, 0)),
    ]
    assert plan.events(config)[2].name == "light_c000_l000_e0"
    assert plan.skipped(config) == ()


def test_no_dark_frames_and_one_exposure() -> None:
    plan = grid_plan(2, 3, exposures_ms=(5.0,), dark_frames=False)
    events = _check_events(plan, _config(min_separation_deg=0.0))
    assert Counter(e.key.kind for e in events) == {"light": 6}
    assert {e.exposure_ms for e in events} == {5.0}


@pytest.mark.parametrize("ordering", ["optimised", "serpentine"])
@pytest.mark.parametrize("layout", ["grid", "fibonacci"])
def test_every_planned_image_once_and_every_move_safe(ordering: str, layout: str) -> None:
    config = _config()  # min separation 10 degrees: same-direction pairs are refused
    plan = grid_plan(6, 12, exposures_ms=(10.0, 40.0), layout=layout, ordering=ordering)
    events = _check_events(plan, config)
    skipped = {(c, t) for c, t, _ in plan.skipped(config)}
    expected = {
        ImageKey("light", c, t, e)
        for c in range(6)
        for t in range(12)
        for e in range(2)
        if (c, t) not in skipped
    } | {ImageKey("dark", c, None, e) for c in range(6) for e in range(2)}
    assert {e.key for e in events} == expected
    for c, t, reason in plan.skipped(config):
        assert reason == pose_violation(config, RigPose(*plan.cameras[c], *plan.lights[t]))


def test_forbidden_pairs_are_skipped_and_listed() -> None:
    zone = ForbiddenZone("cable", light_azimuth_deg=(80.0, 100.0), camera_inclination_deg=(0, 40))
    config = _config(forbidden=(zone,))
    plan = SweepPlan(
        cameras=((0.0, 30.0), (0.0, 60.0)),
        lights=((90.0, 45.0), (200.0, 45.0), (95.0, 80.0)),
        exposures_ms=(10.0,),
    )
    skipped = plan.skipped(config)
    assert [(c, t) for c, t, _ in skipped] == [(0, 0), (0, 2)]
    assert all("forbidden zone 'cable'" in reason for _, _, reason in skipped)
    keys = set(plan.planned_keys(config))
    assert ImageKey("light", 0, 0, 0) not in keys and ImageKey("light", 1, 0, 0) in keys
    _check_events(plan, config)
    assert plan.estimate(config).skipped_pairs == 2


def test_unreachable_light_is_reordered_not_lost() -> None:
    # With the camera at az 180 incl 45, the straight light move from az 150 to az 210 (both at
    # incl 45) passes over the camera: the planner never makes it, yet takes every light.
    config = _config(min_separation_deg=10.0)
    plan = SweepPlan(
        cameras=((180.0, 45.0),),
        lights=((150.0, 45.0), (210.0, 45.0), (210.0, 90.0)),
        exposures_ms=(10.0,),
        ordering="serpentine",
    )
    assert path_violation(config, RigPose(180, 45, 150, 45), RigPose(180, 45, 210, 45))
    lights = [e.key.light_index for e in _check_events(plan, config) if e.key.kind == "light"]
    assert sorted(lights) == [0, 1, 2] and lights != [0, 1, 2]  # type: ignore[type-var]


def test_a_dead_end_start_is_avoided() -> None:
    # Lit from az 240 first, the camera at az 270 blocks every later move; the planner starts
    # the camera's lights elsewhere instead of leaving some out.
    plan = SweepPlan(
        cameras=((270.0, 45.0),),
        lights=((300.0, 60.0), (240.0, 45.0), (90.0, 60.0), (300.0, 30.0)),
        exposures_ms=(1.0,),
        dark_frames=False,
        ordering="serpentine",
    )
    events = _check_events(plan, _config())
    assert sorted(e.key.light_index for e in events) == [0, 1, 2, 3]  # type: ignore[type-var]


def test_unreachable_pairs_are_listed_with_the_unsafe_move() -> None:
    # Camera and lights on one ring: at camera 1 (az 180) the light cannot pass az 180, and the
    # camera cannot pass the light on its way there, so some pairs are unreachable.
    plan = grid_plan(2, 3, exposures_ms=(5.0,), dark_frames=False)
    config = _config()
    skipped = plan.skipped(config)
    unreachable = [reason for _, _, reason in skipped if reason.startswith("unreachable: ")]
    assert unreachable and all("is unsafe" in reason for reason in unreachable)
    assert len(plan.events(config)) + len(skipped) == 6
    _check_events(plan, config)


def test_a_camera_whose_lights_are_all_refused_still_takes_darks() -> None:
    zone = ForbiddenZone("arm", camera_azimuth_deg=(170.0, 190.0))
    config = _config(min_separation_deg=0.0)
    config = dataclasses.replace(config, safety=SafetyConfig(forbidden=(zone,)))
    plan = SweepPlan(
        cameras=((0.0, 30.0), (180.0, 30.0)), lights=((90.0, 45.0),), exposures_ms=(1.0,)
    )
    # The dark frame at camera 1 would itself be in the zone: it is left out with the reason.
    left = [u for u in plan.unplaced(config) if u.kind == "dark"]
    assert len(left) == 1 and "arm" in left[0].reason
    zone = ForbiddenZone("arm", camera_azimuth_deg=(170.0, 190.0), light_azimuth_deg=(80, 100))
    config = dataclasses.replace(config, safety=SafetyConfig(forbidden=(zone,)))
    events = _check_events(plan, config)
    assert [e.key for e in events if e.key.camera_index == 1] == [ImageKey("dark", 1, None, 0)]


# -- serialisation ------------------------------------------------------------------------------


def test_to_dict_from_dict_round_trip() -> None:
    plan = SweepPlan(
        cameras=((0.0, 30.0), (120.0, 60.0)),
        lights=((10.0, 20.0),),
        exposures_ms=(5.0, 20.0),
        dark_frames=False,
        ordering="serpentine",
        calibration=(
            CalibrationCapture("charuco", 1, None, (30.0,)),
            CalibrationCapture("mirror-sphere", 0, 0, (2.0,)),
        ),
    )
    data = json.loads(json.dumps(plan.to_dict()))
    again = SweepPlan.from_dict(data)
    assert again == plan and hash(again) == hash(plan)
    assert again.to_dict() == plan.to_dict()
    example = load_plan(EXAMPLE)
    assert SweepPlan.from_dict(json.loads(json.dumps(example.to_dict()))) == example


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"schema_version": 2}, "schema_version = 2"),
        ({"colour": 1}, "unknown keys ['colour']"),
        ({"exposures_ms": []}, "at least one exposure"),
        ({"cameras": [[0, 95]]}, "cameras[0] inclination_deg = 95 is outside 0..90"),
        ({"ordering": "random"}, "ordering = 'random'"),
        ({"calibration": [{"name": "x", "camera_index": 5, "light_index": None,
                           "exposures_ms": [1]}]}, "camera_index 5 is not a camera"),
    ],
)  # fmt: skip
def test_from_dict_refuses_bad_plans(change: dict[str, object], message: str) -> None:
    data = grid_plan(2, 2).to_dict() | change
    with pytest.raises(InputError, match=_escaped(message)):
        SweepPlan.from_dict(data)


def _escaped(text: str) -> str:
    import re

    return re.escape(text)


# -- the TOML form ------------------------------------------------------------------------------


def test_example_plan_loads() -> None:
    plan = load_plan(EXAMPLE)
    assert len(plan.cameras) == 16 and len(plan.lights) == 36
    assert plan.cameras[:3] == ((-157.5, 30.0), (-112.5, 30.0), (-67.5, 30.0))
    assert plan.cameras[8] == (-157.5, 60.0)
    assert plan.lights[19] == (45.0, 45.0)
    assert plan.exposures_ms == (10.0, 40.0, 160.0)
    names = Counter(c.name for c in plan.calibration)
    assert names == {"charuco": 16, "mirror-sphere": 36, "white-target": 36}
    assert plan.calibration[0] == CalibrationCapture("charuco", 0, 19, (20.0,))
    assert plan.calibration[16] == CalibrationCapture("mirror-sphere", 0, 0, (5.0,))
    assert plan.calibration[-1].exposures_ms == plan.exposures_ms  # the plan's bracket
    config = _config()
    events = plan.events(config)
    first = events[0]
    assert first.key.kind == "calibration" and first.name.endswith("_charuco") and first.light_on
    # The example pair is runnable: every pose within the limits.
    assert all(check.ok for check in plan.limit_checks(load_config(RIG_EXAMPLE)))
    calibration = [e for e in events if e.key.kind == "calibration"]
    assert events[: len(calibration)] == tuple(calibration)  # calibration before the sweep
    assert len({e.key for e in events}) == len(events)


def test_ranges_lists_and_layouts(tmp_path: Path) -> None:
    plan = load_plan(
        _write(
            tmp_path,
            """
            exposures_ms = [10]
            dark_frames = false
            ordering = "serpentine"
            [cameras]
            azimuth_deg = {start = 0, stop = 360, step = 90}
            inclination_deg = {start = 30, stop = 90, step = 30}
            [lights]
            poses_deg = [[0, 0], [45.5, 89]]
            [[calibration]]
            name = "dark-board"
            cameras = [1, 2]
            lights = "off"
            """,
        )
    )
    azimuths = [0.0, 90.0, 180.0, 270.0]  # 360 is 0 again: not repeated
    assert plan.cameras == tuple((a, i) for i in (30.0, 60.0, 90.0) for a in azimuths)
    assert plan.lights == ((0.0, 0.0), (45.5, 89.0))
    assert not plan.dark_frames and plan.ordering == "serpentine"
    assert plan.calibration == (
        CalibrationCapture("dark-board", 1, None, (10.0,)),
        CalibrationCapture("dark-board", 2, None, (10.0,)),
    )
    events = plan.events(_config(min_separation_deg=0.0))
    assert [e.light_on for e in events[:2]] == [False, False]
    assert events[0].key == ImageKey("calibration", 1, 0, 0)

    partial = parse_plan(
        {
            "exposures_ms": [1],
            "cameras": {
                "azimuth_deg": {"start": 10, "stop": 100, "step": 40},
                "inclination_deg": 45,
            },
            "lights": {"layout": "grid", "count": 5},
        }
    )
    assert partial.cameras == ((10.0, 45.0), (50.0, 45.0), (90.0, 45.0))
    assert partial.lights == grid_plan(1, 5).lights


BASE = """
exposures_ms = [10, 20]
[cameras]
azimuth_deg = [0, 90]
inclination_deg = [45]
[lights]
layout = "fibonacci"
count = 8
"""


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("colour = 'red'\n" + BASE, "unknown key colour; keys here are:"),
        (BASE.replace("azimuth_deg = [0, 90]", "azimuth = [0, 90]"), "unknown key cameras.azimuth"),
        (
            BASE.replace("[0, 90]", "{start = 0, stop = 90, step = 0}"),
            "cameras.azimuth_deg.step = 0 must be positive",
        ),
        (
            BASE.replace("[0, 90]", "{start = 90, stop = 0, step = 10}"),
            "cameras.azimuth_deg.stop = 0 is below start = 90",
        ),
        (BASE.replace("[45]", "[45, 100]"), "cameras.inclination_deg[1] = 100 is outside 0..90"),
        (BASE.replace("[45]", "-5"), "cameras.inclination_deg = -5 is outside 0..90"),
        (
            BASE.replace("[45]", "{start = 30, stop = 120, step = 30}"),
            "cameras.inclination_deg = {start, stop, step} gives 120, which is outside 0..90",
        ),
        (BASE.replace("[10, 20]", "[]"), "exposures_ms = [] is empty"),
        (BASE.replace("[10, 20]", "[10, -5]"), "exposures_ms[1] = -5 must be positive"),
        (BASE.replace("[10, 20]", "[10, 'x']"), "exposures_ms[1] = 'x' must be a finite number"),
        (BASE.replace("exposures_ms = [10, 20]", ""), "exposures_ms is missing"),
        (BASE.replace('layout = "fibonacci"', 'layout = "spiral"'), "lights.layout = 'spiral'"),
        (BASE.replace("count = 8", "count = 0"), "lights.count = 0 must be in 1..10000"),
        ("ordering = 'fastest'\n" + BASE, "ordering = 'fastest' is not one of"),
        (
            BASE.replace("count = 8", "count = 8\nposes_deg = [[0, 0]]"),
            "[lights] needs exactly one of",
        ),
        (
            BASE.replace('layout = "fibonacci"\ncount = 8', "poses_deg = [[0, 91]]"),
            "lights.poses_deg[0] inclination_deg = 91 is outside 0..90",
        ),
        (BASE + "[[calibration]]\nname = 'Board'\ncameras = 'all'\nlights = 'off'\n", "lowercase"),
        (
            BASE + "[[calibration]]\nname = 'board'\ncameras = [2]\nlights = 'off'\n",
            "calibration[0].cameras[0] = 2 is not an index in 0..1",
        ),
        (
            BASE + "[[calibration]]\nname = 'board'\ncameras = 'all'\nlights = 'some'\n",
            "calibration[0].lights = 'some' is not 'off' or 'all'",
        ),
        (
            BASE + "[[calibration]]\nname = 'board'\ncameras = 'all'\nlight = 'off'\n",
            "unknown key calibration[0].light",
        ),
        (
            BASE + "[[calibration]]\nname = 'a'\ncameras = 'all'\nlights = 'off'\n" * 2,
            "calibration[1].name = 'a' is used twice",
        ),
        ("schema_version = 3\n" + BASE, "schema_version = 3; only 1 is read"),
        ("exposures_ms = [1", "not valid TOML"),
    ],
)
def test_bad_plan_files_name_file_key_and_value(tmp_path: Path, text: str, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as error:
        load_plan(path)
    assert str(error.value).startswith(f"{path}: ")
    assert message in str(error.value)


def test_missing_plan_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read the plan"):
        load_plan(tmp_path / "nope.toml")


# -- ordering and estimates ---------------------------------------------------------------------


def test_estimate_counts_and_duration() -> None:
    config = dataclasses.replace(_config(), light=LightConfig(settle_s=0.25))
    plan = grid_plan(4, 10, exposures_ms=(10.0, 30.0))
    estimate = plan.estimate(config)
    events = plan.events(config)
    assert (estimate.cameras, estimate.lights, estimate.exposures) == (4, 10, 2)
    assert estimate.images == {
        "light": 80 - 2 * estimate.skipped_pairs,
        "dark": 8,
        "calibration": 0,
    }
    assert estimate.total_images == len(events)
    assert estimate.exposure_s == pytest.approx(sum(e.exposure_ms for e in events) / 1000)
    # Light switches: on at each camera's first light image and off for the next darks.
    assert estimate.overhead_s == pytest.approx(IMAGE_OVERHEAD_S * len(events) + 8 * 0.25)
    poses = [config.park, *(e.pose for e in events), config.park]
    motion = sum(move_seconds(config, a, b) for a, b in itertools.pairwise(poses))
    assert estimate.motion_s == pytest.approx(motion)
    assert estimate.total_s == pytest.approx(motion + estimate.exposure_s + estimate.overhead_s)
    assert estimate.gain_s > 0.0 and 0.0 < estimate.gain_fraction < 1.0
    serpentine = dataclasses.replace(plan, ordering="serpentine").estimate(config)
    assert serpentine.motion_s == pytest.approx(estimate.motion_by_ordering_s["serpentine"])


def _axis(
    role: str, device: str, servo_id: int | None, letter: str | None, speed: float
) -> AxisConfig:
    low, high = (0.0, 359.0) if role.endswith("azimuth") else (0.0, 90.0)
    if device == "dynamixel":
        return AxisConfig(role, "dynamixel", low, high, servo_id=servo_id, velocity_deg_s=speed)
    return AxisConfig(role, "grbl", low, high, grbl_axis=letter, feed_deg_min=60 * speed)


angles = st.tuples(st.floats(0.0, 359.0, allow_nan=False), st.floats(0.0, 90.0, allow_nan=False))


@settings(max_examples=40)
@given(
    cameras=st.lists(angles, min_size=1, max_size=4),
    lights=st.lists(angles, min_size=1, max_size=7),
    speeds=st.lists(st.floats(5.0, 200.0), min_size=4, max_size=4),
    separation=st.sampled_from([0.0, 10.0]),
)
def test_optimised_is_never_slower_than_serpentine(
    cameras: list[tuple[float, float]],
    lights: list[tuple[float, float]],
    speeds: list[float],
    separation: float,
) -> None:
    base = _config(min_separation_deg=separation)
    axes = {
        "camera_azimuth": _axis("camera_azimuth", "dynamixel", 1, None, speeds[0]),
        "camera_inclination": _axis("camera_inclination", "dynamixel", 2, None, speeds[1]),
        "light_azimuth": _axis("light_azimuth", "grbl", None, "X", speeds[2]),
        "light_inclination": _axis("light_inclination", "grbl", None, "Y", speeds[3]),
    }
    config = dataclasses.replace(base, axes=axes)
    plan = SweepPlan(cameras=tuple(cameras), lights=tuple(lights), exposures_ms=(1.0,))
    estimate = plan.estimate(config)
    baseline = dataclasses.replace(plan, ordering="serpentine")
    if len(plan.unplaced(config)) == len(baseline.unplaced(config)):
        assert estimate.gain_s >= -1e-9
    _check_events(plan, config)


def test_limit_checks() -> None:
    config = _config()
    plan = SweepPlan(
        cameras=((-10.0, 30.0), (200.0, 60.0)), lights=((0.0, 90.0),), exposures_ms=(1,)
    )
    checks = {c.role: c for c in plan.limit_checks(config)}
    assert set(checks) == {
        "camera_azimuth",
        "camera_inclination",
        "light_azimuth",
        "light_inclination",
    }
    azimuth = checks["camera_azimuth"]
    assert (azimuth.low_deg, azimuth.high_deg, azimuth.min_deg, azimuth.max_deg) == (
        -10,
        200,
        0,
        359,
    )
    assert not azimuth.ok and checks["light_inclination"].ok
    # The out-of-limit camera's pairs are skipped, with the limit named.
    assert plan.skipped(config)[0][2].startswith("camera_azimuth_deg = -10 is below")


# -- the grid plan matches the simulator's fields -------------------------------------------------


@pytest.mark.parametrize("layout", ["grid", "fibonacci"])
@pytest.mark.parametrize("count", [1, 7, 30])
def test_grid_plan_cameras_are_the_simulators(layout: str, count: int) -> None:
    from sim.field import field_cameras

    plan = grid_plan(count, 3, layout=layout)
    assert plan.cameras == tuple(
        (c.azimuth_deg, c.inclination_deg) for c in field_cameras(count, layout)
    )


@pytest.mark.parametrize("layout", ["grid", "hemisphere"])
def test_grid_plan_lights_are_the_simulators(tmp_path: Path, layout: str) -> None:
    from core.field_store import ReflectanceField
    from sim.field import field_cameras, simulate_field

    sim_layout = "fibonacci" if layout == "hemisphere" else layout
    store = tmp_path / "field.zarr"
    cameras = field_cameras(2, sim_layout, width=8, height=8)
    simulate_field(store, "diffuse-sphere", lights=9, cameras=cameras, points=64, layout=sim_layout)
    field = ReflectanceField.open(store)
    plan = grid_plan(2, 9, layout=layout)
    np.testing.assert_allclose(
        direction_from_angles_deg(*np.array(plan.lights).T), field.light_directions, atol=1e-12
    )
    np.testing.assert_allclose(
        direction_from_angles_deg(*np.array(plan.cameras).T), field.camera_directions, atol=1e-12
    )


def test_grid_plan_refuses_unknown_layouts() -> None:
    with pytest.raises(InputError, match="unknown layout 'spiral'"):
        grid_plan(2, 2, layout="spiral")
    with pytest.raises(InputError, match="positive count"):
        grid_plan(0, 2)
