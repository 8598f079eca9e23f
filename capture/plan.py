"""Sweep plans: what a capture takes, as data (bluesky / useq-schema style).

A :class:`SweepPlan` lists camera poses, light poses, an exposure bracket, whether to take dark
frames, calibration captures and an ordering. It never touches a device: :meth:`SweepPlan.events`
turns it, for a given rig config, into the ordered :class:`CaptureEvent` tuple an executor runs
(forbidden pairs skipped, the order chosen by :mod:`capture.plan_order`), and
:meth:`SweepPlan.estimate` and :meth:`SweepPlan.limit_checks` are the dry run. Plans are read
from TOML (:func:`load_plan`, keys in ``docs/plans.md``) and stored in a dataset's manifest as
JSON (:meth:`SweepPlan.to_dict` / :meth:`SweepPlan.from_dict`).

Image keys: a light image is ``ImageKey("light", camera, light, exposure)``; a dark frame
``ImageKey("dark", camera, None, exposure)``; a calibration capture
``ImageKey("calibration", camera, i, exposure)`` with ``i`` its index in
:attr:`SweepPlan.calibration`.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from capture.journal import IMAGE_KINDS, ImageKey
from capture.plan_order import (
    IMAGE_OVERHEAD_S,
    ORDERINGS,
    LimitCheck,
    PlanEstimate,
    Schedule,
    Unplaced,
    schedules,
)
from core.directions import angles_deg_from_direction, hemisphere_layout
from core.errors import ConfigError, InputError
from rig.config import RigConfig
from rig.config_schema import Table, read_toml
from rig.pose import CAMERA_ROLES, LIGHT_ROLES, ROLES, RigPose

__all__ = [
    "IMAGE_OVERHEAD_S",
    "LAYOUTS",
    "ORDERINGS",
    "PLAN_SCHEMA_VERSION",
    "CalibrationCapture",
    "CaptureEvent",
    "LimitCheck",
    "PlanEstimate",
    "SweepPlan",
    "grid_plan",
    "load_plan",
    "parse_plan",
]

#: Version of the plan's dict and TOML form.
PLAN_SCHEMA_VERSION = 1
#: Hemisphere layouts of :func:`core.directions.hemisphere_layout`.
LAYOUTS = ("grid", "fibonacci")
#: The most poses one range may give (a tiny step is a typo, not a plan).
MAX_RANGE_VALUES = 10_000
_TOP_KEYS = "schema_version exposures_ms dark_frames ordering cameras lights calibration".split()
_NAME = re.compile(r"^[a-z0-9][a-z0-9-]*$")

Angles = tuple[float, float]


@dataclass(frozen=True)
class CaptureEvent:
    """One image to take.

    Attributes
    ----------
    key : ImageKey
    pose : RigPose, where the rig must be (a dark frame: the camera pose, the light where it
        stands for the camera's first light image, or at park when it cannot)
    exposure_ms : float
    light_on : bool, False for dark frames and light-off calibration captures
    name : str, the image file stem (``key.stem()``, plus ``_<name>`` for calibration)
    """

    key: ImageKey
    pose: RigPose
    exposure_ms: float
    light_on: bool
    name: str


@dataclass(frozen=True)
class CalibrationCapture:
    """A calibration capture: a named target seen from a camera pose, lit or not.

    Attributes
    ----------
    name : str, what is at the object's place (lowercase letters, digits, hyphens)
    camera_index : int, the plan camera pose
    light_index : int or None, the plan light pose, or None for the light off
    exposures_ms : tuple of float, its bracket
    """

    name: str
    camera_index: int
    light_index: int | None
    exposures_ms: tuple[float, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise InputError(
                f"calibration name {self.name!r} must be lowercase letters, digits and hyphens"
            )
        _index(self.camera_index, f"calibration {self.name!r} camera_index")
        if self.light_index is not None:
            _index(self.light_index, f"calibration {self.name!r} light_index")
        object.__setattr__(
            self, "exposures_ms", _exposures(self.exposures_ms, f"calibration {self.name!r}")
        )

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "camera_index", "light_index", "exposures_ms"}``."""
        return {
            "name": self.name,
            "camera_index": self.camera_index,
            "light_index": self.light_index,
            "exposures_ms": list(self.exposures_ms),
        }


def _index(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError(f"{name} must be a non-negative integer, got {value!r}")
    return value


def _number(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{name} = {value!r} must be a finite number")
    return float(value)


def _exposures(values: object, where: str) -> tuple[float, ...]:
    if not isinstance(values, list | tuple) or not values:
        raise InputError(f"{where}: exposures_ms = {values!r} must list at least one exposure")
    exposures = tuple(_number(v, f"{where}: exposures_ms[{i}]") for i, v in enumerate(values))
    for i, value in enumerate(exposures):
        if value <= 0:
            raise InputError(f"{where}: exposures_ms[{i}] = {value:g} must be positive")
    return exposures


def _angles(values: object, where: str) -> tuple[Angles, ...]:
    if not isinstance(values, list | tuple) or not values:
        raise InputError(f"{where} must list at least one (azimuth_deg, inclination_deg) pose")
    poses: list[Angles] = []
    for i, pose in enumerate(values):
        if not isinstance(pose, list | tuple) or len(pose) != 2:
            raise InputError(f"{where}[{i}] = {pose!r} is not (azimuth_deg, inclination_deg)")
        azimuth = _number(pose[0], f"{where}[{i}] azimuth_deg")
        inclination = _number(pose[1], f"{where}[{i}] inclination_deg")
        if not 0.0 <= inclination <= 90.0:
            raise InputError(
                f"{where}[{i}] inclination_deg = {inclination:g} is outside 0..90 (from straight "
                "above to the horizon)"
            )
        poses.append((azimuth, inclination))
    return tuple(poses)


@dataclass(frozen=True)
class SweepPlan:
    """What a capture takes: camera poses x light poses x exposures, darks and calibration.

    Attributes
    ----------
    cameras : tuple of (azimuth_deg, inclination_deg), one per camera index
    lights : tuple of (azimuth_deg, inclination_deg), one per light index
    exposures_ms : tuple of float, the bracket (one value: no HDR)
    dark_frames : bool, one dark frame (light off) per camera pose and exposure
    ordering : {"optimised", "serpentine"}, see :mod:`capture.plan_order`
    calibration : tuple of CalibrationCapture, taken before the sweep, in order
    """

    cameras: tuple[Angles, ...]
    lights: tuple[Angles, ...]
    exposures_ms: tuple[float, ...]
    dark_frames: bool = True
    ordering: str = "optimised"
    calibration: tuple[CalibrationCapture, ...] = ()
    _cache: dict[int, tuple[RigConfig, dict[str, Schedule]]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "cameras", _angles(self.cameras, "cameras"))
        object.__setattr__(self, "lights", _angles(self.lights, "lights"))
        object.__setattr__(self, "exposures_ms", _exposures(self.exposures_ms, "plan"))
        if not isinstance(self.dark_frames, bool):
            raise InputError(f"dark_frames = {self.dark_frames!r} must be true or false")
        if self.ordering not in ORDERINGS:
            raise InputError(
                f"ordering = {self.ordering!r} is not one of {', '.join(map(repr, ORDERINGS))}"
            )
        object.__setattr__(self, "calibration", tuple(self.calibration))
        for i, capture in enumerate(self.calibration):
            if not isinstance(capture, CalibrationCapture):
                raise InputError(f"calibration[{i}] is not a CalibrationCapture")
            if capture.camera_index >= len(self.cameras):
                raise InputError(
                    f"calibration[{i}] ({capture.name}): camera_index {capture.camera_index} "
                    f"is not a camera of the plan (0..{len(self.cameras) - 1})"
                )
            if capture.light_index is not None and capture.light_index >= len(self.lights):
                raise InputError(
                    f"calibration[{i}] ({capture.name}): light_index {capture.light_index} "
                    f"is not a light of the plan (0..{len(self.lights) - 1})"
                )

    # -- the events ------------------------------------------------------------------------

    def _schedules(self, config: RigConfig) -> dict[str, Schedule]:
        cached = self._cache.get(id(config))
        if cached is not None and cached[0] is config:
            return cached[1]
        built = schedules(
            config,
            self.cameras,
            self.lights,
            dark_frames=self.dark_frames,
            calibration=[(c.camera_index, c.light_index) for c in self.calibration],
        )
        self._cache.clear()
        self._cache[id(config)] = (config, built)
        return built

    def _events(self, schedule: Schedule) -> tuple[CaptureEvent, ...]:
        events: list[CaptureEvent] = []
        for stop in schedule.stops:
            exposures, light_on, suffix = self.exposures_ms, stop.kind == "light", ""
            if stop.kind == "calibration":
                assert stop.light_index is not None
                capture = self.calibration[stop.light_index]
                exposures, light_on = capture.exposures_ms, capture.light_index is not None
                suffix = f"_{capture.name}"
            for e, exposure_ms in enumerate(exposures):
                key = ImageKey(stop.kind, stop.camera_index, stop.light_index, e)
                events.append(
                    CaptureEvent(key, stop.pose, exposure_ms, light_on, key.stem() + suffix)
                )
        return tuple(events)

    def events(self, config: RigConfig) -> tuple[CaptureEvent, ...]:
        """Every image to take on the rig of ``config``, in order.

        Calibration captures first, then per camera pose its dark frames and its light images;
        the exposures of one pose are consecutive. Pairs in a forbidden zone or outside the
        limits, and poses no safe straight move reaches, are left out (see :meth:`skipped`).
        """
        return self._events(self._schedules(config)[self.ordering])

    def planned_keys(self, config: RigConfig) -> tuple[ImageKey, ...]:
        """The keys of :meth:`events`, in order (what ``Dataset.create(planned=...)`` takes)."""
        return tuple(event.key for event in self.events(config))

    def unplaced(self, config: RigConfig) -> tuple[Unplaced, ...]:
        """Every stop left out (light pairs, dark frames, calibration captures) with the reason."""
        return self._schedules(config)[self.ordering].unplaced

    def skipped(self, config: RigConfig) -> tuple[tuple[int, int, str], ...]:
        """The (camera_index, light_index, reason) pairs left out, sorted by index."""
        pairs = [
            (u.camera_index, u.light_index, u.reason)
            for u in self.unplaced(config)
            if u.kind == "light" and u.light_index is not None
        ]
        return tuple(sorted(pairs))

    # -- the dry run -----------------------------------------------------------------------

    def estimate(self, config: RigConfig) -> PlanEstimate:
        """Counts, motion, exposure and overhead seconds, in both orderings."""
        built = self._schedules(config)
        events = self._events(built[self.ordering])
        images = dict.fromkeys(IMAGE_KINDS, 0)
        for event in events:
            images[event.key.kind] += 1
        switches, light = 0, False
        for event in events:
            switches += event.light_on != light
            light = event.light_on
        switches += light  # off at the end
        unplaced = built[self.ordering].unplaced
        return PlanEstimate(
            ordering=self.ordering,
            cameras=len(self.cameras),
            lights=len(self.lights),
            exposures=len(self.exposures_ms),
            images=images,
            skipped_pairs=sum(u.kind == "light" for u in unplaced),
            unplaced=sum(u.kind != "light" for u in unplaced),
            motion_by_ordering_s={name: s.motion_s for name, s in built.items()},
            exposure_s=sum(e.exposure_ms for e in events) / 1000.0,
            overhead_s=IMAGE_OVERHEAD_S * len(events) + switches * config.light.settle_s,
        )

    def limit_checks(self, config: RigConfig) -> tuple[LimitCheck, ...]:
        """For each axis of the rig, the range the plan's poses use against its limits."""
        used: dict[str, list[float]] = {
            CAMERA_ROLES[0]: [a for a, _ in self.cameras],
            CAMERA_ROLES[1]: [i for _, i in self.cameras],
            LIGHT_ROLES[0]: [a for a, _ in self.lights],
            LIGHT_ROLES[1]: [i for _, i in self.lights],
            "turntable": [0.0],
        }
        return tuple(
            LimitCheck(role, min(used[role]), max(used[role]), axis.min_deg, axis.max_deg)
            for role in ROLES
            if (axis := config.axes.get(role)) is not None
        )

    # -- as data ---------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The plan as plain JSON data (what a dataset's manifest stores)."""
        return {
            "schema_version": PLAN_SCHEMA_VERSION,
            "cameras": [list(pose) for pose in self.cameras],
            "lights": [list(pose) for pose in self.lights],
            "exposures_ms": list(self.exposures_ms),
            "dark_frames": self.dark_frames,
            "ordering": self.ordering,
            "calibration": [capture.to_dict() for capture in self.calibration],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SweepPlan:
        """The plan of :meth:`to_dict`'s form; raises InputError naming the bad key."""
        keys = {"schema_version", "cameras", "lights", "exposures_ms", "dark_frames", "ordering"}
        keys.add("calibration")
        if not isinstance(data, Mapping):
            raise InputError(f"a plan must be a mapping, got {type(data).__name__}")
        if set(data) != keys:
            missing, unknown = sorted(keys - set(data)), sorted(set(data) - keys)
            raise InputError(f"plan: missing keys {missing}, unknown keys {unknown}")
        if data["schema_version"] != PLAN_SCHEMA_VERSION:
            raise InputError(
                f"plan schema_version = {data['schema_version']!r}; only "
                f"{PLAN_SCHEMA_VERSION} is read"
            )
        captures = data["calibration"]
        if not isinstance(captures, list):
            raise InputError("plan calibration must be a list")
        calibration = []
        for i, capture in enumerate(captures):
            fields = {"name", "camera_index", "light_index", "exposures_ms"}
            if not isinstance(capture, Mapping) or set(capture) != fields:
                raise InputError(
                    f"plan calibration[{i}] must have exactly the keys {sorted(fields)}"
                )
            calibration.append(CalibrationCapture(**capture))
        return cls(
            cameras=data["cameras"],
            lights=data["lights"],
            exposures_ms=data["exposures_ms"],
            dark_frames=data["dark_frames"],
            ordering=data["ordering"],
            calibration=tuple(calibration),
        )


def layout_angles(count: int, layout: str) -> tuple[Angles, ...]:
    """``count`` (azimuth_deg, inclination_deg) over the upper hemisphere in ``layout``.

    The directions of :func:`core.directions.hemisphere_layout`, which the simulator's fields
    use too (``sim.field.field_cameras`` and the lights of ``sim.field.simulate_field``).
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise InputError(f"a layout needs a positive count, got {count!r}")
    azimuth, inclination = angles_deg_from_direction(hemisphere_layout(count, layout))
    return tuple((float(a), float(i)) for a, i in zip(azimuth, inclination, strict=True))


def grid_plan(
    cameras: int,
    lights: int,
    *,
    exposures_ms: Sequence[float] = (40.0,),
    layout: str = "grid",
    dark_frames: bool = True,
    ordering: str = "optimised",
) -> SweepPlan:
    """A plan of ``cameras`` x ``lights`` hemisphere poses, the layout of ``rig sim field``.

    Parameters
    ----------
    cameras, lights : int, pose counts
    exposures_ms : sequence of float, the bracket
    layout : {"grid", "fibonacci", "hemisphere"}, ``hemisphere`` meaning ``fibonacci`` (the
        near-uniform one)
    dark_frames, ordering : as :class:`SweepPlan`
    """
    layout = "fibonacci" if layout == "hemisphere" else layout
    if layout not in LAYOUTS:
        raise InputError(f"unknown layout {layout!r}; use 'grid', 'fibonacci' or 'hemisphere'")
    return SweepPlan(
        cameras=layout_angles(cameras, layout),
        lights=layout_angles(lights, layout),
        exposures_ms=tuple(exposures_ms),
        dark_frames=dark_frames,
        ordering=ordering,
    )


# -- the TOML form -----------------------------------------------------------------------------


class _Table(Table):
    """A :class:`rig.config_schema.Table` that also reads raw values and sub-tables."""

    def value(self, name: str, default: Any = None) -> Any:
        """The raw value of ``name`` (``default`` when absent), marked read."""
        return self._get(name, default)

    def sub(self, name: str, *, required: bool = True) -> _Table | None:
        value = self.value(name)
        if value is None:
            if required:
                raise ConfigError(f"section [{self.key(name)}] is missing")
            return None
        if not isinstance(value, Mapping):
            raise ConfigError(f"{self.key(name)} = {value!r} is not a table")
        return _Table(value, self.key(name))

    def only(self, *names: str) -> None:
        """Refuse keys other than ``names`` before reading any (typos are named first)."""
        for key in self.keys():
            if key not in names:
                known = ", ".join(sorted(names))
                raise ConfigError(f"unknown key {self.key(key)}; keys here are: {known}")

    def subs(self, name: str) -> list[_Table]:
        """An optional array of tables (``[[name]]``)."""
        value = self.value(name, [])
        if not isinstance(value, list) or not all(isinstance(v, Mapping) for v in value):
            raise ConfigError(f"{self.key(name)} must be an array of tables [[{name}]]")
        return [_Table(v, f"{self.key(name)}[{i}]") for i, v in enumerate(value)]

    def numbers(self, name: str) -> list[float]:
        """A required non-empty array of finite numbers."""
        value = self.value(name)
        key = self.key(name)
        if value is None:
            raise ConfigError(f"{key} is missing")
        if value == []:
            raise ConfigError(f"{key} = [] is empty; list at least one value")
        if not isinstance(value, list):
            raise ConfigError(f"{key} = {value!r} must be an array of numbers")
        return [_number(v, f"{key}[{i}]") for i, v in enumerate(value)]

    def exposures(self, name: str = "exposures_ms") -> tuple[float, ...]:
        """A required non-empty array of positive exposures."""
        values = self.numbers(name)
        for i, value in enumerate(values):
            if value <= 0:
                raise ConfigError(f"{self.key(name)}[{i}] = {value:g} must be positive")
        return tuple(values)


def _range_values(table: _Table, azimuth: bool) -> list[float]:
    start, stop, step = (table.number(k) for k in ("start", "stop", "step"))
    table.finish()
    if step <= 0:
        raise ConfigError(f"{table.key('step')} = {step:g} must be positive")
    if stop < start:
        raise ConfigError(f"{table.key('stop')} = {stop:g} is below start = {start:g}")
    count = math.floor((stop - start) / step + 1e-9) + 1
    if azimuth and start + (count - 1) * step >= start + 360.0 - 1e-9:
        count = math.ceil((360.0 - 1e-9) / step)  # a full turn: the start is not repeated
    if count > MAX_RANGE_VALUES:
        raise ConfigError(f"{table.path} gives {count} values; at most {MAX_RANGE_VALUES}")
    return [start + k * step for k in range(count)]


def _axis_values(table: _Table, name: str) -> list[float]:
    """An angle axis: a number, an array of numbers or a {start, stop, step} range."""
    key = table.key(name)
    raw = table.peek(name)
    labelled: list[tuple[str, float]]
    if isinstance(raw, Mapping):
        sub = table.sub(name)
        assert sub is not None
        values = _range_values(sub, azimuth=name == "azimuth_deg")
        labelled = [(f"{key} = {{start, stop, step}} gives {v:g}, which", v) for v in values]
    elif isinstance(raw, list):
        labelled = [(f"{key}[{i}] = {v:g}", v) for i, v in enumerate(table.numbers(name))]
    else:
        labelled = [(f"{key} = {table.number(name):g}", float(raw))]
    if name == "inclination_deg":
        for label, value in labelled:
            if not 0.0 <= value <= 90.0:
                raise ConfigError(
                    f"{label} is outside 0..90 (inclination runs from straight above to the "
                    "horizon)"
                )
    return [value for _, value in labelled]


def _poses(table: _Table) -> tuple[Angles, ...]:
    """The poses of ``[cameras]`` or ``[lights]``: a grid of angles, a list, or a layout."""
    table.only("azimuth_deg", "inclination_deg", "poses_deg", "layout", "count")
    forms = [f for f in ("azimuth_deg", "poses_deg", "layout") if table.has(f)]
    if len(forms) != 1:
        raise ConfigError(
            f"[{table.path}] needs exactly one of azimuth_deg + inclination_deg, poses_deg, "
            f"or layout + count; got {', '.join(forms) or 'none'}"
        )
    if forms[0] == "azimuth_deg":
        azimuths = _axis_values(table, "azimuth_deg")
        inclinations = _axis_values(table, "inclination_deg")
        poses: tuple[Angles, ...] = tuple((a, i) for i in inclinations for a in azimuths)
    elif forms[0] == "poses_deg":
        raw = table.value("poses_deg")
        try:
            poses = _angles(raw, table.key("poses_deg"))
        except InputError as error:
            raise ConfigError(str(error)) from None
    else:
        layout = table.string("layout", choices=LAYOUTS)
        count = table.integer("count")
        if count < 1:
            raise ConfigError(f"{table.key('count')} = {count} must be at least 1")
        poses = layout_angles(count, layout)
    table.finish()
    return poses


def _index_list(table: _Table, name: str, count: int, words: Sequence[str]) -> list[int] | str:
    """``name`` as one of ``words`` or an array of indices below ``count``."""
    value = table.value(name)
    key = table.key(name)
    if value is None:
        raise ConfigError(f"{key} is missing; give {' or '.join(map(repr, words))} or indices")
    if isinstance(value, str):
        if value not in words:
            raise ConfigError(f"{key} = {value!r} is not {' or '.join(map(repr, words))}")
        return value
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{key} = {value!r} must be {' or '.join(map(repr, words))} or indices")
    for i, index in enumerate(value):
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < count:
            raise ConfigError(f"{key}[{i}] = {index!r} is not an index in 0..{count - 1}")
    return list(value)


def _calibration(
    tables: Iterable[_Table], cameras: int, lights: int, exposures: tuple[float, ...]
) -> tuple[CalibrationCapture, ...]:
    captures: list[CalibrationCapture] = []
    names: set[str] = set()
    for table in tables:
        table.only("name", "cameras", "lights", "exposures_ms")
        name = table.string("name")
        if not _NAME.match(name):
            raise ConfigError(
                f"{table.key('name')} = {name!r} must be lowercase letters, digits and hyphens"
            )
        if name in names:
            raise ConfigError(f"{table.key('name')} = {name!r} is used twice")
        names.add(name)
        camera_list = _index_list(table, "cameras", cameras, ("all",))
        light_list = _index_list(table, "lights", lights, ("off", "all"))
        bracket = table.exposures() if table.has("exposures_ms") else exposures
        table.finish()
        chosen_cameras = range(cameras) if isinstance(camera_list, str) else camera_list
        chosen_lights: Sequence[int | None] = list(range(lights))
        if not isinstance(light_list, str):
            chosen_lights = list(light_list)
        elif light_list == "off":
            chosen_lights = [None]
        captures += [
            CalibrationCapture(name, c, t, bracket) for c in chosen_cameras for t in chosen_lights
        ]
    return tuple(captures)


def parse_plan(data: Mapping[str, Any], source: str | os.PathLike[str] | None = None) -> SweepPlan:
    """Validate parsed TOML tables and build the plan (keys in ``docs/plans.md``).

    Raises
    ------
    InputError
        Naming the file, the key path and the value.
    """
    where = str(source) if source is not None else "<plan>"
    try:
        root = _Table(data)
        root.only(*_TOP_KEYS)
        version = root.integer("schema_version", PLAN_SCHEMA_VERSION)
        if version != PLAN_SCHEMA_VERSION:
            raise ConfigError(f"schema_version = {version}; only {PLAN_SCHEMA_VERSION} is read")
        exposures = root.exposures()
        cameras_table, lights_table = root.sub("cameras"), root.sub("lights")
        assert cameras_table is not None and lights_table is not None
        cameras, lights = _poses(cameras_table), _poses(lights_table)
        tables = root.subs("calibration")
        plan = SweepPlan(
            cameras=cameras,
            lights=lights,
            exposures_ms=exposures,
            dark_frames=root.boolean("dark_frames", True),
            ordering=root.string("ordering", "optimised", choices=ORDERINGS),
            calibration=_calibration(tables, len(cameras), len(lights), exposures),
        )
        root.finish()
        return plan
    except InputError as error:
        raise InputError(f"{where}: {error}") from None


def load_plan(path: str | os.PathLike[str]) -> SweepPlan:
    """Read and validate a sweep plan file (TOML); see ``docs/plans.md``."""
    return parse_plan(read_toml(path, "plan"), Path(path))
