"""``rig doctor``: connect to every device of a rig config and exercise it a little.

Each check is a row of the report (device, what was tried, ok or the error in words); a
check that fails does not stop the others, and the rig is left safe (light off, axes back
where they were, torque off) whatever happened.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

from core.errors import RigError, SafetyError
from rig.devices import Camera
from rig.hardware import LightGantry, Rig, ServoArm
from rig.pose import RigPose
from rig.safety import describe_pose, pose_violation

__all__ = ["DoctorCheck", "format_checks", "run_doctor"]

#: How far each axis is moved and back, degrees.
NUDGE_DEG = 2.0


@dataclass(frozen=True)
class DoctorCheck:
    """One row of the report."""

    device: str
    check: str
    ok: bool
    detail: str


def _nudged(rig: Rig, pose: RigPose, role: str) -> RigPose | None:
    """``pose`` with one axis moved by NUDGE_DEG inward (a safe direction), or None."""
    axis = rig.config.axes[role]
    value = pose.get(role)
    for step in (NUDGE_DEG, -NUDGE_DEG):
        target = value + step
        if not axis.min_deg <= target <= axis.max_deg:
            continue
        moved = replace(pose, **{f"{role}_deg": target})
        if pose_violation(rig.config, moved) is None:
            return moved
    return None


def run_doctor(rig: Rig, *, exposure_ms: float = 10.0) -> list[DoctorCheck]:
    """Connect, nudge every axis and back, blink the light, take a frame; one row per check."""
    checks: list[DoctorCheck] = []

    def attempt(device: str, check: str, action: Callable[[], str]) -> bool:
        try:
            detail = action()
        except RigError as error:
            checks.append(DoctorCheck(device, check, False, str(error)))
            return False
        checks.append(DoctorCheck(device, check, True, detail))
        return True

    servos = rig.config.servos
    gantry = rig.config.gantry
    connected: list[ServoArm | LightGantry] = []
    if rig.arm is not None and servos is not None:
        ok = attempt(f"servos {servos.port}", "connect", _connect(rig.arm.connect, rig.arm.roles))
        if ok:
            connected.append(rig.arm)
    if gantry is not None:
        ok = attempt(f"gantry {gantry.port}", "connect", _connect(rig.gantry.connect, None))
        if ok:
            connected.append(rig.gantry)
    try:
        if len(connected) == len(rig.devices):
            # A device can fall silent after it answered the connect: a failure to read the
            # start pose is a row of its own, and the rows gathered so far are kept.
            try:
                start: RigPose | None = rig.pose()
            except RigError as error:
                checks.append(DoctorCheck("rig", "read the pose", False, str(error)))
                start = None
            check = f"move {NUDGE_DEG:g} deg and back"
            for role, axis in rig.config.axes.items():
                if start is not None:
                    attempt(f"axis {role} ({axis.device})", check, _nudge(rig, start, role))
            attempt(f"light ({rig.config.light.control})", "on, off", _blink(rig))
        if rig.camera is not None:
            attempt(
                f"camera ({rig.config.camera.backend})", "capture", _frame(rig.camera, exposure_ms)
            )
    finally:
        for part in connected:
            try:
                part.close()
            except RigError as error:
                checks.append(DoctorCheck(type(part).__name__, "close", False, str(error)))
        if rig.camera is not None:
            try:
                rig.camera.close()
            except RigError as error:
                checks.append(DoctorCheck("camera", "close", False, str(error)))
    return checks


def _connect(connect: Callable[[], None], roles: tuple[str, ...] | None) -> Callable[[], str]:
    def action() -> str:
        connect()
        return "answers" + (f": {', '.join(roles)}" if roles else "")

    return action


def _nudge(rig: Rig, start: RigPose, role: str) -> Callable[[], str]:
    def action() -> str:
        target = _nudged(rig, start, role)
        if target is None:
            # An axis that did not move has not been checked: that is a failure to report.
            problem = pose_violation(rig.config, start)
            why = f" (the start pose is unsafe: {problem})" if problem else ""
            raise SafetyError(
                f"not checked: no safe direction to move {NUDGE_DEG:g} deg from "
                f"{describe_pose(start)}{why}; park the rig, then run the doctor again"
            )
        there = rig.move_to(target)
        back = rig.move_to(start)
        assert there is not None and back is not None
        moved = there.get(role) - start.get(role)
        return f"moved {moved:+.2f} deg, back within {abs(back.get(role) - start.get(role)):.2f}"

    return action


def _blink(rig: Rig) -> Callable[[], str]:
    def action() -> str:
        rig.light_on(1.0)
        rig.light_off()
        return "switched on and off"

    return action


def _frame(camera: Camera, exposure_ms: float) -> Callable[[], str]:
    def action() -> str:
        frame = camera.capture(exposure_ms)
        if frame.pixels is not None:
            shape = "x".join(str(n) for n in frame.pixels.shape)
            mean = float(frame.pixels.mean())
            return (
                f"{shape} {frame.pixels.dtype}, mean {mean:.1f}" if math.isfinite(mean) else shape
            )
        return f"wrote {frame.path}"

    return action


def format_checks(checks: list[DoctorCheck]) -> str:
    """The report as an aligned text table."""
    rows = [("device", "check", "result", "detail")] + [
        (c.device, c.check, "ok" if c.ok else "FAILED", c.detail) for c in checks
    ]
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    return "\n".join(
        "  ".join(cell.ljust(width) for cell, width in zip(row[:3], widths, strict=True))
        + "  "
        + row[3]
        for row in rows
    )
