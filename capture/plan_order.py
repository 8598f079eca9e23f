"""Ordering a sweep plan's poses: tours by motion time, and the safe schedule.

The motion model is :mod:`rig.motion_time`'s (every axis at once, each Dynamixel axis its own
trapezoid, the GRBL axes one straight move): the tours minimise its move times and a schedule's
``motion_s`` is its sum.

Two orderings build a :class:`Schedule` (the stops the rig makes, in order):

- ``serpentine``: cameras in plan order; at each camera the lights in ascending order, then
  descending at the next camera, and so on.
- ``optimised``: the cameras toured by camera-move time, and at each camera the lights toured by
  light-move time starting from where the light stands; each tour is the better of a
  nearest-neighbour tour and the index order, each improved by 2-opt (:mod:`capture.tours`).
  The serpentine schedule replaces it when that one leaves out fewer stops, or as many with no
  more motion, so the optimised ordering is never slower than the baseline.

Either way a light stop whose straight move from the previous stop is unsafe
(:func:`rig.safety.path_violation`) is put off, then inserted at the cheapest place of its
camera's stops where both moves around it are safe; a stop that fits nowhere is listed as
unplaced with the reason, as are poses in a forbidden zone or outside the limits
(:func:`rig.safety.pose_violation`). Dark frames are taken at the camera's first light stop's
pose (the light off), so they cost no motion; a camera without light stops takes them with the
light where it stands, or at park.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from capture.tours import open_tour
from core.progress import progress_bar
from rig.config import RigConfig
from rig.motion_time import move_seconds, move_seconds_matrix, path_seconds, pose_row
from rig.pose import ROLES, RigPose
from rig.safety import path_violation, pose_violation

__all__ = [
    "IMAGE_OVERHEAD_S",
    "ORDERINGS",
    "LimitCheck",
    "PlanEstimate",
    "Schedule",
    "Stop",
    "Unplaced",
    "schedules",
]

#: The orderings a plan may ask for.
ORDERINGS = ("optimised", "serpentine")
#: Time per image besides motion and exposure (trigger, readout and transfer, SHA-256, atomic
#: write, journal fsync), seconds; the estimate adds ``light.settle_s`` per light switch.
IMAGE_OVERHEAD_S = 0.5

Angles = tuple[float, float]
FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Stop:
    """A pose where the rig stops to take images.

    ``kind`` is "calibration", "dark" or "light"; ``light_index`` is the plan's light index
    for a light stop, the calibration list index for a calibration stop, None for a dark stop.
    """

    kind: str
    camera_index: int
    light_index: int | None
    pose: RigPose


@dataclass(frozen=True)
class Unplaced:
    """A stop the plan leaves out, and why (same fields as :class:`Stop`, a reason for the pose)."""

    kind: str
    camera_index: int
    light_index: int | None
    reason: str


@dataclass(frozen=True)
class Schedule:
    """The stops in order, the ones left out, and the motion time park -> stops -> park."""

    stops: tuple[Stop, ...]
    unplaced: tuple[Unplaced, ...]
    motion_s: float


@dataclass(frozen=True)
class LimitCheck:
    """The range of one axis a plan uses against the axis' soft limits, degrees."""

    role: str
    low_deg: float
    high_deg: float
    min_deg: float
    max_deg: float

    @property
    def ok(self) -> bool:
        """Whether the used range lies within the limits."""
        return self.min_deg <= self.low_deg and self.high_deg <= self.max_deg


