"""The simulated rig: the servo chain and the GRBL gantry emulated on pseudo-terminals.

:class:`SimulatedRig` starts both emulators for a rig config (the servo ids and GRBL axes it
names, the servos standing at the park pose), and gives the config with the emulators' serial
devices filled in, so the real drivers (:class:`rig.hardware.Rig`) talk to them byte for byte.
``rig sim start`` runs one until Ctrl-C; tests and ``rig capture --sim`` start one in process.
:func:`simulated_camera` renders the synthetic scene at the rig's measured pose and light.
"""

from __future__ import annotations

import dataclasses
from types import TracebackType

from core.errors import InputError
from rig.config import IN_PROCESS_PORT, RigConfig, simulated_config
from rig.config_cameras import SimulatedCameraConfig
from rig.devices import LightState
from rig.hardware import Rig, servo_axis
from rig.pose import RigPose
from sim.dynamixel.emulator import ServoChainEmulator
from sim.dynamixel.faults import FaultConfig
from sim.dynamixel.servo import ServoSpec
from sim.grbl.emulator import GrblEmulator, GrblFaults
from sim.scenes import get_scene
from sim.simulated_camera import SimulatedCamera

__all__ = ["SimulatedRig", "simulated_camera", "simulated_capture_config"]

#: GRBL settings of the emulated gantry before the config's axes are applied: max rates
#: ($110-$112, units/min) high enough that the driver's feed limits a move.
GANTRY_SETTINGS: dict[int, float] = {110: 360_000.0, 111: 360_000.0, 112: 360_000.0}


def simulated_capture_config(
    scene: str,
    *,
    size: int | tuple[int, int] = 128,
    points: int = 20_000,
    speed: float = 1.0,
) -> RigConfig:
    """The simulated rig's config for a capture: the scene, image size and axis speeds.

    ``size`` is the image's side, or its (width, height), in pixels.
    """
    if not speed > 0:
        raise InputError(f"the axis speed factor must be positive, got {speed}")
    get_scene(scene)  # an unknown scene is refused before a dataset is made for it
    base = simulated_config(IN_PROCESS_PORT, IN_PROCESS_PORT, scene=scene)
    axes = {
        role: dataclasses.replace(
            axis,
            velocity_deg_s=axis.velocity_deg_s * speed,
            acceleration_deg_s2=axis.acceleration_deg_s2 * speed**2,
            feed_deg_min=axis.feed_deg_min * speed,
        )
        for role, axis in base.axes.items()
    }
    assert isinstance(base.camera, SimulatedCameraConfig)
    width, height = (size, size) if isinstance(size, int) else size
    camera = dataclasses.replace(base.camera, width=width, height=height, points=points)
    return dataclasses.replace(base, axes=axes, camera=camera)


def _servo_ticks(config: RigConfig, role: str, degrees: float) -> int:
    axis = servo_axis(config.axes[role])
    turns = axis.direction * axis.gear_ratio * (degrees - axis.offset_deg) / 360.0
    return round(2048 + 4096 * turns)


class SimulatedRig:
    """Both emulators of a rig config, running until :meth:`close`.

    Parameters
    ----------
    config : RigConfig, optional
        The rig to emulate (its ports are replaced by the emulators'); default
        :func:`rig.config.simulated_config`.
    servo_faults, gantry_faults : fault injection of the emulators
    light_start_deg : (azimuth, inclination) where the gantry stands at power-up (default: the
        park pose); GRBL reports wherever it stands as the configured machine position
    """

    def __init__(
        self,
        config: RigConfig | None = None,
        *,
        servo_faults: FaultConfig | None = None,
        gantry_faults: GrblFaults | None = None,
        light_start_deg: tuple[float, float] | None = None,
    ) -> None:
        base = config or simulated_config(IN_PROCESS_PORT, IN_PROCESS_PORT)
        servo_roles = base.axes_of("dynamixel")
        specs = [
            ServoSpec(
                id=int(axis.servo_id or 0),
                position_ticks=_servo_ticks(base, role, base.park.get(role)),
            )
            for role, axis in servo_roles.items()
        ]
        settings = dict(GANTRY_SETTINGS)
        settings[30] = base.light.max_s
        # The gantry stands at the park pose too (as a real one left there after a session),
        # unless told where it was left.
        position = [0.0, 0.0, 0.0]
        for role, axis in base.axes_of("grbl").items():
            index = "XYZ".index(str(axis.grbl_axis))
            angle = base.park.get(role)
            if light_start_deg is not None:
                angle = light_start_deg[0 if role == "light_azimuth" else 1]
            position[index] = axis.to_device(angle)
            # The controller accelerates as the config says ($120-$122, units/s^2), so the
            # plan's motion model and the emulated motion agree.
            settings[120 + index] = axis.acceleration_deg_s2 * axis.units_per_deg
        self.servos = ServoChainEmulator(specs, faults=servo_faults) if specs else None
        try:
            self.gantry = GrblEmulator(
                settings=settings,
                faults=gantry_faults,
                position=(position[0], position[1], position[2]),
            ).start()
        except BaseException:
            if self.servos is not None:
                self.servos.close()
            raise
        servos = base.servos
        self.config = dataclasses.replace(
            base,
            servos=None
            if servos is None or self.servos is None
            else dataclasses.replace(servos, port=self.servos.port),
            gantry=dataclasses.replace(base.gantry, port=self.gantry.port)
            if base.gantry is not None
            else None,
        )

    @property
    def ports(self) -> dict[str, str]:
        """The emulators' serial devices by name."""
        ports = {"gantry": self.gantry.port}
        if self.servos is not None:
            ports["servos"] = self.servos.port
        return ports

    def rig(self, *, camera: bool = True) -> Rig:
        """A :class:`Rig` on the emulators (not yet connected), with the simulated camera."""
        rig = Rig(self.config)
        if camera:
            rig.camera = simulated_camera(rig)
        return rig

    # The context-manager protocol (leaving closes), alike in shape to the emulators' (see
    # sim/dynamixel/emulator.py): Python's protocol, no logic worth a shared base class.
    def __enter__(self) -> SimulatedRig:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Stop both emulators and remove their ptys (idempotent)."""
        try:
            if self.servos is not None:
                self.servos.close()
        finally:
            self.gantry.close()


def simulated_camera(rig: Rig) -> SimulatedCamera:
    """The config's simulated camera, seeing the scene at ``rig``'s measured pose and light."""
    camera = rig.config.camera
    if not isinstance(camera, SimulatedCameraConfig):
        raise InputError(f"the rig config's camera is {camera.backend!r}, not simulated")
    root = None if rig.config.source is None else rig.config.source.parent

    def state() -> tuple[RigPose, LightState]:
        pose, light = rig.state()
        # Servo positions are whole ticks: round to 1/100 degree so that a pose the plan asked
        # for renders (and seeds its noise) identically on every run.
        return RigPose.from_roles({r: round(v, 2) for r, v in pose.items()}), light

    return SimulatedCamera.from_config(camera, state, root=root)
