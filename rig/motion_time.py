"""How long the rig takes to move: the one motion-time model.

Every axis moves at once, so a move takes the longest of its parts. Each Dynamixel axis runs its
own trapezoid (``velocity_deg_s``, ``acceleration_deg_s2``); the GRBL axes run one straight move
at the smallest ``feed_deg_min`` of them (the feed the gantry is driven at), with the
acceleration GRBL allows along the move's direction (the smallest ``acceleration_deg_s2 /
|u_i|`` over the moving axes, ``u`` the unit direction in rig degrees). From rest to rest, a
trapezoid of distance ``d`` takes ``d / v + v / a`` when it reaches cruise speed and
``2 sqrt(d / a)`` otherwise (:func:`trapezoid_s`).

:class:`rig.hardware.ServoArm` times its moves with :func:`trapezoid_s` (the wait it allows
before a timeout); :mod:`capture.plan_order` orders and estimates plans with
:func:`move_seconds_matrix`, :func:`move_seconds` and :func:`path_seconds`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rig.config import RigConfig
from rig.pose import ROLES, RigPose

__all__ = ["move_seconds", "move_seconds_matrix", "path_seconds", "pose_row", "trapezoid_s"]

FloatArray = NDArray[np.float64]


def trapezoid_s(distance: ArrayLike, velocity: float, acceleration: ArrayLike) -> FloatArray:
    """Duration of a trapezoidal (or triangular) move from rest to rest, seconds.

    Parameters
    ----------
    distance : array_like, float, >= 0, degrees (any shape)
    velocity : float, > 0, cruise speed, degrees per second
    acceleration : array_like, float, > 0, degrees per second squared (broadcast with
        ``distance``)

    Returns
    -------
    ndarray, float64, the broadcast shape (0-d for scalars)
        ``d / v + v / a`` when the move reaches cruise speed (``d >= v^2 / a``), else
        ``2 sqrt(d / a)``; 0 for a zero distance whatever the acceleration.
    """
    d = np.asarray(distance, dtype=np.float64)
    a = np.asarray(acceleration, dtype=np.float64)
    with np.errstate(all="ignore"):  # a zero distance (maybe with a zero acceleration) is 0 s
        ramp = velocity / a
        cruise = d / velocity + ramp
        triangle = 2.0 * np.sqrt(d / a)
        return np.where(d <= 0.0, 0.0, np.where(d < velocity * ramp, triangle, cruise))


def move_seconds_matrix(config: RigConfig, start: FloatArray, end: FloatArray) -> FloatArray:
    """Motion time of every move from ``start[i]`` to ``end[j]``, seconds.

    Parameters
    ----------
    config : RigConfig, whose axes' speeds are used
    start, end : ndarray, shapes (n, 5) and (m, 5), degrees in :data:`rig.pose.ROLES` order

    Returns
    -------
    ndarray, shape (n, m)
    """
    delta = np.abs(end[None, :, :] - start[:, None, :])
    seconds = np.zeros(delta.shape[:2])
    axes = [(i, config.axes[r]) for i, r in enumerate(ROLES) if r in config.axes]
    for i, axis in axes:
        if axis.device == "dynamixel":
            acceleration = np.full(delta.shape[:2], axis.acceleration_deg_s2)
            part = trapezoid_s(delta[..., i], axis.velocity_deg_s, acceleration)
            seconds = np.maximum(seconds, part)
    gantry = [(i, axis) for i, axis in axes if axis.device == "grbl"]
    if gantry:
        columns = [i for i, _ in gantry]
        length = np.sqrt(np.sum(delta[..., columns] ** 2, axis=-1))
        feed_deg_s = min(axis.feed_deg_min for _, axis in gantry) / 60.0
        acceleration = np.full(length.shape, np.inf)
        with np.errstate(all="ignore"):  # an axis that does not move does not limit
            for i, axis in gantry:
                allowed = axis.acceleration_deg_s2 * length / delta[..., i]
                acceleration = np.minimum(
                    acceleration, np.where(delta[..., i] > 0, allowed, np.inf)
                )
        acceleration = np.where(np.isfinite(acceleration), acceleration, 1.0)
        seconds = np.maximum(seconds, trapezoid_s(length, feed_deg_s, acceleration))
    return seconds


def pose_row(pose: RigPose) -> FloatArray:
    """A pose's degrees as a row, shape (5,), float64, in :data:`rig.pose.ROLES` order."""
    return np.array([value for _, value in pose.items()], dtype=np.float64)


def move_seconds(config: RigConfig, start: RigPose, end: RigPose) -> float:
    """Motion time of the straight move from ``start`` to ``end``, seconds."""
    return float(move_seconds_matrix(config, pose_row(start)[None], pose_row(end)[None])[0, 0])


def path_seconds(config: RigConfig, poses: Sequence[RigPose]) -> float:
    """Motion time along consecutive poses, seconds."""
    if len(poses) < 2:
        return 0.0
    rows = np.array([pose_row(p) for p in poses])
    return float(move_seconds_matrix(config, rows[:-1], rows[1:]).diagonal().sum())
