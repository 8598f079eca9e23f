"""The whole rig of a config: the camera arm's servos, the light gantry and its light, a camera.

:class:`Rig` is what a capture session drives: ``move_to(RigPose)`` checks the pose and the
straight path to it against the config's limits and forbidden zones before any byte is sent,
then moves the servo chain and the gantry together and waits for both; ``light_on`` /
``light_off``; ``capture``; ``park``. Leaving it (``with Rig(...)``, or ``close()``) switches
the light off, stops motion and takes the servos' torque off on every path, errors included.

The device adapters :class:`ServoArm` and :class:`LightGantry` give the drivers
(:mod:`rig.dynamixel`, :mod:`rig.grbl`) the role-addressed interface of
:class:`rig.devices.PoseAxes`, converting rig degrees with each axis' config.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Mapping
from dataclasses import replace
from types import TracebackType

from core.errors import DeviceError, InputError, RigError, SafetyError
from core.exclusive_lock import ExclusiveLock
from rig.config import XM430_W350, AxisConfig, RigConfig
from rig.devices import Camera, Frame, LightState, close_after
from rig.dynamixel import DynamixelChain, ServoAxisConfig
from rig.grbl import GantryAxes, GantryAxisConfig, GrblGantry
from rig.motion_time import trapezoid_s
from rig.port_lock import port_lock
from rig.pose import RigPose
from rig.safety import check_path, check_pose, escape_violation, pose_violation

__all__ = ["LightGantry", "Rig", "ServoArm", "gantry_axis", "servo_axis"]

#: Extra time a move may take beyond the slowest axis' trapezoid (controller latency, polling).
MOVE_MARGIN_S = 5.0


def servo_axis(axis: AxisConfig, model_number: int = XM430_W350) -> ServoAxisConfig:
    """The driver's view of a Dynamixel axis of the config.

    The config counts servo degrees from the servo's tick 0 (``device = scale (rig -
    offset)``); the driver's offset is the rig angle at the centre tick (180 servo degrees).
    """
    if axis.servo_id is None:
        raise InputError(f"axes.{axis.role} is not a dynamixel axis")
    return ServoAxisConfig(
        id=axis.servo_id,
        role=axis.role,
        offset_deg=axis.from_device(180.0),
        direction=axis.direction,
        gear_ratio=axis.gear_ratio,
        min_deg=axis.min_deg,
        max_deg=axis.max_deg,
        velocity_deg_s=axis.velocity_deg_s,
        acceleration_deg_s2=axis.acceleration_deg_s2,
        model_number=model_number,
    )


def gantry_axis(axis: AxisConfig) -> GantryAxisConfig:
    """The driver's view of a GRBL axis of the config."""
    if axis.grbl_axis not in ("X", "Y", "Z"):
        raise InputError(f"axes.{axis.role} is not a GRBL axis")
    return GantryAxisConfig(
        letter=axis.grbl_axis,  # type: ignore[arg-type]
        min_deg=axis.min_deg,
        max_deg=axis.max_deg,
        offset_deg=axis.offset_deg,
        direction=1 if axis.direction > 0 else -1,
        units_per_deg=axis.units_per_deg,
        max_rate_deg_min=axis.feed_deg_min,
        acceleration_deg_s2=axis.acceleration_deg_s2,
    )