@dataclass(frozen=True)
class PlanEstimate:
    """A plan's counts and estimated duration on a rig.

    Attributes
    ----------
    ordering : str, the plan's ordering (the one ``motion_s`` and ``total_s`` describe)
    cameras, lights, exposures : int, the plan's pose and bracket sizes
    images : dict of kind -> int, the images the events take (every kind listed)
    skipped_pairs : int, (camera, light) pairs left out (forbidden or unreachable)
    unplaced : int, other stops left out (dark frames, calibration captures)
    motion_by_ordering_s : dict of ordering -> float, motion time park -> images -> park
    exposure_s : float, the sum of the exposures
    overhead_s : float, :data:`IMAGE_OVERHEAD_S` per image plus the light's settle time per
        switch
    """

    ordering: str
    cameras: int
    lights: int
    exposures: int
    images: dict[str, int]
    skipped_pairs: int
    unplaced: int
    motion_by_ordering_s: dict[str, float]
    exposure_s: float
    overhead_s: float

    @property
    def total_images(self) -> int:
        """Images of every kind."""
        return sum(self.images.values())

    @property
    def motion_s(self) -> float:
        """Motion time of the plan's ordering."""
        return self.motion_by_ordering_s[self.ordering]

    def duration_s(self, ordering: str | None = None) -> float:
        """Estimated wall time in ``ordering`` (default: the plan's), seconds."""
        motion = self.motion_by_ordering_s[ordering or self.ordering]
        return motion + self.exposure_s + self.overhead_s

    @property
    def total_s(self) -> float:
        """Estimated wall time of the plan's ordering."""
        return self.duration_s()

    @property
    def gain_s(self) -> float:
        """Motion seconds the optimised ordering saves over the serpentine baseline."""
        return self.motion_by_ordering_s["serpentine"] - self.motion_by_ordering_s["optimised"]

    @property
    def gain_fraction(self) -> float:
        """``gain_s`` as a fraction of the serpentine ordering's whole duration."""
        baseline = self.duration_s("serpentine")
        return self.gain_s / baseline if baseline > 0 else 0.0


def _pose(camera: Angles, light: Angles) -> RigPose:
    return RigPose(camera[0], camera[1], light[0], light[1])


def _light_tour(
    config: RigConfig, camera: Angles, lights: Sequence[Angles], start: RigPose
) -> list[int]:
    """Positions into ``lights`` in a short tour from the light pose of ``start``."""
    nodes = [(start.light_azimuth_deg, start.light_inclination_deg), *lights]
    rows = np.array([[camera[0], camera[1], az, incl, 0.0] for az, incl in nodes])
    order = open_tour(move_seconds_matrix(config, rows, rows))
    return [k - 1 for k in order]


def _camera_tour(config: RigConfig, cameras: Sequence[Angles], start: RigPose) -> list[int]:
    """Camera indices in a short tour (camera moves only) from the camera pose of ``start``."""
    nodes = [(start.camera_azimuth_deg, start.camera_inclination_deg), *cameras]
    rows = np.array([[az, incl, 0.0, 0.0, 0.0] for az, incl in nodes])
    order = open_tour(move_seconds_matrix(config, rows, rows))
    return [k - 1 for k in order]


def _separation_deg(pose: RigPose) -> float:
    """Camera-light angle, degrees (plain math: the quick checks run for every move)."""
    tc, pc = math.radians(pose.camera_inclination_deg), math.radians(pose.camera_azimuth_deg)
    tl, pl = math.radians(pose.light_inclination_deg), math.radians(pose.light_azimuth_deg)
    cosine = math.sin(tc) * math.sin(tl) * math.cos(pc - pl) + math.cos(tc) * math.cos(tl)
    return math.degrees(math.acos(max(-1.0, min(1.0, cosine))))


class _Safety:
    """The pose and path checks of :mod:`rig.safety`, with a fast sufficient test in front.

    :func:`rig.safety.pose_violation` and :func:`~rig.safety.path_violation`; the fast test in
    front passes most moves without sampling them.

    The fast test holds when the rig has no forbidden boxes, both ends are within the limits
    (a box, so the straight move is too) and the camera-light angle cannot fall below
    ``safety.min_separation_deg`` on the way: a direction moved by ``(d_incl, d_az)`` turns by
    at most ``|d_incl| + |d_az|``, so the angle along the move stays above ``(sep_start +
    sep_end - motion) / 2``, ``motion`` the sum of those bounds for camera and light.
    """

    def __init__(self, config: RigConfig) -> None:
        self.config = config
        self.limit_deg = config.safety.min_separation_deg
        self.fast = not config.safety.forbidden
        self._checked: dict[tuple[RigPose, RigPose], bool] = {}
        self.bounds = [
            (axis.min_deg, axis.max_deg) if (axis := config.axes.get(role)) else (0.0, 0.0)
            for role in ROLES
        ]

    def _inside(self, pose: RigPose) -> bool:
        return all(
            low <= v <= high for (low, high), (_, v) in zip(self.bounds, pose.items(), strict=True)
        )

    def pose(self, pose: RigPose) -> str | None:
        if self.fast and self._inside(pose) and _separation_deg(pose) > self.limit_deg + 1e-6:
            return None
        return pose_violation(self.config, pose)

    def path_ok(self, start: RigPose, end: RigPose) -> bool:
        """Whether the straight move is safe (conservative by 1e-6 degree of separation)."""
        if not self.fast:
            # The ordering tries the same moves again and again (each insertion point of
            # every light): a rig with forbidden boxes samples each move once.
            known = self._checked.get((start, end))
            if known is None:
                known = self._checked[start, end] = path_violation(self.config, start, end) is None
            return known
        if not (self._inside(start) and self._inside(end)):
            return False
        if self.limit_deg <= 0.0:
            return True
        motion = sum(abs(b - a) for (_, a), (_, b) in zip(start.items(), end.items(), strict=True))
        margin = _separation_deg(start) + _separation_deg(end) - motion
        return margin / 2.0 > self.limit_deg + 1e-6 or self._sampled_safe(start, end)

    def path(self, start: RigPose, end: RigPose) -> str | None:
        """Why the straight move is unsafe, or None."""
        return None if self.path_ok(start, end) else path_violation(self.config, start, end)

    def _sampled_safe(self, start: RigPose, end: RigPose) -> bool:
        """The separation at path_violation's samples, vectorised (its limits hold already)."""
        a, b = pose_row(start), pose_row(end)
        count = max(1, math.ceil(float(np.max(np.abs(b - a))) / self.config.safety.path_step_deg))
        poses = a + np.linspace(0.0, 1.0, count + 1)[:, None] * (b - a)
        camera = np.radians(poses[:, 1]), np.radians(poses[:, 0])
        light = np.radians(poses[:, 3]), np.radians(poses[:, 2])
        cosine = np.sin(camera[0]) * np.sin(light[0]) * np.cos(camera[1] - light[1])
        cosine += np.cos(camera[0]) * np.cos(light[0])
        separation = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
        return bool(np.all(separation > self.limit_deg + 1e-6))


