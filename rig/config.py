"""The rig config: devices, axes, limits, park pose, light, camera and forbidden zones (TOML).

:func:`load_config` reads and validates a file; every problem is a :class:`ConfigError` naming
the file, the key path and the value (unknown keys, wrong types, contradictory limits, unknown
axis roles, duplicate servo ids, missing sections, a park pose outside the limits or in a
forbidden zone). :meth:`RigConfig.to_toml` writes a config back, so the simulated rig can hand
out a ready-to-use file. The keys, units and defaults are documented in ``docs/rig-config.md``;
``docs/rig.example.toml`` is a commented example.

Axis conversion (both devices): ``device = direction * scale * (rig_deg - offset_deg)``, with
``scale = gear_ratio`` (servo degrees per rig degree) for a Dynamixel axis and
``scale = units_per_deg`` (GRBL machine units per rig degree) for a GRBL axis.

The parts have modules of their own, their names importable from here: the serial devices,
axes and light (:mod:`rig.config_devices`), the cameras (:mod:`rig.config_cameras`), the
checked TOML tables (:mod:`rig.config_schema`) and the safety rules (:mod:`rig.safety`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from core.errors import ConfigError, InputError
from core.field_store import BELOW_HORIZON, BelowHorizon
from rig.config_cameras import (
    CameraConfig,
    CameraFaultConfig,
    GPhoto2CameraConfig,
    OpenCVCameraConfig,
    ReplayCameraConfig,
    SimulatedCameraConfig,
    camera_to_dict,
    parse_camera,
)
from rig.config_devices import (
    XM430_W350,
    AxisConfig,
    GantryConfig,
    LightConfig,
    ServoChainConfig,
    _axis_to_dict,
    _check,
    _light_to_dict,
    _parse_axis,
)
from rig.config_schema import Table, dump_toml, read_toml
from rig.pose import REQUIRED_ROLES, ROLES, RigPose
from rig.safety import ForbiddenZone, SafetyConfig, parse_safety, pose_violation, safety_to_dict

__all__ = [
    "IN_PROCESS_PORT",
    "SCHEMA_VERSION",
    "XM430_W350",
    "AxisConfig",
    "CameraConfig",
    "CameraFaultConfig",
    "ForbiddenZone",
    "GPhoto2CameraConfig",
    "GantryConfig",
    "LightConfig",
    "OpenCVCameraConfig",
    "ReplayCameraConfig",
    "RigConfig",
    "SafetyConfig",
    "ServoChainConfig",
    "SimulatedCameraConfig",
    "load_config",
    "parse_config",
    "simulated_config",
]

SCHEMA_VERSION = 1
#: The serial port of a simulated rig's devices in a config that ``rig capture --sim`` (or any
#: caller of :class:`sim.simulated_rig.SimulatedRig`) starts in its own process: no device.
IN_PROCESS_PORT = "/dev/null"


@dataclass(frozen=True)
class RigConfig:
    """A whole rig. Construction validates everything that depends on more than one key.

    Attributes
    ----------
    axes : dict of role -> AxisConfig
        The four required roles, and ``turntable`` when the rig has one.
    servos, gantry : the serial devices; present exactly when an axis (or the light) needs them
    light, camera, safety : see their classes
    park : RigPose, where the rig rests between sessions and after an error
    below_horizon : {"blocked", "open"}, what lies below the object's horizon (its base or
        turntable blocks the environment, the usual case; or the object hangs free): the
        statement every field built from the rig's captures carries
        (:data:`core.field_store.BELOW_HORIZON`)
    source : Path or None, the file it was read from (not compared)
    """

    axes: dict[str, AxisConfig]
    park: RigPose
    camera: CameraConfig
    servos: ServoChainConfig | None = None
    gantry: GantryConfig | None = None
    light: LightConfig = field(default_factory=LightConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    name: str = "rig"
    below_horizon: BelowHorizon = "blocked"
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        _check(
            self.below_horizon in BELOW_HORIZON,
            "below_horizon",
            self.below_horizon,
            f"is not one of {', '.join(BELOW_HORIZON)}",
        )
        for role, axis in self.axes.items():
            _check(role == axis.role, f"axes.{role}.role", axis.role, f"does not match {role!r}")
        missing = [role for role in REQUIRED_ROLES if role not in self.axes]
        if missing:
            raise ConfigError(
                f"section [axes.{missing[0]}] is missing (every rig has "
                f"{', '.join(REQUIRED_ROLES)})"
            )
        devices = {axis.device for axis in self.axes.values()}
        if "dynamixel" in devices and self.servos is None:
            raise ConfigError("section [servos] is missing; the dynamixel axes need its port")
        if self.gantry is None:
            raise ConfigError("section [gantry] is missing; the light is switched through GRBL")
        _unique(self.axes, "servo_id", "dynamixel servo id")
        _unique(self.axes, "grbl_axis", "GRBL axis letter")
        for role, value in self.park.items():
            limits = self.axes.get(role)
            if limits is None:
                _check(value == 0.0, f"park.{role}_deg", value, f"needs an [axes.{role}] section")
            elif not limits.within_limits(value):
                raise ConfigError(
                    f"park.{role}_deg = {value!r} is outside the limits of axes.{role} "
                    f"[{limits.min_deg!r}, {limits.max_deg!r}]"
                )
        problem = pose_violation(self, self.park)
        if problem:
            raise ConfigError(f"the park pose is not safe: {problem}")

    def axes_of(self, device: str) -> dict[str, AxisConfig]:
        """The axes driven by ``device`` ("dynamixel" or "grbl"), by role."""
        return {role: axis for role, axis in self.axes.items() if axis.device == device}

    def resolve(self, path: str | os.PathLike[str]) -> Path:
        """A path from the config, relative to the config file's folder when it has one."""
        candidate = Path(path).expanduser()
        if candidate.is_absolute() or self.source is None:
            return candidate
        return self.source.parent / candidate

    def to_dict(self) -> dict[str, Any]:
        """The config as the nested tables of its TOML form (None values left out)."""
        document: dict[str, Any] = {
            "schema_version": SCHEMA_VERSION,
            "name": self.name,
            "below_horizon": self.below_horizon,
        }
        for section, value in (("servos", self.servos), ("gantry", self.gantry)):
            if value is not None:
                document[section] = {f.name: getattr(value, f.name) for f in fields(value)}
        document["axes"] = {role: _axis_to_dict(axis) for role, axis in self.axes.items()}
        document["park"] = {
            f"{role}_deg": value
            for role, value in self.park.items()
            if role in self.axes or value != 0.0
        }
        document["light"] = _light_to_dict(self.light)
        document["camera"] = camera_to_dict(self.camera)
        document["safety"] = safety_to_dict(self.safety)
        return document

    def to_toml(self) -> str:
        """The config as TOML text that :func:`parse_config` reads back equal."""
        header = f"# Rig config {self.name!r} (schema {SCHEMA_VERSION}); see docs/rig-config.md\n"
        return header + dump_toml(self.to_dict())


