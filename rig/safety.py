"""Safety checks of rig poses and moves: soft limits and forbidden zones. Pure functions.

A pose is refused when an axis is outside its ``[min_deg, max_deg]``, when the camera and the
light directions are closer than ``safety.min_separation_deg`` (the light arm would hit the
camera arm, or the camera would shadow the light), or when it lies in one of the forbidden boxes
``[[safety.forbidden]]``. A box gives ``[low, high]`` intervals on any of the four angles and on
the relative azimuth (light azimuth minus camera azimuth, wrapped into [-180, 180)); a pose is in
the box when every interval the box gives contains it. Angles are compared as the axes report
them, without wrapping (only the relative azimuth wraps). See ``docs/rig-config.md``.

The drivers and the executor call :func:`check_pose` / :func:`check_path` before any byte is
sent; the sweep planner uses :func:`pose_violation` to skip and list unsafe pairs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from core.directions import direction_from_angles_deg
from core.errors import ConfigError, SafetyError
from rig.config_schema import Table
from rig.pose import ROLES, RigPose

__all__ = [
    "ZONE_AXES",
    "AxisLimits",
    "ForbiddenZone",
    "GuardedRig",
    "SafetyConfig",
    "check_path",
    "check_pose",
    "describe_pose",
    "escape_violation",
    "parse_safety",
    "path_is_safe",
    "path_violation",
    "pose_violation",
    "relative_azimuth_deg",
    "safety_to_dict",
    "separation_deg",
    "unsafe_poses",
]

#: The quantities a forbidden box can bound, in degrees.
ZONE_AXES = (
    "camera_azimuth_deg",
    "camera_inclination_deg",
    "light_azimuth_deg",
    "light_inclination_deg",
    "relative_azimuth_deg",
)


def relative_azimuth_deg(pose: RigPose) -> float:
    """Light azimuth minus camera azimuth, wrapped into [-180, 180)."""
    return (pose.light_azimuth_deg - pose.camera_azimuth_deg + 180.0) % 360.0 - 180.0


def separation_deg(pose: RigPose) -> float:
    """Angle between the directions toward the camera and toward the light, degrees."""
    return float(
        _separations_deg(
            np.float64(pose.camera_azimuth_deg),
            np.float64(pose.camera_inclination_deg),
            np.float64(pose.light_azimuth_deg),
            np.float64(pose.light_inclination_deg),
        )
    )


def _separations_deg(
    camera_azimuth: Any, camera_inclination: Any, light_azimuth: Any, light_inclination: Any
) -> Any:
    """Camera-light angles in degrees of angles in degrees (arrays or numpy scalars).

    One formula for :func:`separation_deg` and :func:`unsafe_poses`, so the two agree to the
    last bit: directions from the angles (unit by construction), then atan2 of the cross
    product's length and the dot product (exact near 0, where the limit is checked).
    """
    cx, cy, cz = np.moveaxis(direction_from_angles_deg(camera_azimuth, camera_inclination), -1, 0)
    lx, ly, lz = np.moveaxis(direction_from_angles_deg(light_azimuth, light_inclination), -1, 0)
    cross = np.sqrt((cy * lz - cz * ly) ** 2 + (cz * lx - cx * lz) ** 2 + (cx * ly - cy * lx) ** 2)
    return np.degrees(np.arctan2(cross, cx * lx + cy * ly + cz * lz))


def describe_pose(pose: RigPose) -> str:
    """A pose in words, for messages."""
    text = (
        f"camera az {pose.camera_azimuth_deg:g} incl {pose.camera_inclination_deg:g}, "
        f"light az {pose.light_azimuth_deg:g} incl {pose.light_inclination_deg:g}"
    )
    if pose.turntable_deg:
        text += f", turntable {pose.turntable_deg:g}"
    return text + " (deg)"


@dataclass(frozen=True)
class ForbiddenZone:
    """A named box of (camera, light) poses the rig must never reach.

    Each attribute is ``None`` (no bound on that quantity) or ``(low, high)`` in degrees,
    inclusive. ``relative_azimuth_deg`` may have ``low > high``: the interval then wraps through
    180 (``(170, -170)`` is the 20 degrees around the opposite side).
    """

    name: str
    camera_azimuth_deg: tuple[float, float] | None = None
    camera_inclination_deg: tuple[float, float] | None = None
    light_azimuth_deg: tuple[float, float] | None = None
    light_inclination_deg: tuple[float, float] | None = None
    relative_azimuth_deg: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        key = f"safety.forbidden {self.name!r}"
        if not self.name:
            raise ConfigError("safety.forbidden zones need a name (used in messages)")
        if not self.bounds():
            raise ConfigError(f"{key} bounds nothing; give at least one of {', '.join(ZONE_AXES)}")
        for axis, (low, high) in self.bounds():
            if axis == "relative_azimuth_deg":
                if not (-180 <= low <= 180 and -180 <= high <= 180 and low != high):
                    raise ConfigError(
                        f"{key}: {axis} = [{low!r}, {high!r}] needs two different ends in "
                        "[-180, 180]"
                    )
            elif not low <= high:
                raise ConfigError(f"{key}: {axis} = [{low!r}, {high!r}] has low above high")

    def bounds(self) -> list[tuple[str, tuple[float, float]]]:
        """The intervals the zone gives, as ``(quantity, (low, high))``."""
        return [(a, getattr(self, a)) for a in ZONE_AXES if getattr(self, a) is not None]

    def contains(self, pose: RigPose) -> bool:
        """Whether ``pose`` lies in the zone (every given interval holds)."""
        for axis, (low, high) in self.bounds():
            if axis == "relative_azimuth_deg":
                value = relative_azimuth_deg(pose)
                inside = low <= value <= high if low < high else value >= low or value <= high
            else:
                value = float(getattr(pose, axis))
                inside = low <= value <= high
            if not inside:
                return False
        return True

    def describe(self) -> str:
        """The zone in words, for messages: its name and every interval it gives."""
        limits = ", ".join(f"{a} in [{lo:g}, {hi:g}]" for a, (lo, hi) in self.bounds())
        return f"forbidden zone {self.name!r} ({limits})"


@dataclass(frozen=True)
class SafetyConfig:
    """The ``[safety]`` section.

    Attributes
    ----------
    min_separation_deg : float
        Smallest allowed angle between the camera and the light directions (0 disables it).
    path_step_deg : float
        Sampling step of :func:`path_violation` along a move (largest axis change per sample).
    forbidden : tuple of ForbiddenZone
    """

    min_separation_deg: float = 0.0
    path_step_deg: float = 1.0
    forbidden: tuple[ForbiddenZone, ...] = ()

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_separation_deg < 180.0:
            raise ConfigError(
                f"safety.min_separation_deg = {self.min_separation_deg!r} must be in [0, 180)"
            )
        if not self.path_step_deg > 0.0:
            raise ConfigError(f"safety.path_step_deg = {self.path_step_deg!r} must be positive")
        if not 0.001 <= self.path_step_deg <= 90.0:  # a finer step is millions of checks a move
            raise ConfigError(
                f"safety.path_step_deg = {self.path_step_deg!r} must be in [0.001, 90] degrees"
            )
        names = [zone.name for zone in self.forbidden]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ConfigError(f"safety.forbidden: duplicate zone name {duplicates[0]!r}")


def parse_safety(table: Table) -> SafetyConfig:
    """Read the ``[safety]`` table and its ``[[safety.forbidden]]`` boxes."""
    zones = []
    for zone_table in table.tables("forbidden"):
        zone = ForbiddenZone(
            name=zone_table.string("name"), **{a: zone_table.interval(a) for a in ZONE_AXES}
        )
        zone_table.finish()
        zones.append(zone)
    safety = SafetyConfig(
        min_separation_deg=table.number("min_separation_deg", 0.0),
        path_step_deg=table.number("path_step_deg", 1.0),
        forbidden=tuple(zones),
    )
    table.finish()
    return safety


def safety_to_dict(safety: SafetyConfig) -> dict[str, Any]:
    """The ``[safety]`` table of a config."""
    return {
        "min_separation_deg": safety.min_separation_deg,
        "path_step_deg": safety.path_step_deg,
        "forbidden": [
            {"name": zone.name, **{a: list(b) for a, b in zone.bounds()}}
            for zone in safety.forbidden
        ],
    }


class AxisLimits(Protocol):
    """An axis's soft limits, degrees."""

    @property
    def min_deg(self) -> float:
        """The lowest angle the axis may be commanded to."""
        ...

    @property
    def max_deg(self) -> float:
        """The highest angle the axis may be commanded to."""
        ...