class _Builder:
    """Accumulates stops while tracking where the rig stands."""

    def __init__(self, config: RigConfig) -> None:
        self.config = config
        self.safety = _Safety(config)
        self.current = config.park
        self.stops: list[Stop] = []
        self.unplaced: list[Unplaced] = []

    def place(self, kind: str, camera: int, light: int | None, pose: RigPose) -> str | None:
        """Add a stop if its pose and the move to it are safe; else return why not."""
        problem = self.safety.pose(pose) or self.safety.path(self.current, pose)
        if problem is None:
            self.stops.append(Stop(kind, camera, light, pose))
            self.current = pose
        return problem

    def light_off_stop(
        self, kind: str, camera: int, light: int | None, camera_angles: Angles
    ) -> None:
        """A stop with the light off: the light stays put if it can, else goes to park."""
        problem = ""
        for light_pose in (self.current, self.config.park):
            angles = (light_pose.light_azimuth_deg, light_pose.light_inclination_deg)
            problem = self.place(kind, camera, light, _pose(camera_angles, angles)) or ""
            if not problem:
                return
        self.unplaced.append(Unplaced(kind, camera, light, problem))

    def lights_at(
        self, camera: int, camera_angles: Angles, order: Sequence[int], lights: Sequence[Angles]
    ) -> bool:
        """Light stops at one camera in ``order``; whether any was placed.

        A stop the straight move from the present one cannot reach safely is put off, then
        inserted where both moves around it are safe (the cheapest such place). When some fit
        nowhere, the group is rebuilt starting from each light in turn (nearest first), keeping
        the one that leaves out fewest; those left out are listed with the reason.
        """
        stops = {
            light: Stop("light", camera, light, _pose(camera_angles, lights[light]))
            for light in order
        }
        before = self.current
        group, left = self._group([stops[light] for light in order], before)
        if left:
            starts = sorted(order, key=lambda t: move_seconds(self.config, before, stops[t].pose))
            for start in starts:
                rest = [stops[start], *(stops[t] for t in order if t != start)]
                other, other_left = self._group(rest, before)
                if len(other_left) < len(left):
                    group, left = other, other_left
                if not left:
                    break
        self.stops += group
        self.current = group[-1].pose if group else before
        for stop in left:
            reason = self.safety.path(self.current, stop.pose)
            self.unplaced.append(
                Unplaced("light", camera, stop.light_index, f"unreachable: {reason}")
            )
        return bool(group)

    def _group(self, order: Sequence[Stop], before: RigPose) -> tuple[list[Stop], list[Stop]]:
        """Place ``order`` from ``before``: the stops placed, and those that fit nowhere."""
        group: list[Stop] = []
        current = before
        deferred: list[Stop] = []
        for stop in order:
            if self.safety.path_ok(current, stop.pose):
                group.append(stop)
                current = stop.pose
            else:
                deferred.append(stop)
        left = [stop for stop in deferred if not self._insert(group, stop, before)]
        return group, left

    def _insert(self, group: list[Stop], stop: Stop, before: RigPose) -> bool:
        """Insert ``stop`` into ``group`` (which follows ``before``) where safe and cheapest."""
        best: tuple[float, int] | None = None
        for position in range(len(group) + 1):
            previous = group[position - 1].pose if position > 0 else before
            following = group[position].pose if position < len(group) else None
            if not self.safety.path_ok(previous, stop.pose):
                continue
            added = move_seconds(self.config, previous, stop.pose)
            if following is not None:
                if not self.safety.path_ok(stop.pose, following):
                    continue
                added += move_seconds(self.config, stop.pose, following)
                added -= move_seconds(self.config, previous, following)
            if best is None or added < best[0]:
                best = (added, position)
        if best is None:
            return False
        group.insert(best[1], stop)
        return True

    def motion_s(self) -> float:
        poses = [self.config.park, *(s.pose for s in self.stops), self.config.park]
        return path_seconds(self.config, poses)


