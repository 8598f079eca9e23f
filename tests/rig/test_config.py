from __future__ import annotations

import copy
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from core.errors import ConfigError, InputError
from rig.config import (
    AxisConfig,
    OpenCVCameraConfig,
    RigConfig,
    load_config,
    parse_config,
    simulated_config,
)
from rig.config_schema import dump_toml
from rig.pose import RigPose

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "rig.example.toml"


@pytest.fixture(scope="module")
def example_data() -> dict[str, Any]:
    return tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))


def test_the_documented_example_loads() -> None:
    config = load_config(EXAMPLE)
    assert config.source == EXAMPLE
    assert set(config.axes) == {
        "camera_azimuth",
        "camera_inclination",
        "light_azimuth",
        "light_inclination",
    }
    assert config.axes["camera_inclination"].servo_id == 2
    assert config.axes["light_azimuth"].grbl_axis == "X"
    assert config.park == RigPose(0.0, 45.0, 180.0, 45.0)
    assert isinstance(config.camera, OpenCVCameraConfig)
    assert config.camera.api == "v4l2"
    assert [zone.name for zone in config.safety.forbidden] == [
        "light arm under camera arm",
        "drag chain",
    ]
    assert config.servos is not None and config.servos.port == "/dev/ttyUSB0"
    assert set(config.axes_of("grbl")) == {"light_azimuth", "light_inclination"}


@pytest.mark.parametrize(
    "config",
    [load_config(EXAMPLE), simulated_config("/dev/pts/7", "/dev/pts/8")],
    ids=["example", "simulated"],
)
def test_round_trip_through_toml(config: RigConfig, tmp_path: Path) -> None:
    text = config.to_toml()
    assert parse_config(tomllib.loads(text)) == config
    path = tmp_path / "rig.toml"
    path.write_text(text, encoding="utf-8")
    again = load_config(path)
    assert again == config
    assert again.to_toml() == text


def test_round_trip_keeps_every_camera_backend_and_faults() -> None:
    base = tomllib.loads(simulated_config("a", "b").to_toml())
    cameras: list[dict[str, Any]] = [
        {"backend": "opencv", "device": "/dev/video2", "exposure_unit": "log2_s"},
        {"backend": "gphoto2", "port": "usb:001,005", "folder": "raw files"},
        {"backend": "replay", "dataset": "../captures/owl", "tolerance_deg": 1.0},
        {
            "backend": "simulated",
            "scene": "textured-torus",
            "light_distance": 6.0,
            "faults": {"timeout_after": 3, "timeout_probability": 0.25, "seed": 9},
        },
    ]
    for camera in cameras:
        data = {**base, "camera": camera}
        config = parse_config(data)
        assert parse_config(tomllib.loads(config.to_toml())) == config