class GuardedRig(Protocol):
    """What the checks read of a rig config (:class:`rig.config.RigConfig`): limits and zones."""

    @property
    def axes(self) -> Mapping[str, AxisLimits]:
        """The rig's axes by role."""
        ...

    @property
    def safety(self) -> SafetyConfig:
        """The config's ``[safety]`` section."""
        ...


def pose_violation(config: GuardedRig, pose: RigPose) -> str | None:
    """Why ``pose`` is unsafe for the rig, or None when it is safe.

    Checks, in order: every axis within its soft limits (a turntable angle needs a turntable
    axis), the camera-light separation, the forbidden boxes.
    """
    for role, value in pose.items():
        axis = config.axes.get(role)
        if axis is None:
            if value != 0.0:
                return f"{role}_deg = {value:g} but the rig has no {role} axis"
        elif value < axis.min_deg:
            return f"{role}_deg = {value:g} is below axes.{role}.min_deg = {axis.min_deg:g}"
        elif value > axis.max_deg:
            return f"{role}_deg = {value:g} is above axes.{role}.max_deg = {axis.max_deg:g}"
    limit = config.safety.min_separation_deg
    if limit > 0.0:
        apart = separation_deg(pose)
        if apart < limit:
            return (
                f"camera and light are {apart:.3g} deg apart, closer than "
                f"safety.min_separation_deg = {limit:g}"
            )
    for zone in config.safety.forbidden:
        if zone.contains(pose):
            return f"the pose is in {zone.describe()}"
    return None


