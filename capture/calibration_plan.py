"""Calibration captures chosen for a sweep plan: the pairs a rig allows, nearest first."""

from __future__ import annotations

import dataclasses

from capture.plan import CalibrationCapture, SweepPlan
from core.directions import direction_from_angles_deg
from rig.config import RigConfig

__all__ = ["with_calibration_captures"]


def with_calibration_captures(
    plan: SweepPlan, config: RigConfig, *, white_target: bool = True
) -> SweepPlan:
    """``plan`` with the calibration captures ``rig calibrate`` needs (docs/calibration.md).

    A ChArUco capture per camera pose (light on: any light the camera's pose allows), then per
    light pose a mirror-sphere capture and (``white_target``) a white-target capture, both from
    the camera pose nearest the light that the rig allows (the mirror sphere's highlight is then
    far from its limb). The two targets alternate at one pose, which saves a move per light on
    the simulated rig (a real rig's plan groups captures by target: fewer swaps by hand). All
    in the plan's exposure bracket; captures no camera pose allows are left out.
    """
    lights = range(len(plan.lights))
    towards = [direction_from_angles_deg(*angles) for angles in plan.cameras]

    def nearest(t: int) -> list[tuple[int, int]]:
        light = direction_from_angles_deg(*plan.lights[t])
        order = sorted(range(len(towards)), key=lambda c: (-float(towards[c] @ light), c))
        return [(c, t) for c in order]

    # (name, candidate (camera, light) pairs in order of preference)
    wanted: list[tuple[str, list[tuple[int, int]]]] = [
        ("charuco", [(c, t) for t in lights]) for c in range(len(plan.cameras))
    ]
    names = ("mirror-sphere", "white-target") if white_target else ("mirror-sphere",)
    wanted += [(name, nearest(t)) for t in lights for name in names]
    choice = [0] * len(wanted)
    while True:
        chosen = [k for k in range(len(wanted)) if choice[k] < len(wanted[k][1])]
        captures = [
            CalibrationCapture(wanted[k][0], *wanted[k][1][choice[k]], plan.exposures_ms)
            for k in chosen
        ]
        candidate = dataclasses.replace(plan, calibration=tuple(captures))
        unplaced = [
            u.light_index
            for u in candidate.unplaced(config)
            if u.kind == "calibration" and u.light_index is not None
        ]
        if not unplaced:
            return candidate
        for index in unplaced:  # the calibration list index: try the next pair
            choice[chosen[index]] += 1
