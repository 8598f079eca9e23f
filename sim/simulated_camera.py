"""The simulated rig's camera: renders the synthetic scene at the rig's current pose and light.

Before each capture it asks a state source (:data:`rig.devices.RigStateSource`, the emulators'
state in the simulated rig, a plain function in tests) for the pose and the light, renders the
scene with :func:`sim.synthetic_camera.render_under_light` (camera on the arm looking at the
origin; a directional light of irradiance ``intensity``, or a point light at ``light_distance``
delivering that irradiance at the origin) and records it through the sensor model
(:mod:`sim.sensor`), exactly as ``rig sim photo`` does. :meth:`SimulatedCamera.place_target`
puts a calibration target at the object's place instead (:data:`TARGETS`, rendered by
:mod:`sim.calibration_targets`): the ChArUco board :data:`BOARD` lying flat, the mirror sphere
(radius :data:`MIRROR_SPHERE_RADIUS`) reflecting the rig's light, or the white target
:data:`WHITE_TARGET`; ``None`` puts the object back. A turntable angle rotates the object,
which is the same as rotating camera and light the other way about ``+z``.

Sensor noise is seeded by the pose, the light and the exposure, so two captures of the same
pose are byte-identical (resumed captures reproduce an uninterrupted run). Light off gives a
dark frame: black level and read noise only. Faults (:class:`rig.config.CameraFaultConfig`):
time out after N captures, or with a seeded probability, or on demand (:meth:`fail_next`).
"""

from __future__ import annotations

import hashlib
import os
import struct
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.directions import angles_deg_from_direction, direction_from_angles_deg
from core.errors import DeviceError, InputError
from rig.config_cameras import SIMULATED_OUTPUTS, CameraFaultConfig, SimulatedCameraConfig
from rig.devices import CameraTimeoutError, Frame, LightState, RigStateSource, frame_metadata
from rig.pose import RigPose
from sim.calibration_targets import (
    DiscLight,
    WhiteTarget,
    render_charuco,
    render_mirror_sphere,
    render_white_target,
)
from sim.scenes import build_scene
from sim.sensor import Sensor, bayer_mosaic, expose, to_linear16, to_srgb8
from sim.sensor_files import write_dng
from sim.synthetic_camera import DirectionalLight, PointLight, render_under_light

__all__ = [
    "BOARD",
    "BOARD_RADIANCE",
    "LIGHT_DISC_DEG",
    "MIRROR_SPHERE_RADIUS",
    "TARGETS",
    "WHITE_TARGET",
    "SimulatedCamera",
    "capture_seed",
]

#: Calibration targets :meth:`SimulatedCamera.place_target` knows (capture plan names).
TARGETS = ("charuco", "mirror-sphere", "white-target")
#: The simulator's ChArUco board: squares x and y, square and marker length (scene units) and
#: OpenCV dictionary; coarse enough to be found in 160-pixel images of a 40-degree camera at 4
#: units (``processing.calibrate_dataset.DEFAULT_BOARD`` is the same board).
BOARD = (5, 5, 0.45, 0.33, "DICT_4X4_50")
#: Radiance of the board's print per unit reflectance per unit light level (evenly lit; white
#: print, reflectance 0.8, stays below saturation at the default 40 ms exposure).
BOARD_RADIANCE = 0.25
#: The chrome ball's radius, scene units, centred at the origin.
MIRROR_SPHERE_RADIUS = 1.0
#: Angular size of the light as the mirror sphere sees it, degrees: the highlight must cover
#: a few pixels for its centroid to be sub-pixel (a 2-degree disc hides between pixel centres
#: at 160 pixels).
LIGHT_DISC_DEG = 4.0
#: The flat white target, face up at the origin.
WHITE_TARGET = WhiteTarget(albedo=0.8, half_size=1.5)


def capture_seed(seed: int, pose: RigPose, light: LightState, exposure_ms: float) -> int:
    """The sensor-noise seed of one capture: a hash of everything that defines the image."""
    # Rounded so that the last bits of a float read back from an emulator do not matter.
    values = [round(v, 6) for _, v in pose.items()]
    values += [float(light.on), round(light.level, 9), round(exposure_ms, 9)]
    packed = struct.pack(f"<q{len(values)}d", seed, *values)
    return int.from_bytes(hashlib.blake2b(packed, digest_size=8).digest(), "little")


def _camera_angles(azimuth_deg: float, inclination_deg: float) -> tuple[float, float]:
    """Angles the pinhole camera accepts (inclination in [0, 180]) for an arm past the zenith."""
    if 0.0 <= inclination_deg <= 180.0:
        return azimuth_deg, inclination_deg  # keeps the azimuth at the pole (image up)
    azimuth, inclination = angles_deg_from_direction(
        direction_from_angles_deg(azimuth_deg, inclination_deg)
    )
    return float(azimuth), float(inclination)