def _unique(axes: Mapping[str, AxisConfig], attribute: str, what: str) -> None:
    seen: dict[object, str] = {}
    for role, axis in axes.items():
        value = getattr(axis, attribute)
        if value is None:
            continue
        if value in seen:
            raise ConfigError(
                f"duplicate {what} {value!r}: axes.{seen[value]}.{attribute} and "
                f"axes.{role}.{attribute}"
            )
        seen[value] = role


def _parse_port(table: Table, cls: type[Any], baudrate: int, **extra: Any) -> Any:
    return cls(port=table.string("port"), baudrate=table.integer("baudrate", baudrate), **extra)


def _parse(root: Table, source: Path | None) -> RigConfig:
    version = root.integer("schema_version", SCHEMA_VERSION)
    _check(
        version == SCHEMA_VERSION,
        "schema_version",
        version,
        f"is not supported (this program reads {SCHEMA_VERSION})",
    )
    name = root.string("name", "rig")
    below_horizon = root.string("below_horizon", "blocked", choices=BELOW_HORIZON)
    servos_table = root.table("servos", required=False)
    servos = None
    if servos_table is not None:
        servos = _parse_port(
            servos_table,
            ServoChainConfig,
            57_600,
            model_number=servos_table.integer("model_number", XM430_W350),
        )
        servos_table.finish()
    gantry_table = root.table("gantry", required=False)
    gantry = None
    if gantry_table is not None:
        gantry = _parse_port(
            gantry_table,
            GantryConfig,
            115_200,
            homing=gantry_table.boolean("homing", False),
            unlock_on_alarm=gantry_table.boolean("unlock_on_alarm", False),
        )
        gantry_table.finish()
    axes_table = root.table("axes")
    assert axes_table is not None
    axes: dict[str, AxisConfig] = {}
    for role in axes_table.keys():
        if role not in ROLES:
            raise ConfigError(f"unknown axis role axes.{role}; roles are {', '.join(ROLES)}")
        sub = axes_table.table(role)
        assert sub is not None
        axes[role] = _parse_axis(sub, role)
    axes_table.finish()
    park_table = root.table("park")
    assert park_table is not None
    park_roles = {role: park_table.number(f"{role}_deg") for role in REQUIRED_ROLES}
    if park_table.has("turntable_deg") or "turntable" in axes:
        park_roles["turntable"] = park_table.number("turntable_deg", 0.0)
    park_table.finish()
    light_table = root.table("light", required=False) or Table({}, "light")
    control = light_table.string("control", "spindle", choices=("spindle", "coolant"))
    if control == "coolant" and light_table.has("max_s"):
        raise ConfigError("light.max_s does not apply to coolant control (on/off only)")
    light = LightConfig(
        control=control,
        max_s=light_table.number("max_s", 1000.0),
        settle_s=light_table.number("settle_s", 0.0),
    )
    light_table.finish()
    camera_table = root.table("camera")
    assert camera_table is not None
    camera = parse_camera(camera_table)
    safety = parse_safety(root.table("safety", required=False) or Table({}, "safety"))
    root.finish()
    return RigConfig(
        axes=axes,
        park=RigPose.from_roles(park_roles),
        camera=camera,
        servos=servos,
        gantry=gantry,
        light=light,
        safety=safety,
        name=name,
        below_horizon=below_horizon,
        source=source,
    )


