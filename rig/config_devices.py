"""The rig config's devices: the serial ports, the axes they drive, and how the light is switched.

``[servos]`` (:class:`ServoChainConfig`), ``[gantry]`` (:class:`GantryConfig`), each
``[axes.<role>]`` (:class:`AxisConfig`: the device, the conversion between rig degrees and the
device's units, limits and speed) and ``[light]`` (:class:`LightConfig`), each validated as it
is made, and an axis read from its TOML table and written back. The whole config, which checks
what depends on more than one of them, is :class:`rig.config.RigConfig`; every name here is
also importable from :mod:`rig.config`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Literal

from core.errors import ConfigError
from rig.config_schema import Table
from rig.pose import ROLES

__all__ = ["XM430_W350", "AxisConfig", "GantryConfig", "LightConfig", "ServoChainConfig"]

#: Dynamixel model number of the XM430-W350 (the control table of issue 5).
XM430_W350 = 1020
_SERVO_KEYS = ("servo_id", "gear_ratio", "velocity_deg_s")
_GRBL_KEYS = ("grbl_axis", "units_per_deg", "feed_deg_min")
#: Axis limits beyond ten turns are a typo (or 1e308), never a rig.
LIMIT_DEG = 3600.0


@dataclass(frozen=True)
class ServoChainConfig:
    """The Dynamixel chain's serial port (``[servos]``)."""

    port: str
    baudrate: int = 57_600
    model_number: int = XM430_W350

    def __post_init__(self) -> None:
        _check(bool(self.port), "servos.port", self.port, "must name a serial device")
        _check(self.baudrate > 0, "servos.baudrate", self.baudrate, "must be positive")


@dataclass(frozen=True)
class GantryConfig:
    """The GRBL controller's serial port (``[gantry]``) and its operator choices."""

    port: str
    baudrate: int = 115_200
    homing: bool = False  # run $H on connect (the controller must have $22=1)
    unlock_on_alarm: bool = False  # send $X after an alarm without asking the operator

    def __post_init__(self) -> None:
        _check(bool(self.port), "gantry.port", self.port, "must name a serial device")
        _check(self.baudrate > 0, "gantry.baudrate", self.baudrate, "must be positive")


@dataclass(frozen=True)
class AxisConfig:
    """One axis (``[axes.<role>]``): which device drives it, conversion, limits and speed.

    ``servo_id``, ``gear_ratio`` and ``velocity_deg_s`` apply to Dynamixel axes; ``grbl_axis``,
    ``units_per_deg`` and ``feed_deg_min`` to GRBL axes.
    """

    role: str
    device: Literal["dynamixel", "grbl"]
    min_deg: float
    max_deg: float
    servo_id: int | None = None
    grbl_axis: str | None = None
    offset_deg: float = 0.0
    direction: int = 1
    gear_ratio: float = 1.0
    units_per_deg: float = 1.0
    velocity_deg_s: float = 30.0
    acceleration_deg_s2: float = 60.0
    feed_deg_min: float = 1800.0

    def __post_init__(self) -> None:
        key = f"axes.{self.role}"
        if self.role not in ROLES:
            raise ConfigError(f"unknown axis role {key}; roles are {', '.join(ROLES)}")
        _check(
            self.device in ("dynamixel", "grbl"),
            f"{key}.device",
            self.device,
            "is not 'dynamixel' or 'grbl'",
        )
        for name, value in (("min_deg", self.min_deg), ("max_deg", self.max_deg)):
            _check(
                -LIMIT_DEG <= value <= LIMIT_DEG,
                f"{key}.{name}",
                value,
                f"must be within +-{LIMIT_DEG:g} degrees (ten turns)",
            )
        _check(
            self.min_deg < self.max_deg,
            f"{key}.min_deg",
            self.min_deg,
            f"is not below max_deg = {self.max_deg!r}",
        )
        _check(self.direction in (1, -1), f"{key}.direction", self.direction, "must be 1 or -1")
        _check(
            self.acceleration_deg_s2 > 0,
            f"{key}.acceleration_deg_s2",
            self.acceleration_deg_s2,
            "must be positive",
        )
        if self.device == "dynamixel":
            _check(
                self.servo_id is not None,
                f"{key}.servo_id",
                None,
                "is required for a dynamixel axis",
            )
            # 253 is reserved and 254 is the broadcast id in Protocol 2.0.
            _check(
                0 <= (self.servo_id or 0) <= 252,
                f"{key}.servo_id",
                self.servo_id,
                "must be in 0..252",
            )
            _check(
                self.grbl_axis is None,
                f"{key}.grbl_axis",
                self.grbl_axis,
                "does not apply to a dynamixel axis",
            )
            _check(self.gear_ratio > 0, f"{key}.gear_ratio", self.gear_ratio, "must be positive")
            _check(
                self.velocity_deg_s > 0,
                f"{key}.velocity_deg_s",
                self.velocity_deg_s,
                "must be positive",
            )
        else:
            _check(
                self.grbl_axis in ("X", "Y", "Z"),
                f"{key}.grbl_axis",
                self.grbl_axis,
                "must be 'X', 'Y' or 'Z'",
            )
            _check(
                self.servo_id is None,
                f"{key}.servo_id",
                self.servo_id,
                "does not apply to a grbl axis",
            )
            _check(
                self.units_per_deg > 0,
                f"{key}.units_per_deg",
                self.units_per_deg,
                "must be positive (use direction = -1 to reverse)",
            )
            _check(
                self.feed_deg_min > 0, f"{key}.feed_deg_min", self.feed_deg_min, "must be positive"
            )
            _check(
                0.01 <= self.feed_deg_min <= 1e7,
                f"{key}.feed_deg_min",
                self.feed_deg_min,
                "must be between 0.01 and 1e7 degrees a minute",
            )

    @property
    def scale(self) -> float:
        """Device units (servo degrees or GRBL machine units) per rig degree, signed."""
        return self.direction * (
            self.gear_ratio if self.device == "dynamixel" else self.units_per_deg
        )

    def to_device(self, rig_deg: float) -> float:
        """Rig degrees to the device's position (servo degrees or GRBL machine units)."""
        return self.scale * (rig_deg - self.offset_deg)

    def from_device(self, device_position: float) -> float:
        """The device's position back to rig degrees."""
        return device_position / self.scale + self.offset_deg

    def within_limits(self, rig_deg: float) -> bool:
        """Whether ``rig_deg`` lies within ``[min_deg, max_deg]``, ends included."""
        return self.min_deg <= rig_deg <= self.max_deg


