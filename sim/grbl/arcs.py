"""GRBL 1.1's arcs (G2/G3): the checks ``gcode.c`` makes and the segments ``mc_arc`` plans.

An arc is given by its centre's offset from the start (``I``/``J``/``K``) or by its radius
(``R``, negative for more than half a turn), in the selected plane (G17 XY, G18 ZX, G19 YZ)
with an optional linear move along the third axis (a helix). GRBL checks it as ``gcode.c``
does (:func:`arc_offset`) and cuts it into straight segments whose chords stay within the arc
tolerance ``$12`` of the circle (:func:`arc_points`); every segment is then planned like a G1
block. Segment points are computed exactly (GRBL's small-angle rotation, corrected every 12
segments, lands on the same points to within float error).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from sim.grbl.motion import Vec
from sim.grbl.words import Refused

__all__ = ["PLANES", "arc_offset", "arc_points"]

PLANES: dict[int, tuple[int, int, int]] = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
"""Plane select code to (first plane axis, second plane axis, linear axis), as ``gcode.c``."""

_ANGULAR_EPSILON = 5e-7  # ARC_ANGULAR_TRAVEL_EPSILON: a zero turn is a full circle
_MAX_SEGMENTS = 65535  # mc_arc counts segments in a uint16_t


def arc_offset(
    start: Vec,
    target: Vec,
    plane: int,
    axis_words: frozenset[int],
    offsets: Mapping[int, float],
    radius: float | None,
    clockwise: bool,
) -> tuple[Vec, float]:
    """The centre's offset from ``start`` and the radius of an arc, checked as ``gcode.c`` does.

    Parameters
    ----------
    start, target : machine positions, units
    plane : 17, 18 or 19
    axis_words : the axes (0, 1, 2) the block names
    offsets : the ``I``/``J``/``K`` words by axis, units (offset mode)
    radius : the ``R`` word, units, or None (offset mode)
    clockwise : G2 (True) or G3

    Returns
    -------
    ``(offset, radius)``: the offset of the centre from ``start`` in the plane (zero on the
    linear axis) and the radius, units.

    Raises
    ------
    Refused
        26 no axis words, 32 none in the plane, 33 invalid target (R mode: the target is the
        start; offset mode: the radii to start and target differ by more than 0.5 units, or by
        more than 0.005 units and 0.1 %), 34 the radius is too small for the chord, 35 no
        offsets in the plane.
    """
    first, second, _ = PLANES[plane]
    if not axis_words:
        raise Refused(26)
    if not axis_words & {first, second}:
        raise Refused(32)
    x = target[first] - start[first]
    y = target[second] - start[second]
    offset = [0.0, 0.0, 0.0]
    if radius is not None:
        chord = math.hypot(x, y)
        # GRBL divides by the chord here; one of zero (a pure linear move) is no circle either.
        if target == start or chord == 0.0:
            raise Refused(33)
        h_squared = 4.0 * radius * radius - x * x - y * y
        if h_squared < 0:
            raise Refused(34)
        h_x2_div_d = -math.sqrt(h_squared) / chord
        if not clockwise:
            h_x2_div_d = -h_x2_div_d
        if radius < 0:
            h_x2_div_d, radius = -h_x2_div_d, -radius
        offset[first] = 0.5 * (x - y * h_x2_div_d)
        offset[second] = 0.5 * (y + x * h_x2_div_d)
        return (offset[0], offset[1], offset[2]), radius
    if first not in offsets and second not in offsets:
        raise Refused(35)
    offset[first] = offsets.get(first, 0.0)
    offset[second] = offsets.get(second, 0.0)
    radius = math.hypot(offset[first], offset[second])
    target_radius = math.hypot(x - offset[first], y - offset[second])
    delta = abs(target_radius - radius)
    if delta > 0.005 and (delta > 0.5 or delta > 0.001 * radius):
        raise Refused(33)
    return (offset[0], offset[1], offset[2]), radius


def arc_points(
    start: Vec,
    target: Vec,
    offset: Vec,
    radius: float,
    plane: int,
    clockwise: bool,
    tolerance: float,
) -> list[Vec]:
    """The end points of the arc's segments, as ``mc_arc`` plans them; the last is ``target``.

    Parameters
    ----------
    start, target : machine positions, units
    offset, radius : from :func:`arc_offset`
    plane : 17, 18 or 19
    clockwise : G2 (True) or G3
    tolerance : ``$12``, the largest distance of a chord from the circle, units
    """
    first, second, linear = PLANES[plane]
    centre = (start[first] + offset[first], start[second] + offset[second])
    r0, r1 = -offset[first], -offset[second]
    t0, t1 = target[first] - centre[0], target[second] - centre[1]
    travel = math.atan2(r0 * t1 - r1 * t0, r0 * t0 + r1 * t1)
    if clockwise and travel >= -_ANGULAR_EPSILON:
        travel -= 2 * math.pi
    elif not clockwise and travel <= _ANGULAR_EPSILON:
        travel += 2 * math.pi
    chord_room = tolerance * (2 * radius - tolerance)
    # GRBL would take the root of a negative number (a radius under half the tolerance) or
    # divide by zero ($12=0); both mean the arc is one straight segment here.
    segments = 0
    if chord_room > 0:
        segments = min(
            _MAX_SEGMENTS, math.floor(abs(0.5 * travel * radius) / math.sqrt(chord_room))
        )
    points: list[Vec] = []
    for i in range(1, segments):
        theta = travel * i / segments
        cos, sin = math.cos(theta), math.sin(theta)
        point = list(start)
        point[first] = centre[0] + r0 * cos - r1 * sin
        point[second] = centre[1] + r0 * sin + r1 * cos
        point[linear] = start[linear] + (target[linear] - start[linear]) * i / segments
        points.append((point[0], point[1], point[2]))
    points.append(target)
    return points