def parse_config(
    data: Mapping[str, Any], source: str | os.PathLike[str] | None = None
) -> RigConfig:
    """Validate parsed TOML tables and build the config.

    Parameters
    ----------
    data : mapping, what ``tomllib`` returns
    source : path of the file, used in messages and to resolve relative paths

    Raises
    ------
    ConfigError
        Naming the file, the key path and the value.
    """
    where = str(source) if source is not None else "<rig config>"
    try:
        return _parse(Table(data), Path(source) if source is not None else None)
    except InputError as error:  # ConfigError, or a value refused by a shared dataclass
        raise ConfigError(f"{where}: {error}") from None


def load_config(path: str | os.PathLike[str]) -> RigConfig:
    """Read and validate a rig config file (TOML); see ``docs/rig-config.md``."""
    return parse_config(read_toml(path, "rig config"), Path(path))


def simulated_config(
    servo_port: str, gantry_port: str, *, scene: str = "glossy-sphere", name: str = "simulated rig"
) -> RigConfig:
    """A ready-to-use config for the simulated rig on the given serial devices.

    Camera arm on Dynamixel ids 1 (azimuth) and 2 (inclination), light on GRBL X (azimuth) and
    Y (inclination) at one machine unit per degree, spindle PWM light, simulated camera.
    """

    def servo(role: str, servo_id: int, min_deg: float, max_deg: float) -> AxisConfig:
        return AxisConfig(
            role,
            "dynamixel",
            min_deg,
            max_deg,
            servo_id=servo_id,
            velocity_deg_s=90.0,
            acceleration_deg_s2=360.0,
        )

    def grbl(role: str, letter: str, min_deg: float, max_deg: float) -> AxisConfig:
        return AxisConfig(
            role,
            "grbl",
            min_deg,
            max_deg,
            grbl_axis=letter,
            feed_deg_min=6000.0,
            acceleration_deg_s2=360.0,
        )

    # Azimuths run 0..359 as sweep plans count them; a servo turn holds 0..360 from tick 0.
    axes = {
        "camera_azimuth": servo("camera_azimuth", 1, 0.0, 359.0),
        "camera_inclination": servo("camera_inclination", 2, 0.0, 90.0),
        "light_azimuth": grbl("light_azimuth", "X", 0.0, 360.0),
        "light_inclination": grbl("light_inclination", "Y", 0.0, 90.0),
    }
    return RigConfig(
        axes=axes,
        park=RigPose(0.0, 0.0, 180.0, 45.0),
        camera=SimulatedCameraConfig(scene=scene),
        servos=ServoChainConfig(port=servo_port),
        gantry=GantryConfig(port=gantry_port),
        safety=SafetyConfig(min_separation_deg=10.0),
        name=name,
        # The simulator's scenes float: its ground truth lights them from every direction.
        below_horizon="open",
    )