@dataclass(frozen=True)
class LightConfig:
    """How GRBL switches the light (``[light]``): spindle PWM (M3 S / M5) or coolant (M8 / M9)."""

    control: Literal["spindle", "coolant"] = "spindle"
    max_s: float = 1000.0  # spindle: the S word of full intensity (GRBL $30)
    settle_s: float = 0.0  # wait after switching before an image is taken

    def __post_init__(self) -> None:
        _check(
            self.control in ("spindle", "coolant"),
            "light.control",
            self.control,
            "is not 'spindle' or 'coolant'",
        )
        _check(self.max_s > 0, "light.max_s", self.max_s, "must be positive")
        _check(self.settle_s >= 0, "light.settle_s", self.settle_s, "must be >= 0")


def _check(ok: bool, key: str, value: object, problem: str) -> None:
    if not ok:
        raise ConfigError(f"{key} = {value!r} {problem}")


def _axis_to_dict(axis: AxisConfig) -> dict[str, Any]:
    skip = {"role", *(_GRBL_KEYS if axis.device == "dynamixel" else _SERVO_KEYS)}
    return {f.name: getattr(axis, f.name) for f in fields(axis) if f.name not in skip}


def _light_to_dict(light: LightConfig) -> dict[str, Any]:
    document: dict[str, Any] = {"control": light.control, "settle_s": light.settle_s}
    if light.control == "spindle":
        document["max_s"] = light.max_s
    return document


def _parse_axis(table: Table, role: str) -> AxisConfig:
    device = table.string("device", choices=("dynamixel", "grbl"))
    foreign = _GRBL_KEYS if device == "dynamixel" else _SERVO_KEYS
    for name in foreign:
        if table.has(name):
            raise ConfigError(f"{table.key(name)} does not apply to a {device} axis")
    values: dict[str, Any] = {
        "min_deg": table.number("min_deg"),
        "max_deg": table.number("max_deg"),
        "offset_deg": table.number("offset_deg", 0.0),
        "direction": table.integer("direction", 1),
        "acceleration_deg_s2": table.number("acceleration_deg_s2", 60.0),
    }
    if device == "dynamixel":
        values["servo_id"] = table.integer("servo_id")
        values["gear_ratio"] = table.number("gear_ratio", 1.0)
        values["velocity_deg_s"] = table.number("velocity_deg_s", 30.0)
    else:
        values["grbl_axis"] = table.string("grbl_axis", choices=("X", "Y", "Z"))
        values["units_per_deg"] = table.number("units_per_deg", 1.0)
        values["feed_deg_min"] = table.number("feed_deg_min", 1800.0)
    table.finish()
    return AxisConfig(role=role, device=device, **values)