def _build(
    config: RigConfig,
    cameras: Sequence[Angles],
    lights: Sequence[Angles],
    *,
    dark_frames: bool,
    calibration: Sequence[tuple[int, int | None]],
    ordering: str,
) -> Schedule:
    builder = _Builder(config)
    for index, (c, t) in enumerate(calibration):
        if t is None:
            builder.light_off_stop("calibration", c, index, cameras[c])
            continue
        problem = builder.place("calibration", c, index, _pose(cameras[c], lights[t]))
        if problem is not None:
            builder.unplaced.append(Unplaced("calibration", c, index, problem))
    allowed: list[list[int]] = []
    for c, camera in enumerate(cameras):
        allowed.append([])
        for t, light in enumerate(lights):
            problem = builder.safety.pose(_pose(camera, light))
            if problem is None:
                allowed[c].append(t)
            else:
                builder.unplaced.append(Unplaced("light", c, t, problem))
    if ordering == "serpentine":
        camera_order = list(range(len(cameras)))
    else:
        camera_order = _camera_tour(config, cameras, builder.current)
    # A bar only when ordering takes a while (thousands of pairs, forbidden boxes to sample).
    bar = progress_bar(camera_order, desc=f"ordering ({ordering})", unit="camera", delay=1.0)
    for position, c in enumerate(bar):
        if ordering == "serpentine":
            order = allowed[c] if position % 2 == 0 else allowed[c][::-1]
        else:
            tour = _light_tour(config, cameras[c], [lights[t] for t in allowed[c]], builder.current)
            order = [allowed[c][k] for k in tour]
        first = len(builder.stops)
        if builder.lights_at(c, cameras[c], order, lights):
            if dark_frames:  # the dark frames at the first light stop's pose: no extra move
                builder.stops.insert(first, Stop("dark", c, None, builder.stops[first].pose))
        elif dark_frames:
            builder.light_off_stop("dark", c, None, cameras[c])
    return Schedule(tuple(builder.stops), tuple(builder.unplaced), builder.motion_s())


def schedules(
    config: RigConfig,
    cameras: Sequence[Angles],
    lights: Sequence[Angles],
    *,
    dark_frames: bool = True,
    calibration: Sequence[tuple[int, int | None]] = (),
) -> dict[str, Schedule]:
    """The stops of a sweep in each ordering, calibration stops first.

    Parameters
    ----------
    config : RigConfig, for the limits, forbidden zones, park pose and speeds
    cameras, lights : sequences of (azimuth_deg, inclination_deg)
    dark_frames : bool, a dark stop (light off) at each camera, before its light stops
    calibration : sequence of (camera index, light index or None for light off), in order

    Returns
    -------
    dict of ordering -> Schedule
        For every name of :data:`ORDERINGS`. The optimised schedule is the serpentine one when
        that leaves out fewer stops, or as many with no more motion.
    """
    built = {
        ordering: _build(
            config,
            cameras,
            lights,
            dark_frames=dark_frames,
            calibration=calibration,
            ordering=ordering,
        )
        for ordering in ORDERINGS
    }
    optimised, baseline = built["optimised"], built["serpentine"]
    if (len(optimised.unplaced), optimised.motion_s) > (len(baseline.unplaced), baseline.motion_s):
        built["optimised"] = baseline
    return built
