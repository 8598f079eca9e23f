"""Sweep plans: what a capture takes, as data (bluesky / useq-schema style).

A :class:`SweepPlan` lists camera poses, light poses, an exposure bracket, whether to take dark
frames, calibration captures and an ordering. It never touches a device: :meth:`SweepPlan.events`
turns it, for a given rig config, into the ordered :class:`CaptureEvent` tuple an executor runs
(forbidden pairs skipped, the order chosen by :mod:`capture.plan_order`), and
:meth:`SweepPlan.estimate` and :meth:`SweepPlan.limit_checks` are the dry run. Plans are read
from TOML by :mod:`capture.plan_file` (keys in ``docs/plans.md``), made from hemisphere layouts
by :mod:`capture.grid_plan`, and stored in a dataset's manifest as JSON
(:meth:`SweepPlan.to_dict` / :meth:`SweepPlan.from_dict`).

Image keys: a light image is ``ImageKey("light", camera, light, exposure)``; a dark frame
``ImageKey("dark", camera, None, exposure)``; a calibration capture
``ImageKey("calibration", camera, i, exposure)`` with ``i`` its index in
:attr:`SweepPlan.calibration`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
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
from core.errors import InputError
from rig.config import RigConfig
from rig.pose import CAMERA_ROLES, LIGHT_ROLES, ROLES, RigPose

__all__ = [
    "CALIBRATION_NAME",
    "IMAGE_OVERHEAD_S",
    "MAX_PAIRS",
    "MAX_POSES",
    "ORDERINGS",
    "PLAN_SCHEMA_VERSION",
    "CalibrationCapture",
    "CaptureEvent",
    "LimitCheck",
    "PlanEstimate",
    "SweepPlan",
    "check_plan_size",
    "finite_number",
    "pose_angles",
]

#: Version of the plan's dict and TOML form.
PLAN_SCHEMA_VERSION = 1
#: What a calibration capture's name may be: what is at the object's place, in file-name form.
CALIBRATION_NAME = re.compile(r"^[a-z0-9][a-z0-9-]*$")

Angles = tuple[float, float]

#: The most poses a plan's cameras or lights may be, and the most (camera, light) pairs:
#: checked before poses are expanded (plan files, grid plans), so a typo is refused at once
#: instead of hanging the dry run. A 100 x 100 sweep is 10 000 pairs; the pair limit is a
#: month of capture at half a second per image.
MAX_POSES = 10_000
MAX_PAIRS = 5_000_000


def check_plan_size(cameras: int, lights: int, where: str = "the plan") -> None:
    """Refuse more than :data:`MAX_POSES` cameras or lights, or :data:`MAX_PAIRS` pairs."""
    for what, count in (("camera", cameras), ("light", lights)):
        if count > MAX_POSES:
            raise InputError(f"{where}: {count} {what} poses; at most {MAX_POSES}")
    if cameras * lights > MAX_PAIRS:
        raise InputError(
            f"{where}: {cameras} cameras x {lights} lights = {cameras * lights} pairs; at most "
            f"{MAX_PAIRS}"
        )


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
        if not isinstance(self.name, str) or not CALIBRATION_NAME.match(self.name):
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


def finite_number(value: object, name: str) -> float:
    """``value`` as a float, refusing anything but a finite int or float (bool included).

    Parameters
    ----------
    value : object
        The candidate.
    name : str
        Its key, for the error message.

    Returns
    -------
    float

    Raises
    ------
    InputError
        ``value`` is not a finite number.
    """
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{name} = {value!r} must be a finite number")
    return float(value)


#: The longest exposure a plan may ask for (ms) and the most per pose: beyond, a typo.
MAX_EXPOSURE_MS = 3_600_000.0
MAX_EXPOSURES = 32


def _exposures(values: object, where: str) -> tuple[float, ...]:
    if not isinstance(values, list | tuple) or not values:
        raise InputError(f"{where}: exposures_ms = {values!r} must list at least one exposure")
    exposures = tuple(finite_number(v, f"{where}: exposures_ms[{i}]") for i, v in enumerate(values))
    if len(exposures) > MAX_EXPOSURES:
        raise InputError(
            f"{where}: exposures_ms lists {len(exposures)} exposures; at most {MAX_EXPOSURES} "
            "per pose"
        )
    for i, value in enumerate(exposures):
        if not 0 < value <= MAX_EXPOSURE_MS:
            raise InputError(
                f"{where}: exposures_ms[{i}] = {value:g} must be positive and at most "
                f"{MAX_EXPOSURE_MS:g} ms (an hour)"
            )
    return exposures


def pose_angles(values: object, where: str) -> tuple[Angles, ...]:
    """Poses as ``(azimuth_deg, inclination_deg)`` pairs, inclination within 0..90.

    Parameters
    ----------
    values : object
        A non-empty list or tuple of two-number lists or tuples.
    where : str
        Their key, for error messages.

    Returns
    -------
    tuple of (float, float)

    Raises
    ------
    InputError
        Naming the pose and the value that is not a finite number, or out of range.
    """
    if not isinstance(values, list | tuple) or not values:
        raise InputError(f"{where} must list at least one (azimuth_deg, inclination_deg) pose")
    poses: list[Angles] = []
    for i, pose in enumerate(values):
        if not isinstance(pose, list | tuple) or len(pose) != 2:
            raise InputError(f"{where}[{i}] = {pose!r} is not (azimuth_deg, inclination_deg)")
        azimuth = finite_number(pose[0], f"{where}[{i}] azimuth_deg")
        inclination = finite_number(pose[1], f"{where}[{i}] inclination_deg")
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
        check_plan_size(len(self.cameras), len(self.lights))
        object.__setattr__(self, "cameras", pose_angles(self.cameras, "cameras"))
        object.__setattr__(self, "lights", pose_angles(self.lights, "lights"))
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
        """Counts, motion, exposure and overhead seconds, in both orderings.

        Ordering the stops reports a bar (:mod:`core.progress`) when it takes more than a second.
        """
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

    def require_within_limits(self, config: RigConfig) -> None:
        """Refuse the plan on ``config`` when a pose lies outside an axis' soft limits.

        What ``rig plan`` reports as a violation: a capture refuses it before anything moves
        rather than leaving the unreachable poses out.

        Raises
        ------
        InputError
            Naming each axis, the range the plan uses and the limits.
        """
        bad = [check for check in self.limit_checks(config) if not check.ok]
        if bad:
            ranges = "; ".join(
                f"{c.role} uses {c.low_deg:g} .. {c.high_deg:g} deg, limits "
                f"{c.min_deg:g} .. {c.max_deg:g} deg"
                for c in bad
            )
            raise InputError(
                f"the plan is not runnable on {config.name!r}: a pose lies outside the limits "
                f"({ranges}); change the plan's poses or the rig's limits (rig plan shows the "
                "dry run)"
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