class SimulatedCamera:
    """A synthetic camera satisfying :class:`rig.devices.Camera`.

    Parameters
    ----------
    state : callable
        Returns the rig's current ``(RigPose, LightState)``.
    scene, points : the synthetic object (``rig sim scenes``) and its number of surface points
    distance, fov_deg, width, height : the camera (see :class:`core.camera_model.PinholeCamera`)
    light_distance : float, optional
        Point light at this distance from the origin; a directional light when None.
    output : {"linear16", "srgb8", "dng"}
        Pixels as 16-bit linear or 8-bit sRGB RGB, or a Bayer DNG file written in ``folder``.
    folder : path, optional
        Where DNG files go (required for ``"dng"``).
    sensor : Sensor, optional
        Sensor model; its exposure time is replaced by each capture's.
    seed : int
        Base of the per-pose noise seeds.
    timeout_s : float
        What a timed-out capture reports (and the cap on ``faults.stall_s``).
    faults : CameraFaultConfig, optional
    """

    def __init__(
        self,
        state: RigStateSource,
        *,
        scene: str = "glossy-sphere",
        points: int = 20_000,
        distance: float = 4.0,
        fov_deg: float = 40.0,
        width: int = 256,
        height: int = 256,
        light_distance: float | None = None,
        output: str = "linear16",
        folder: str | os.PathLike[str] | None = None,
        sensor: Sensor | None = None,
        seed: int = 0,
        timeout_s: float = 5.0,
        faults: CameraFaultConfig | None = None,
    ) -> None:
        if output not in SIMULATED_OUTPUTS:
            raise InputError(f"unknown output {output!r}; use one of {SIMULATED_OUTPUTS}")
        if output == "dng" and (folder is None or width % 2 or height % 2):
            raise InputError("DNG output needs a folder and an even image size")
        PinholeCamera(0.0, 90.0, distance, fov_deg, width, height)  # validates the camera
        self._state = state
        self._samples = build_scene(scene, points)
        if light_distance is not None and light_distance <= self._samples.bounding_radius:
            raise InputError(f"light_distance {light_distance} is inside the object {scene!r}")
        self.scene = scene
        self.distance, self.fov_deg, self.width, self.height = distance, fov_deg, width, height
        self.light_distance = light_distance
        self.output = output
        self.folder = Path(folder) if folder is not None else None
        self.sensor = sensor or Sensor()
        self.seed = seed
        self.timeout_s = timeout_s
        self.faults = faults or CameraFaultConfig()
        self._fault_rng = np.random.default_rng(self.faults.seed)
        self._fail_next = 0
        self._captures = 0
        self._closed = False
        self._last_render: tuple[tuple[Any, ...], NDArray[np.float32]] | None = None
        self.target: str | None = None
        self._board: cv2.aruco.CharucoBoard | None = None

    @classmethod
    def from_config(
        cls,
        config: SimulatedCameraConfig,
        state: RigStateSource,
        *,
        root: str | os.PathLike[str] | None = None,
    ) -> SimulatedCamera:
        """The camera a rig config's ``[camera]`` (backend ``simulated``) describes.

        ``root`` is the folder relative DNG folders are taken from (the config's folder).
        """
        folder = Path(config.folder)
        if root is not None and not folder.is_absolute():
            folder = Path(root) / folder
        return cls(
            state,
            scene=config.scene,
            points=config.points,
            distance=config.distance,
            fov_deg=config.fov_deg,
            width=config.width,
            height=config.height,
            light_distance=config.light_distance,
            output=config.output,
            folder=folder,
            sensor=Sensor(noise=config.noise),
            seed=config.seed,
            timeout_s=config.timeout_s,
            faults=config.faults,
        )

    def fail_next(self, count: int = 1) -> None:
        """Make the next ``count`` captures time out (fault injection on demand)."""
        self._fail_next += count

    def place_target(self, name: str | None) -> None:
        """Show calibration target ``name`` (one of :data:`TARGETS`) or, for None, the object.

        Raises
        ------
        InputError
            An unknown target (the message lists the known ones).
        """
        if name is not None and name not in TARGETS:
            raise InputError(
                f"the simulated camera has no calibration target {name!r}; known: "
                f"{', '.join(TARGETS)}"
            )
        self.target = name

    def _board_object(self) -> cv2.aruco.CharucoBoard:
        if self._board is None:
            squares_x, squares_y, square, marker, dictionary = BOARD
            self._board = cv2.aruco.CharucoBoard(
                (squares_x, squares_y),
                square,
                marker,
                cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)),
            )
        return self._board

    def _render_target(
        self, camera: PinholeCamera, towards: NDArray[np.float64], level: float
    ) -> NDArray[np.float32]:
        """The placed calibration target under a light of ``level`` toward ``towards``."""
        if self.target == "charuco":
            scale = BOARD_RADIANCE * level
            return render_charuco(
                self._board_object(),
                camera,
                white=0.8 * scale,
                black=0.04 * scale,
                background=0.15 * scale,
            )
        direction = (float(towards[0]), float(towards[1]), float(towards[2]))
        disc = DiscLight(
            direction,
            distance=self.light_distance,
            angular_size_deg=LIGHT_DISC_DEG,
            irradiance=level,
        )
        if self.target == "mirror-sphere":
            return render_mirror_sphere(camera, disc, radius=MIRROR_SPHERE_RADIUS)
        return render_white_target(camera, disc, WHITE_TARGET)

    def render(self, pose: RigPose, light: LightState) -> NDArray[np.float32]:
        """Noiseless linear radiance (H, W, 3) at ``pose`` under ``light``.

        Of the scene, or of the calibration target in place (:meth:`place_target`).
        """
        key = (self.target, pose, light.level)
        if self._last_render is not None and self._last_render[0] == key:
            return self._last_render[1]
        if light.level == 0.0:
            rgb = np.zeros((self.height, self.width, 3), dtype=np.float32)
        else:
            # Turning the object by t is turning camera and light by -t.
            azimuth, inclination = _camera_angles(
                pose.camera_azimuth_deg - pose.turntable_deg, pose.camera_inclination_deg
            )
            camera = PinholeCamera(
                azimuth, inclination, self.distance, self.fov_deg, self.width, self.height
            )
            towards = direction_from_angles_deg(
                pose.light_azimuth_deg - pose.turntable_deg, pose.light_inclination_deg
            )
            source: DirectionalLight | PointLight
            if self.target is not None:
                rgb = self._render_target(camera, towards, light.level)
                self._last_render = (key, rgb)
                return rgb
            if self.light_distance is None:
                direction = (float(towards[0]), float(towards[1]), float(towards[2]))
                source = DirectionalLight(direction, irradiance=light.level)
            else:
                where = towards * self.light_distance
                # Intensity chosen so the irradiance at the object's centre is the level.
                source = PointLight(
                    (float(where[0]), float(where[1]), float(where[2])),
                    intensity=light.level * self.light_distance**2,
                )
            rgb = render_under_light(self._samples, camera, source).rgb.astype(np.float32)
        self._last_render = (key, rgb)
        return rgb

    def _check_faults(self) -> None:
        faults = self.faults
        reason = None
        if self._fail_next > 0:
            self._fail_next -= 1
            reason = "on demand"
        elif faults.timeout_after is not None and self._captures > faults.timeout_after:
            reason = f"after {faults.timeout_after} captures"
        elif (
            faults.timeout_probability > 0 and self._fault_rng.random() < faults.timeout_probability
        ):
            reason = f"with probability {faults.timeout_probability:g}"
        if reason is not None:
            time.sleep(min(faults.stall_s, self.timeout_s))
            raise CameraTimeoutError(
                f"simulated camera: no frame within {self.timeout_s:g} s (fault injected {reason})"
            )

    def capture(self, exposure_ms: float) -> Frame:
        """Render the current pose and light and record it through the sensor."""
        metadata = frame_metadata(exposure_ms, "simulated", f"simulated:{self.scene}")
        if self._closed:
            raise DeviceError("simulated camera is closed")
        self._captures += 1
        self._check_faults()
        pose, light = self._state()
        sensor = replace(self.sensor, exposure_s=exposure_ms / 1000.0)
        dn = expose(
            self.render(pose, light), sensor, capture_seed(self.seed, pose, light, exposure_ms)
        )
        metadata.update(
            pose=pose.to_dict(),
            light_on=light.on,
            light_intensity=light.intensity,
            scene=self.scene,
            target=self.target,
            output=self.output,
        )
        if self.output == "dng":
            assert self.folder is not None
            path = self.folder / f"{self._captures:06d}.dng"
            write_dng(path, bayer_mosaic(dn, sensor.pattern), sensor)
            return Frame(path=path, metadata=metadata)
        pixels = to_linear16(dn, sensor) if self.output == "linear16" else to_srgb8(dn, sensor)
        return Frame(pixels=pixels, metadata=metadata)

    def close(self) -> None:
        """Refuse further captures (a DeviceError); closing twice is harmless."""
        self._closed = True