class ServoArm:
    """The Dynamixel axes of a config (the camera arm, a turntable) as :class:`PoseAxes`."""

    def __init__(self, config: RigConfig) -> None:
        if config.servos is None:
            raise InputError("the rig config has no [servos] section")
        self._axes = config.axes_of("dynamixel")
        self._lock = port_lock(config.servos.port)
        self.chain = DynamixelChain(
            config.servos.port,
            config.servos.baudrate,
            [servo_axis(a, config.servos.model_number) for a in self._axes.values()],
        )

    @property
    def roles(self) -> tuple[str, ...]:
        """The roles of the config's Dynamixel axes."""
        return tuple(self._axes)

    def connect(self) -> None:
        """Lock and open the servo chain's port, check and configure every servo, torque on."""
        with _locked_while_failing(self._lock):
            self.chain.connect()

    def move_to_deg(self, targets: Mapping[str, float]) -> None:
        """Start a synchronised move of some servos to ``{role: degrees}``; returns at once."""
        self.chain.move_many_deg(targets, wait=False)

    def wait_until_arrived(self, timeout_s: float) -> None:
        """Block until every servo has stopped at its target, within ``timeout_s`` seconds."""
        self.chain.wait_until_arrived(self.roles, timeout_s)

    def position_deg(self) -> dict[str, float]:
        """The measured position of every servo axis, ``{role: degrees}``."""
        return self.chain.positions_deg()

    def seconds_to(self, start: Mapping[str, float], end: Mapping[str, float]) -> float:
        """Time the slowest axis needs for the move (its trapezoid), seconds."""
        return max(
            (
                float(trapezoid_s(abs(end[r] - start[r]), a.velocity_deg_s, a.acceleration_deg_s2))
                for r, a in self._axes.items()
                if r in end
            ),
            default=0.0,
        )

    def clear_faults(self) -> str:
        """Reboot every servo reporting a hardware error, then torque on; what was done."""
        faulty = [role for role, errors in self.chain.hardware_errors().items() if errors]
        for role in faulty:
            self.chain.reboot(role)
        if faulty:
            self.chain.torque(True)
        return f"rebooted {', '.join(faulty)}" if faulty else ""

    def stop(self) -> None:
        """Hold every servo at its present position (clamped to the soft limits)."""
        # Holding the present position is the servos' stop: the goal becomes where they are
        # (kept inside the soft limits, which a servo may overshoot by a tick).
        here = self.chain.positions_deg()
        self.chain.move_many_deg(
            {r: min(max(v, self._axes[r].min_deg), self._axes[r].max_deg) for r, v in here.items()},
            wait=False,
        )

    def close(self) -> None:
        """Switch torque off on every servo and close the port (then give back its lock)."""
        try:
            self.chain.close()
        finally:
            self._lock.release()