def check_pose(config: GuardedRig, pose: RigPose) -> None:
    """Raise :class:`SafetyError` naming the axis and limit, or the zone, if pose is unsafe."""
    problem = pose_violation(config, pose)
    if problem is not None:
        raise SafetyError(f"refused to move to {describe_pose(pose)}: {problem}")


def _path_fractions(
    config: GuardedRig, start: RigPose, end: RigPose, step_deg: float | None
) -> list[float]:
    """Fractions of the straight move to sample: no axis changes by more than the step."""
    step = config.safety.path_step_deg if step_deg is None else step_deg
    if not step > 0:
        raise SafetyError(f"path sampling step must be positive, got {step}")
    largest = max(abs(b - a) for (_, a), (_, b) in zip(start.items(), end.items(), strict=True))
    count = max(1, math.ceil(largest / step))
    return [i / count for i in range(count + 1)]


def _path_samples(
    config: GuardedRig, start: RigPose, end: RigPose, step_deg: float | None
) -> list[tuple[float, RigPose]]:
    """(fraction, pose) along the straight move, no axis changing by more than the step."""
    return [(f, start.interpolate(end, f)) for f in _path_fractions(config, start, end, step_deg)]


def _unsafe_at(start: RigPose, end: RigPose, fraction: float, problem: str) -> str:
    where = "at its start" if fraction == 0 else f"{fraction:.0%} of the way"
    return (
        f"the move from {describe_pose(start)} to {describe_pose(end)} is unsafe {where}: {problem}"
    )


