"""Sweep plan files: reading a plan from TOML and validating every key (``docs/plans.md``).

:func:`load_plan` reads a file, :func:`parse_plan` checks tables already parsed. Poses come as
a grid of angles (a number, an array or a ``{start, stop, step}`` range per angle), a list of
poses or a hemisphere layout; calibration captures as ``[[calibration]]`` tables naming cameras
and lights by index or as ``"all"`` / ``"off"``. Every problem is an :class:`InputError` naming
the file, the key path and the value; the result is a :class:`capture.plan.SweepPlan`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from capture.grid_plan import LAYOUTS, layout_angles
from capture.plan import (
    CALIBRATION_NAME,
    MAX_POSES,
    PLAN_SCHEMA_VERSION,
    Angles,
    CalibrationCapture,
    SweepPlan,
    check_plan_size,
    finite_number,
    pose_angles,
)
from capture.plan_order import ORDERINGS
from core.errors import ConfigError, InputError
from rig.config_schema import Table, read_toml

__all__ = ["load_plan", "parse_plan"]

#: The most poses one range may give (a tiny step is a typo, not a plan).
MAX_RANGE_VALUES = 10_000
_TOP_KEYS = "schema_version exposures_ms dark_frames ordering cameras lights calibration".split()


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
        return [finite_number(v, f"{key}[{i}]") for i, v in enumerate(value)]

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
    span = (stop - start) / step
    if not span <= MAX_RANGE_VALUES:  # an overflow (inf) or a typo's step, before any count
        raise ConfigError(
            f"{table.path}: {start:g} to {stop:g} in steps of {step:g} gives more than "
            f"{MAX_RANGE_VALUES} values"
        )
    count = math.floor(span + 1e-9) + 1
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
        if len(azimuths) * len(inclinations) > MAX_POSES:
            raise ConfigError(
                f"[{table.path}] gives {len(azimuths) * len(inclinations)} poses "
                f"({len(azimuths)} azimuths x {len(inclinations)} inclinations); at most "
                f"{MAX_POSES}: check the steps"
            )  # before the grid is expanded
        poses: tuple[Angles, ...] = tuple((a, i) for i in inclinations for a in azimuths)
    elif forms[0] == "poses_deg":
        raw = table.value("poses_deg")
        try:
            poses = pose_angles(raw, table.key("poses_deg"))
        except InputError as error:
            raise ConfigError(str(error)) from None
    else:
        layout = table.string("layout", choices=LAYOUTS)
        count = table.integer("count")
        if not 1 <= count <= MAX_POSES:
            raise ConfigError(f"{table.key('count')} = {count} must be in 1..{MAX_POSES}")
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
        if not CALIBRATION_NAME.match(name):
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
        check_plan_size(len(cameras), len(lights), "the plan")
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