class LightGantry:
    """The GRBL gantry of a config: light azimuth and inclination, and the light."""

    def __init__(self, config: RigConfig) -> None:
        gantry = config.gantry
        if gantry is None:
            raise InputError("the rig config has no [gantry] section")
        axes = config.axes_of("grbl")
        missing = {"light_azimuth", "light_inclination"} - set(axes)
        if missing:
            raise InputError(
                f"the light gantry drives light_azimuth and light_inclination; "
                f"{', '.join(sorted(missing))} is not a grbl axis in the config"
            )
        self._azimuth, self._inclination = axes["light_azimuth"], axes["light_inclination"]
        self.homing = gantry.homing
        self.settle_s = config.light.settle_s
        self._lock = port_lock(gantry.port)
        self.gantry = GrblGantry(
            gantry.port,
            gantry.baudrate,
            GantryAxes(gantry_axis(self._azimuth), gantry_axis(self._inclination)),
            light=config.light.control,
            feed_deg_min=min(self._azimuth.feed_deg_min, self._inclination.feed_deg_min),
            unlock_on_connect=gantry.unlock_on_alarm,
        )
        self.light = LightState()

    @property
    def roles(self) -> tuple[str, ...]:
        """``("light_azimuth", "light_inclination")``."""
        return ("light_azimuth", "light_inclination")

    def connect(self) -> None:
        """Connect to GRBL, then run its homing cycle when the config asks for homing.

        Raises
        ------
        DeviceError
            GRBL is locked in alarm and the config neither homes nor unlocks it: nothing of the
            rig can move until an operator decides how.
        """
        with _locked_while_failing(self._lock):
            self.gantry.connect()
        if self.homing:
            self.gantry.home()
        status = self.gantry.status()
        if status.state == "Alarm":
            needs = "homing ($22=1)" if self.gantry.homing_enabled else "an unlock"
            raise DeviceError(
                f"GRBL at {self.gantry.port} is locked in alarm and needs {needs} before "
                "anything moves: set gantry.homing = true in the rig config to home on connect "
                "(a gantry with limit switches), or place the gantry by hand and set "
                "gantry.unlock_on_alarm = true (or send '$X' in a GRBL terminal)"
            )

    def move_to_deg(self, targets: Mapping[str, float]) -> None:
        """Start a move of the light to ``{role: degrees}``; an axis not named keeps its place."""
        # A status round trip only when an axis keeps its place (Rig.move_to names both).
        here = targets if set(self.roles) <= set(targets) else {**self.position_deg(), **targets}
        self.gantry.move_to_deg(here["light_azimuth"], here["light_inclination"], wait=False)

    def wait_until_arrived(self, timeout_s: float) -> None:
        """Block until GRBL is Idle, within ``timeout_s`` seconds."""
        self.gantry.wait_until_idle(timeout_s)

    def position_deg(self) -> dict[str, float]:
        """The measured light azimuth and inclination, ``{role: degrees}``."""
        azimuth, inclination = self.gantry.position_deg()
        return {"light_azimuth": azimuth, "light_inclination": inclination}

    def seconds_to(self, start: Mapping[str, float], end: Mapping[str, float]) -> float:
        """Time of the straight move at the configured feed, seconds (acceleration ignored)."""
        distance = sum((end.get(r, start[r]) - start[r]) ** 2 for r in self.roles) ** 0.5
        return 60.0 * distance / self.gantry.feed_deg_min

    def light_on(self, intensity: float = 1.0) -> None:
        """Switch the light on at ``intensity`` in [0, 1], then wait ``light.settle_s``."""
        self.gantry.light_on(intensity)
        self.light = LightState(True, intensity)
        time.sleep(self.settle_s)

    def light_off(self) -> None:
        """Switch the light off, then wait ``light.settle_s``."""
        self.gantry.light_off()
        self.light = LightState()
        time.sleep(self.settle_s)

    def clear_faults(self) -> str:
        """Clear an alarm: home when the config homes, else unlock; what was done."""
        if self.gantry.status().state != "Alarm":
            return ""
        if self.homing:
            self.gantry.home()
            return "homed the gantry"
        self.gantry.unlock()
        return "unlocked the gantry"

    def stop(self) -> None:
        """Stop motion and switch the light off, whatever state GRBL is in; never raises."""
        self.gantry.safe_stop()

    def close(self) -> None:
        """Stop motion, switch the light off and close the port (closed even if stopping fails)."""
        try:
            self.gantry.safe_stop()
        finally:
            self.light = LightState()
            try:
                self.gantry.close()
            finally:
                self._lock.release()