def test_dump_toml_escapes_strings_and_writes_tables() -> None:
    document = {
        "text": 'quote " backslash \\ newline \n tab \t del \x7f bell \x07 é 🦉',
        "key with space": 1,
        "numbers": [1.5, -2.0, 1e-7, 3],
        "flag": False,
        "table": {"inner": {"x": 1}},
        "rows": [{"a": 1}, {"a": 2}],
        "skipped": None,
    }
    parsed = tomllib.loads(dump_toml(document))
    expected = {k: v for k, v in document.items() if v is not None}
    assert parsed == expected


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def mutate(data: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        node = data
        for name in parents:
            node = node[name]
        node[last] = value

    return mutate


def _delete(path: str) -> Callable[[dict[str, Any]], None]:
    def mutate(data: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        node = data
        for name in parents:
            node = node[name]
        del node[last]

    return mutate


def _rename_axis(old: str, new: str) -> Callable[[dict[str, Any]], None]:
    def mutate(data: dict[str, Any]) -> None:
        data["axes"][new] = data["axes"].pop(old)

    return mutate


def _zone(**bounds: Any) -> Callable[[dict[str, Any]], None]:
    def mutate(data: dict[str, Any]) -> None:
        data["safety"]["forbidden"].append({"name": "extra", **bounds})

    return mutate


BAD_CONFIGS: list[tuple[str, Callable[[dict[str, Any]], None], str]] = [
    ("unknown top-level key", _set("colour", "red"), r"unknown key colour"),
    (
        "unknown axis key (typo)",
        _set("axes.camera_azimuth.max_degs", 10.0),
        r"unknown key axes\.camera_azimuth\.max_degs; keys here are: .*max_deg",
    ),
    (
        "wrong type",
        _set("servos.baudrate", "fast"),
        r"servos\.baudrate = 'fast' is a string; expected an integer",
    ),
    (
        "boolean is not a number",
        _set("axes.light_inclination.min_deg", True),
        r"axes\.light_inclination\.min_deg = True is a boolean; expected a number",
    ),
    ("not finite", _set("axes.camera_azimuth.offset_deg", float("nan")), r"must be finite"),
    (
        "contradictory limits",
        _set("axes.camera_azimuth.min_deg", 200.0),
        r"axes\.camera_azimuth\.min_deg = 200\.0 is not below max_deg = 170\.0",
    ),
    (
        "equal limits",
        _set("axes.light_inclination.max_deg", 0.0),
        r"axes\.light_inclination\.min_deg = 0\.0 is not below max_deg = 0\.0",
    ),
    (
        "unknown role",
        _rename_axis("camera_inclination", "camera_tilt"),
        r"unknown axis role axes\.camera_tilt; roles are camera_azimuth, ",
    ),
    (
        "duplicate servo id",
        _set("axes.camera_inclination.servo_id", 1),
        r"duplicate dynamixel servo id 1: axes\.camera_azimuth\.servo_id and "
        r"axes\.camera_inclination\.servo_id",
    ),
    (
        "duplicate GRBL axis",
        _set("axes.light_inclination.grbl_axis", "X"),
        r"duplicate GRBL axis letter 'X'",
    ),
    (
        "unknown GRBL axis",
        _set("axes.light_inclination.grbl_axis", "A"),
        r"axes\.light_inclination\.grbl_axis = 'A' is not one of 'X', 'Y', 'Z'",
    ),
    (
        "servo key on a GRBL axis",
        _set("axes.light_azimuth.servo_id", 5),
        r"axes\.light_azimuth\.servo_id does not apply to a grbl axis",
    ),
    (
        "bad direction",
        _set("axes.camera_azimuth.direction", 2),
        r"axes\.camera_azimuth\.direction = 2 must be 1 or -1",
    ),
    (
        "servo id out of range",
        _set("axes.camera_azimuth.servo_id", 254),
        r"servo_id = 254 must be in 0\.\.252",
    ),
    (
        "negative speed",
        _set("axes.light_azimuth.feed_deg_min", -5.0),
        r"axes\.light_azimuth\.feed_deg_min = -5\.0 must be positive",
    ),
    ("missing camera section", _delete("camera"), r"section \[camera\] is missing"),
    ("missing servos section", _delete("servos"), r"section \[servos\] is missing"),
    ("missing gantry section", _delete("gantry"), r"section \[gantry\] is missing"),
    (
        "missing axis",
        _delete("axes.light_inclination"),
        r"section \[axes\.light_inclination\] is missing",
    ),
    ("missing key", _delete("servos.port"), r"servos\.port is missing"),
    (
        "park outside limits",
        _set("park.camera_inclination_deg", 95.0),
        r"park\.camera_inclination_deg = 95\.0 is outside the limits of "
        r"axes\.camera_inclination \[5\.0, 85\.0\]",
    ),
    (
        "park in a forbidden zone",
        lambda d: d["park"].update(camera_azimuth_deg=100.0, light_inclination_deg=20.0),
        r"the park pose is not safe: the pose is in forbidden zone 'drag chain'",
    ),
    (
        "park too close to the light",
        lambda d: d["park"].update(light_azimuth_deg=5.0, light_inclination_deg=40.0),
        r"park pose is not safe: camera and light are .* closer than "
        r"safety\.min_separation_deg = 12",
    ),
    (
        "park turntable without a turntable",
        _set("park.turntable_deg", 10.0),
        r"park\.turntable_deg = 10\.0 needs an \[axes\.turntable\] section",
    ),
    (
        "unknown camera backend",
        _set("camera.backend", "webcam"),
        r"camera\.backend = 'webcam' is not one of 'opencv', 'gphoto2'",
    ),
    (
        "key of another camera backend",
        _set("camera.scene", "glossy-sphere"),
        r"unknown key camera\.scene \(not a key of the opencv backend\)",
    ),
    (
        "bad exposure unit",
        _set("camera.exposure_unit", "ms"),
        r"camera\.exposure_unit = 'ms' is not one of '100us', 'log2_s'",
    ),
    (
        "zone with low above high",
        _zone(camera_inclination_deg=[50.0, 40.0]),
        r"safety\.forbidden 'extra': camera_inclination_deg = \[50\.0, 40\.0\] has low above high",
    ),
    ("zone bounding nothing", _zone(), r"safety\.forbidden 'extra' bounds nothing"),
    (
        "zone interval is not a pair",
        _zone(light_azimuth_deg=[1.0]),
        r"safety\.forbidden\[2\]\.light_azimuth_deg = \[1\.0\] is an array; expected an array "
        r"of two numbers",
    ),
    (
        "zone with an unknown key",
        _zone(light_azimuth_deg=[0.0, 10.0], colour="red"),
        r"unknown key safety\.forbidden\[2\]\.colour",
    ),
    (
        "separation out of range",
        _set("safety.min_separation_deg", 200.0),
        r"safety\.min_separation_deg = 200\.0 must be in \[0, 180\)",
    ),
    (
        "max_s on coolant control",
        _set("light.control", "coolant"),
        r"light\.max_s does not apply to coolant control",
    ),
    ("unsupported schema", _set("schema_version", 2), r"schema_version = 2 is not supported"),
    ("below the horizon", _set("below_horizon", "floor"), r"below_horizon"),
]


@pytest.mark.parametrize(
    ("mutate", "message"),
    [case[1:] for case in BAD_CONFIGS],
    ids=[case[0] for case in BAD_CONFIGS],
)
def test_bad_configs_say_what_is_wrong(
    example_data: dict[str, Any], mutate: Callable[[dict[str, Any]], None], message: str
) -> None:
    data = copy.deepcopy(example_data)
    mutate(data)
    with pytest.raises(ConfigError, match=r"^bad\.toml: .*" + message):
        parse_config(data, "bad.toml")


def test_config_error_is_an_input_error() -> None:
    assert issubclass(ConfigError, InputError)


def test_unreadable_and_invalid_files_name_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match=r"nope\.toml: cannot read the rig config"):
        load_config(missing)
    broken = tmp_path / "broken.toml"
    broken.write_text("[servos\nport = 1\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"broken\.toml: not valid TOML: .*line 1"):
        load_config(broken)


def test_turntable_axis_and_its_park_angle(example_data: dict[str, Any]) -> None:
    data = copy.deepcopy(example_data)
    data["axes"]["turntable"] = {
        "device": "dynamixel",
        "servo_id": 3,
        "min_deg": -360.0,
        "max_deg": 360.0,
    }
    config = parse_config(data)
    assert config.park.turntable_deg == 0.0
    assert config.axes["turntable"].velocity_deg_s == 30.0  # the documented default
    assert parse_config(tomllib.loads(config.to_toml())) == config


def test_axis_conversion_to_device_units() -> None:
    axis = AxisConfig(
        "camera_inclination",
        "dynamixel",
        0.0,
        90.0,
        servo_id=2,
        direction=-1,
        gear_ratio=3.0,
        offset_deg=10.0,
    )
    assert axis.to_device(40.0) == pytest.approx(-90.0)
    assert axis.from_device(axis.to_device(37.25)) == pytest.approx(37.25)
    gantry = AxisConfig("light_inclination", "grbl", 0.0, 80.0, grbl_axis="Y", units_per_deg=0.5)
    assert gantry.to_device(30.0) == pytest.approx(15.0)


def test_relative_paths_resolve_next_to_the_config(tmp_path: Path) -> None:
    config = simulated_config("a", "b")
    path = tmp_path / "sub" / "rig.toml"
    path.parent.mkdir()
    path.write_text(config.to_toml(), encoding="utf-8")
    loaded = load_config(path)
    assert loaded.resolve("raw") == path.parent / "raw"
    assert loaded.resolve("/abs/raw") == Path("/abs/raw")
    assert config.resolve("raw") == Path("raw")


def test_the_example_config_fits_its_servos_in_one_turn() -> None:
    # A config the driver refuses on connect is no example (the servo limits map to ticks).
    from rig.dynamixel import DynamixelChain
    from rig.hardware import servo_axis

    config = load_config(Path(__file__).resolve().parents[2] / "docs" / "rig.example.toml")
    axes = [servo_axis(a) for a in config.axes.values() if a.device == "dynamixel"]
    DynamixelChain._check_axes("example", axes)


def test_a_rig_states_what_lies_below_its_horizon(example_data: dict[str, Any]) -> None:
    # The usual rig: the object on a base or turntable, which hides the environment below.
    assert load_config(EXAMPLE).below_horizon == "blocked"
    data = copy.deepcopy(example_data)
    data["below_horizon"] = "open"
    config = parse_config(data)
    assert config.below_horizon == "open"
    assert parse_config(tomllib.loads(config.to_toml())) == config
    # The simulator's scenes float (its ground truth lights them from below too).
    assert simulated_config("/dev/pts/7", "/dev/pts/8").below_horizon == "open"