def unsafe_poses(config: GuardedRig, degrees: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which poses are unsafe, for many poses at once: :func:`pose_violation` is not None.

    Parameters
    ----------
    config : the rig's limits and zones
    degrees : ndarray, shape (N, 5), float64, poses as angles in :data:`rig.pose.ROLES` order

    Returns
    -------
    ndarray, shape (N,), bool. The same arithmetic as :func:`pose_violation`, so the two
    agree sample for sample (tested); this one is what a dry run of thousands of moves can
    afford.
    """
    values = np.asarray(degrees, dtype=np.float64)
    column = {role: values[:, j] for j, role in enumerate(ROLES)}
    unsafe = np.zeros(len(values), dtype=bool)
    for role in ROLES:
        axis = config.axes.get(role)
        if axis is None:
            unsafe |= column[role] != 0.0
        else:
            unsafe |= (column[role] < axis.min_deg) | (column[role] > axis.max_deg)
    limit = config.safety.min_separation_deg
    if limit > 0.0:
        unsafe |= (
            _separations_deg(
                column["camera_azimuth"],
                column["camera_inclination"],
                column["light_azimuth"],
                column["light_inclination"],
            )
            < limit
        )
    relative = (column["light_azimuth"] - column["camera_azimuth"] + 180.0) % 360.0 - 180.0
    for zone in config.safety.forbidden:
        inside = np.ones(len(values), dtype=bool)
        for quantity, (low, high) in zone.bounds():
            if quantity == "relative_azimuth_deg":
                within = (relative >= low) & (relative <= high)
                inside &= within if low < high else (relative >= low) | (relative <= high)
            else:
                value = column[quantity.removesuffix("_deg")]
                inside &= (value >= low) & (value <= high)
        unsafe |= inside
    return unsafe


def path_violation(
    config: GuardedRig, start: RigPose, end: RigPose, *, step_deg: float | None = None
) -> str | None:
    """Why the straight move from start to end is unsafe, or None.

    The move is taken as every axis moving linearly and together (what a synchronised move
    does); it is sampled so no axis changes by more than ``step_deg`` (default
    ``safety.path_step_deg``) between samples, ends included. A zone thinner than the step in
    every direction could slip between samples: keep zones wider than the step.
    """
    fractions = _path_fractions(config, start, end, step_deg)
    a = np.array([value for _, value in start.items()])
    b = np.array([value for _, value in end.items()])
    # As RigPose.interpolate computes each sample, so both checks see the same angles.
    degrees = a + np.array(fractions)[:, None] * (b - a)
    for index in np.flatnonzero(unsafe_poses(config, degrees)):
        fraction = fractions[int(index)]
        problem = pose_violation(config, start.interpolate(end, fraction))  # its words
        if problem is not None:
            return _unsafe_at(start, end, fraction, problem)
    return None


def escape_violation(
    config: GuardedRig, start: RigPose, end: RigPose, *, step_deg: float | None = None
) -> str | None:
    """Why the straight move does not lead out of an unsafe start into safety, or None.

    A rig can be left unsafe (a controller that powered up at machine zero, a crash): the way
    out is a move whose unsafe samples are all at its beginning (once safe, it stays safe to
    the end) and along which the camera and the light never come closer together. For a safe
    start this is :func:`path_violation`.
    """
    samples = _path_samples(config, start, end, step_deg)
    leaving = True
    closest = separation_deg(start)
    for fraction, pose in samples:
        problem = pose_violation(config, pose)
        if problem is None:
            leaving = False
            continue
        if not leaving:
            return _unsafe_at(start, end, fraction, problem)
        apart = separation_deg(pose)
        if apart < closest - 1e-9:
            return _unsafe_at(
                start, end, fraction, f"{problem}, and it brings camera and light closer"
            )
        closest = apart
    return None


def path_is_safe(
    config: GuardedRig, start: RigPose, end: RigPose, *, step_deg: float | None = None
) -> bool:
    """Whether every sampled pose of the straight move from start to end is safe."""
    return path_violation(config, start, end, step_deg=step_deg) is None


def check_path(
    config: GuardedRig, start: RigPose, end: RigPose, *, step_deg: float | None = None
) -> None:
    """Raise :class:`SafetyError` when the straight move from start to end is unsafe."""
    problem = path_violation(config, start, end, step_deg=step_deg)
    if problem is not None:
        raise SafetyError(f"refused: {problem}")