class Rig:
    """A rig config's devices, driven in rig poses.

    Parameters
    ----------
    config : RigConfig
    camera : Camera, optional; the frames of :meth:`capture` (a rig can move without one)
    """

    def __init__(self, config: RigConfig, camera: Camera | None = None) -> None:
        self.config = config
        self.camera = camera
        self.arm = ServoArm(config) if config.axes_of("dynamixel") else None
        self.gantry = LightGantry(config)
        self._connected = False

    @property
    def devices(self) -> tuple[ServoArm | LightGantry, ...]:
        """The servo arm (when the config has Dynamixel axes) and the light gantry."""
        return (self.gantry,) if self.arm is None else (self.arm, self.gantry)

    def connect(self) -> None:
        """Connect every device; on a failure the ones already connected are closed."""
        try:
            if self.arm is not None:
                self.arm.connect()
            self.gantry.connect()
            self.gantry.light_off()
        except BaseException:
            self.close()
            raise
        self._connected = True

    # The context-manager protocol, alike in shape to core.exclusive_lock's (duplicates pairs
    # them): connecting and a close that says its failures are the Rig's own.
    def __enter__(self) -> Rig:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        close_after(self.close, exc)

    def close(self) -> None:
        """Light off, motion stopped, torque off, ports closed; every step is attempted."""
        problems: list[str] = []
        for step in (self.gantry.close, *(() if self.arm is None else (self.arm.close,))):
            try:
                step()
            except RigError as error:
                problems.append(str(error))
        if self.camera is not None:
            with contextlib.suppress(RigError):
                self.camera.close()
        self._connected = False
        if problems:
            raise DeviceError("closing the rig: " + "; ".join(problems))

    def pose(self) -> RigPose:
        """The measured pose of every axis."""
        positions: dict[str, float] = {}
        for device in self.devices:
            positions.update(device.position_deg())
        return RigPose.from_roles(positions)

    def state(self) -> tuple[RigPose, LightState]:
        """The measured pose and the light: the simulated camera's view of the rig."""
        return self.pose(), self.gantry.light

    def move_to(self, pose: RigPose, *, wait: bool = True) -> RigPose | None:
        """Move every axis to ``pose`` together; returns the measured pose when ``wait``.

        Raises
        ------
        SafetyError
            The pose, or the straight path from the present pose to it, is outside the limits
            or crosses a forbidden zone; nothing was sent.
        """
        check_pose(self.config, pose)
        start = self.pose()
        if pose_violation(self.config, start) is None:
            check_path(self.config, start, pose)
        else:
            # Only a move that leads out of the unsafe start (and never back) may start there.
            problem = escape_violation(self.config, start, pose)
            if problem is not None:
                raise SafetyError(f"refused: {problem}")
        targets = dict(pose.items())
        begin = dict(start.items())
        seconds = 0.0
        for device in self.devices:
            wanted = {role: targets[role] for role in device.roles if role in targets}
            device.move_to_deg(wanted)
            seconds = max(seconds, device.seconds_to(begin, wanted))
        if not wait:
            return None
        self.wait_until_arrived(2.0 * seconds + MOVE_MARGIN_S)
        return self.pose()

    def wait_until_arrived(self, timeout_s: float) -> None:
        """Block until every device's axes are at their targets, ``timeout_s`` each."""
        for device in self.devices:
            device.wait_until_arrived(timeout_s)

    def clear_faults(self) -> str:
        """Clear every device's own faults (see each device); what was done, in words."""
        done = [device.clear_faults() for device in self.devices]
        return "; ".join(d for d in done if d) or "nothing to clear"

    def park(self) -> RigPose | None:
        """Light off, then move to the config's park pose by the first safe route.

        Routes tried: straight; the light first, then the camera; the camera first, then the
        light (a straight move may sweep the light past the camera where moving one arm at a
        time does not). From an unsafe pose (a controller that powered up at machine zero), the
        first leg may start unsafe if it leads out and never back in
        (:func:`rig.safety.escape_violation`).
        """
        self.gantry.light_off()
        here, park = self.pose(), self.config.park
        light_first = replace(
            here,
            light_azimuth_deg=park.light_azimuth_deg,
            light_inclination_deg=park.light_inclination_deg,
        )
        camera_first = replace(
            here,
            camera_azimuth_deg=park.camera_azimuth_deg,
            camera_inclination_deg=park.camera_inclination_deg,
        )
        routes = ((park,), (light_first, park), (camera_first, park))
        for route in routes:
            legs = zip((here, *route[:-1]), route, strict=True)
            if all(
                pose_violation(self.config, b) is None
                and escape_violation(self.config, a, b) is None
                for a, b in legs
            ):
                reached = None
                for pose in route:
                    reached = self.move_to(pose)
                return reached
        return self.move_to(park)  # raises SafetyError naming the unsafe stretch

    def light_on(self, intensity: float = 1.0) -> None:
        """Switch the light on at ``intensity`` in [0, 1] and wait for it to settle."""
        self.gantry.light_on(intensity)

    def light_off(self) -> None:
        """Switch the light off and wait for it to settle."""
        self.gantry.light_off()

    def stop(self) -> None:
        """Stop every axis now (never raises)."""
        for device in self.devices:
            with contextlib.suppress(RigError):
                device.stop()

    def capture(self, exposure_ms: float) -> Frame:
        """Take one frame exposed for ``exposure_ms`` ms; InputError when built without a camera."""
        if self.camera is None:
            raise InputError("this rig was built without a camera")
        return self.camera.capture(exposure_ms)


@contextlib.contextmanager
def _locked_while_failing(lock: ExclusiveLock) -> Iterator[None]:
    """Take ``lock`` for a device's connect; give it back if the connect fails."""
    lock.acquire()
    try:
        yield
    except BaseException:
        lock.release()
        raise
