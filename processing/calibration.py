"""Calibration results: camera intrinsics, camera poses, lights; and their plain-JSON form.

The solvers live beside this module: :mod:`processing.charuco` (intrinsics from ChArUco views,
each camera pose from a board at the object's place), :mod:`processing.light_probe` (light
directions from a mirror sphere) and :mod:`processing.light_falloff` (light intensity and
falloff from a white target). This module holds what they produce and what the dataset's
manifest stores (:meth:`Calibration.to_dict`, the manifest's ``calibration`` field).

Frames and pixels (``docs/calibration.md``):

- Positions and directions are in the rig frame (``docs/conventions.md``): ``+z`` up, scene
  units, directions from the object toward the camera or light.
- A camera's ``axes`` are its right, up and forward unit vectors in the rig frame, as
  :meth:`core.camera_model.PinholeCamera.axes` (image columns grow along right, rows against up).
- Pixel coordinates follow :mod:`core.camera_model`: pixel (row i, col j) covers
  [j, j + 1) x [i, i + 1), so its centre is (j + 0.5, i + 0.5) and a PinholeCamera's principal
  point is exactly (W / 2, H / 2). OpenCV puts pixel centres at integers; the conversion
  (0.5 pixel) happens only here (:meth:`Intrinsics.camera_matrix`).
- Distortion is OpenCV's ``(k1, k2, p1, p2, k3)`` on normalised coordinates of OpenCV's camera
  frame (x right, y down, z forward).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.camera_model import PinholeCamera
from core.colour import srgb_to_linear
from core.directions import angles_deg_from_direction, normalize
from core.errors import DatasetError, InputError

__all__ = [
    "CALIBRATION_SCHEMA",
    "CalibratedCamera",
    "Calibration",
    "CameraPose",
    "ImageInput",
    "Intrinsics",
    "LightCalibration",
    "PoseDisagreement",
    "gray8",
    "linear_luminance",
    "load_image",
]

CALIBRATION_SCHEMA = 1
F64 = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
#: An image array (H, W) or (H, W, 3), or a path cv2 can read.
ImageInput = NDArray[Any] | str | os.PathLike[str]


# --- images ----------------------------------------------------------------------------------


def load_image(image: ImageInput, name: str) -> NDArray[Any]:
    """An image as an array (RGB channel order); paths are read with OpenCV, unchanged depth."""
    if isinstance(image, str | os.PathLike):
        data = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
        if data is None:
            raise InputError(f"{name}: cannot read image file {os.fspath(image)!r}")
        array = np.asarray(data)
        return array[..., ::-1] if array.ndim == 3 else array  # OpenCV reads BGR
    array = np.asarray(image)
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (1, 3, 4)):
        raise InputError(f"{name}: expected an (H, W) or (H, W, 3) image, got {array.shape}")
    return array


def linear_luminance(image: NDArray[Any], name: str) -> F64:
    """Linear luminance (H, W): uint8 is sRGB-decoded, uint16 is linear 16-bit, floats linear."""
    if image.dtype == np.uint8:
        linear: F64 = srgb_to_linear(image / 255.0).astype(np.float64)
    elif image.dtype == np.uint16:
        linear = image / 65535.0
    elif np.issubdtype(image.dtype, np.floating):
        linear = image.astype(np.float64)
    else:
        raise InputError(f"{name}: unsupported pixel type {image.dtype}")
    if not np.isfinite(linear).all():
        raise InputError(f"{name}: the image holds NaN or infinite values")
    if linear.ndim == 2:
        return linear
    if linear.shape[2] == 1:
        return linear[..., 0]
    return 0.2126 * linear[..., 0] + 0.7152 * linear[..., 1] + 0.0722 * linear[..., 2]


def gray8(image: NDArray[Any], name: str) -> NDArray[np.uint8]:
    """8-bit grey for marker detection: uint8 kept as encoded, deeper images scaled to 0..255."""
    if image.dtype == np.uint8:
        grey = image if image.ndim == 2 else image[..., :3].mean(axis=2)
        return np.rint(grey).astype(np.uint8)
    luminance = linear_luminance(image, name)
    # Markers only need contrast: stretch to the brightest percentile, sRGB-encoded so the dark
    # squares keep their steps as in an ordinary photo.
    top = float(np.percentile(luminance, 99.5))
    if top <= 0:
        raise InputError(f"{name}: the image is black")
    encoded = np.clip(luminance / top, 0.0, 1.0)
    encoded = np.where(encoded <= 0.0031308, 12.92 * encoded, 1.055 * encoded ** (1 / 2.4) - 0.055)
    return np.rint(encoded * 255.0).astype(np.uint8)


# --- cameras ---------------------------------------------------------------------------------


def _vec3(values: ArrayLike) -> Vec3:
    v = np.asarray(values, dtype=np.float64).reshape(3)
    return (float(v[0]), float(v[1]), float(v[2]))


def _mat3(values: ArrayLike) -> Mat3:
    m = np.asarray(values, dtype=np.float64).reshape(3, 3)
    return (_vec3(m[0]), _vec3(m[1]), _vec3(m[2]))


@dataclass(frozen=True)
class Intrinsics:
    """A camera's intrinsic parameters.

    Attributes
    ----------
    width, height : int, image size in pixels
    fx, fy : float, focal lengths in pixels
    cx, cy : float, principal point, pixel (row i, col j) centred at (j + 0.5, i + 0.5)
    distortion : (k1, k2, p1, p2, k3), OpenCV's model
    rms_px : float, RMS reprojection error of the calibration, pixels (0 for a nominal camera)
    views : int, images the calibration used
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    rms_px: float = 0.0
    views: int = 0

    @classmethod
    def from_pinhole(cls, camera: PinholeCamera) -> Intrinsics:
        """The ideal intrinsics of a :class:`PinholeCamera` (no distortion)."""
        f = camera.focal_px
        return cls(camera.width, camera.height, f, f, 0.5 * camera.width, 0.5 * camera.height)

    def camera_matrix(self) -> F64:
        """OpenCV's 3 x 3 camera matrix (pixel centres at integers); float64."""
        return np.array(
            [[self.fx, 0.0, self.cx - 0.5], [0.0, self.fy, self.cy - 0.5], [0.0, 0.0, 1.0]]
        )

    def distortion_array(self) -> F64:
        """OpenCV's distortion vector (5,); float64."""
        return np.array(self.distortion, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data."""
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "distortion": list(self.distortion),
            "rms_px": self.rms_px,
            "views": self.views,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Intrinsics:
        """Inverse of :meth:`to_dict`."""
        d = _fields(data, "intrinsics", ("width", "height", "fx", "fy", "cx", "cy", "distortion"))
        distortion = _floats(d["distortion"], "intrinsics.distortion", 5)
        return cls(
            width=int(d["width"]),
            height=int(d["height"]),
            fx=float(d["fx"]),
            fy=float(d["fy"]),
            cx=float(d["cx"]),
            cy=float(d["cy"]),
            distortion=(distortion[0], distortion[1], distortion[2], distortion[3], distortion[4]),
            rms_px=float(d.get("rms_px", 0.0)),
            views=int(d.get("views", 0)),
        )


@dataclass(frozen=True)
class PoseDisagreement:
    """How far a calibrated camera pose is from the pose the rig's kinematics claim.

    Attributes
    ----------
    position_error : float, distance between the two camera centres, scene units
    distance_error : float, calibrated minus nominal distance from the origin, scene units
    direction_error_deg : float, angle at the origin between the two camera centres
    orientation_error_deg : float, angle of the rotation between the two camera frames
    """

    position_error: float
    distance_error: float
    direction_error_deg: float
    orientation_error_deg: float

    def to_dict(self) -> dict[str, float]:
        """Plain JSON data."""
        return {
            "position_error": self.position_error,
            "distance_error": self.distance_error,
            "direction_error_deg": self.direction_error_deg,
            "orientation_error_deg": self.orientation_error_deg,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PoseDisagreement:
        """Inverse of :meth:`to_dict`."""
        names = ("position_error", "distance_error", "direction_error_deg", "orientation_error_deg")
        d = _fields(data, "disagreement", names)
        return cls(*(float(d[n]) for n in names))


@dataclass(frozen=True)
class CameraPose:
    """A camera's pose in the rig frame.

    Attributes
    ----------
    position : (x, y, z), camera centre, scene units
    axes : 3 x 3, rows: the camera's right, up and forward unit vectors in the rig frame
    rms_px : float, RMS reprojection error of the pose fit, pixels
    corners : int, board corners the fit used
    disagreement : PoseDisagreement or None, against the rig's nominal camera when given
    """

    position: Vec3
    axes: Mat3
    rms_px: float = 0.0
    corners: int = 0
    disagreement: PoseDisagreement | None = None

    @classmethod
    def from_pinhole(cls, camera: PinholeCamera) -> CameraPose:
        """The pose of a :class:`PinholeCamera`."""
        return cls(position=_vec3(camera.position), axes=_mat3(camera.axes()))

    @classmethod
    def from_opencv(cls, rotation: ArrayLike, translation: ArrayLike) -> CameraPose:
        """From OpenCV's world-to-camera ``R`` (3, 3) and ``t`` (3,), world = rig frame."""
        r = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        axes = np.stack([r[0], -r[1], r[2]])  # OpenCV's y points down the image
        return cls(position=_vec3(-r.T @ t), axes=_mat3(axes))

    @property
    def rotation(self) -> F64:
        """OpenCV's world (rig) to camera rotation; (3, 3)."""
        right, up, forward = np.asarray(self.axes, dtype=np.float64)
        return np.stack([right, -up, forward])

    @property
    def translation(self) -> F64:
        """OpenCV's world (rig) to camera translation; (3,)."""
        return -self.rotation @ np.asarray(self.position, dtype=np.float64)

    @property
    def viewing_direction(self) -> F64:
        """Unit vector the camera looks along (its forward axis); (3,)."""
        return np.asarray(self.axes[2], dtype=np.float64)

    @property
    def distance(self) -> float:
        """Distance of the camera centre from the origin, scene units."""
        return float(np.linalg.norm(self.position))

    @property
    def azimuth_deg(self) -> float:
        """Azimuth of the camera centre seen from the origin, degrees in [0, 360)."""
        return float(angles_deg_from_direction(self.position)[0])

    @property
    def inclination_deg(self) -> float:
        """Inclination of the camera centre seen from the origin, degrees in [0, 180]."""
        return float(angles_deg_from_direction(self.position)[1])

    def compare(self, nominal: PinholeCamera) -> PoseDisagreement:
        """How far this pose is from ``nominal`` (the camera the rig's kinematics describe)."""
        here = np.asarray(self.position, dtype=np.float64)
        there = nominal.position
        relative = np.asarray(self.axes, dtype=np.float64) @ nominal.axes().T
        cos_angle = np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0)
        direction = np.arctan2(np.linalg.norm(np.cross(here, there)), float(here @ there))
        return PoseDisagreement(
            position_error=float(np.linalg.norm(here - there)),
            distance_error=float(np.linalg.norm(here) - nominal.distance),
            direction_error_deg=math.degrees(float(direction)),
            orientation_error_deg=math.degrees(math.acos(float(cos_angle))),
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (azimuth, inclination and distance are derived, for people)."""
        return {
            "position": list(self.position),
            "axes": [list(row) for row in self.axes],
            "azimuth_deg": self.azimuth_deg,
            "inclination_deg": self.inclination_deg,
            "distance": self.distance,
            "rms_px": self.rms_px,
            "corners": self.corners,
            "disagreement": None if self.disagreement is None else self.disagreement.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> CameraPose:
        """Inverse of :meth:`to_dict` (the derived angles are not read)."""
        d = _fields(data, "camera", ("position", "axes"))
        axes = np.asarray([_floats(row, "camera.axes", 3) for row in d["axes"]])
        if axes.shape != (3, 3) or not np.allclose(axes @ axes.T, np.eye(3), atol=1e-6):
            raise DatasetError(f"calibration camera.axes must be 3 orthonormal rows: {d['axes']}")
        disagreement = d.get("disagreement")
        return cls(
            position=_vec3(_floats(d["position"], "camera.position", 3)),
            axes=_mat3(axes),
            rms_px=float(d.get("rms_px", 0.0)),
            corners=int(d.get("corners", 0)),
            disagreement=None if disagreement is None else PoseDisagreement.from_dict(disagreement),
        )


@dataclass(frozen=True)
class CalibratedCamera:
    """A calibrated camera: intrinsics and pose; casts rays and projects points."""

    intrinsics: Intrinsics
    pose: CameraPose

    @classmethod
    def from_pinhole(cls, camera: PinholeCamera) -> CalibratedCamera:
        """The ideal camera a :class:`PinholeCamera` describes."""
        return cls(Intrinsics.from_pinhole(camera), CameraPose.from_pinhole(camera))

    @property
    def position(self) -> F64:
        """Camera centre in the rig frame; (3,)."""
        return np.asarray(self.pose.position, dtype=np.float64)

    def rays(self, cols: ArrayLike, rows: ArrayLike) -> F64:
        """Unit ray directions (N, 3) in the rig frame through pixel coordinates (N,).

        Coordinates as :mod:`core.camera_model` (pixel (i, j) centred at (j + 0.5, i + 0.5)).
        """
        c = np.asarray(cols, dtype=np.float64).ravel()
        r = np.asarray(rows, dtype=np.float64).ravel()
        pixels = np.stack([c - 0.5, r - 0.5], axis=1)[:, None, :]
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        normalised = cv2.undistortPoints(
            pixels,
            self.intrinsics.camera_matrix(),
            self.intrinsics.distortion_array(),
            criteria=criteria,
        ).reshape(-1, 2)
        local = np.concatenate([normalised, np.ones((len(normalised), 1))], axis=1)
        directions = local @ self.pose.rotation  # camera to rig: multiply by R transposed
        return normalize(directions)

    def project(self, points: ArrayLike) -> tuple[F64, F64, F64]:
        """Pixel coordinates and depth of rig points (N, 3).

        Returns
        -------
        col, row : ndarray (N,), pixel (i, j) centred at (j + 0.5, i + 0.5)
        depth : ndarray (N,), distance along the viewing axis (> 0 in front)
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        rvec, _ = cv2.Rodrigues(self.pose.rotation)
        image, _ = cv2.projectPoints(
            p,
            rvec,
            self.pose.translation,
            self.intrinsics.camera_matrix(),
            self.intrinsics.distortion_array(),
        )
        pixels = np.asarray(image, dtype=np.float64).reshape(-1, 2) + 0.5
        depth = (p - self.position) @ self.pose.viewing_direction
        return pixels[:, 0], pixels[:, 1], depth


def as_calibrated(camera: CalibratedCamera | PinholeCamera) -> CalibratedCamera:
    """A :class:`CalibratedCamera` from either kind of camera."""
    if isinstance(camera, PinholeCamera):
        return CalibratedCamera.from_pinhole(camera)
    return camera


# --- lights and the whole calibration ---------------------------------------------------------


@dataclass(frozen=True)
class LightCalibration:
    """One light's calibration.

    Attributes
    ----------
    direction : (x, y, z), unit vector from the origin toward the light, rig frame
    position : (x, y, z) or None, the light's position for a point light, scene units
    intensity : float or None, relative intensity (the calibrated lights average 1)
    falloff_exponent : float or None, fitted p of irradiance ~ 1 / r^p (2 for a point light)
    """

    direction: Vec3
    position: Vec3 | None = None
    intensity: float | None = None
    falloff_exponent: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data."""
        return {
            "direction": list(self.direction),
            "position": None if self.position is None else list(self.position),
            "intensity": self.intensity,
            "falloff_exponent": self.falloff_exponent,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LightCalibration:
        """Inverse of :meth:`to_dict`."""
        d = _fields(data, "light", ("direction",))
        position = d.get("position")
        intensity = d.get("intensity")
        exponent = d.get("falloff_exponent")
        return cls(
            direction=_vec3(normalize(_floats(d["direction"], "light.direction", 3))),
            position=None if position is None else _vec3(_floats(position, "light.position", 3)),
            intensity=None if intensity is None else float(intensity),
            falloff_exponent=None if exponent is None else float(exponent),
        )


@dataclass(frozen=True)
class Calibration:
    """Everything the calibration captures give; stored in a dataset manifest's ``calibration``.

    Attributes
    ----------
    intrinsics : Intrinsics or None
    cameras : tuple of CameraPose, one per camera pose of the plan, by camera index
    lights : tuple of LightCalibration, one per light pose of the plan, by light index
    """

    intrinsics: Intrinsics | None = None
    cameras: tuple[CameraPose, ...] = ()
    lights: tuple[LightCalibration, ...] = ()

    @classmethod
    def from_arrays(
        cls,
        intrinsics: Intrinsics | None,
        cameras: Sequence[CameraPose],
        directions: ArrayLike | None = None,
        *,
        intensities: ArrayLike | None = None,
        positions: ArrayLike | None = None,
        falloff_exponents: ArrayLike | None = None,
    ) -> Calibration:
        """Assemble from the solvers' outputs: light arrays of shape (T, 3) and (T,).

        Non-finite falloff exponents (directional lights) are stored as None.
        """
        if directions is None:
            return cls(intrinsics, tuple(cameras), ())
        d = normalize(directions).reshape(-1, 3)
        count = len(d)

        def per_light(values: ArrayLike | None, name: str, width: int) -> list[Any]:
            if values is None:
                return [None] * count
            array = np.asarray(values, dtype=np.float64)
            if array.size != count * width:
                raise InputError(f"{name} must hold {width} number(s) per light ({count} lights)")
            return list(array.reshape(count, width) if width > 1 else array.reshape(count))

        lights = []
        for direction, position, intensity, exponent in zip(
            d,
            per_light(positions, "positions", 3),
            per_light(intensities, "intensities", 1),
            per_light(falloff_exponents, "falloff_exponents", 1),
            strict=True,
        ):
            lights.append(
                LightCalibration(
                    direction=_vec3(direction),
                    position=None if position is None else _vec3(position),
                    intensity=None if intensity is None else float(intensity),
                    falloff_exponent=(
                        float(exponent)
                        if exponent is not None and math.isfinite(float(exponent))
                        else None
                    ),
                )
            )
        return cls(intrinsics, tuple(cameras), tuple(lights))

    def camera(self, index: int) -> CalibratedCamera:
        """The calibrated camera of camera pose ``index``."""
        if self.intrinsics is None:
            raise InputError("the calibration has no intrinsics")
        if not 0 <= index < len(self.cameras):
            raise InputError(f"no calibrated camera pose {index} (have {len(self.cameras)})")
        return CalibratedCamera(self.intrinsics, self.cameras[index])

    def light_directions(self) -> F64:
        """Unit directions toward the lights, (T, 3) float64."""
        return np.array([light.direction for light in self.lights], dtype=np.float64).reshape(-1, 3)

    def light_intensities(self) -> F64:
        """Relative light intensities (T,), float64; 1 where a light has none."""
        return np.array(
            [1.0 if light.intensity is None else light.intensity for light in self.lights]
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (the manifest's ``calibration``; ``docs/calibration.md``)."""
        return {
            "schema": CALIBRATION_SCHEMA,
            "intrinsics": None if self.intrinsics is None else self.intrinsics.to_dict(),
            "cameras": [camera.to_dict() for camera in self.cameras],
            "lights": [light.to_dict() for light in self.lights],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Calibration:
        """Inverse of :meth:`to_dict`; ``{}`` (nothing solved yet) gives an empty calibration."""
        if not isinstance(data, Mapping):
            raise DatasetError(f"calibration must be a JSON object, got {type(data).__name__}")
        if not data:
            return cls()
        schema = data.get("schema")
        if schema != CALIBRATION_SCHEMA:
            raise DatasetError(
                f"calibration schema {schema!r} is not supported (this version reads "
                f"{CALIBRATION_SCHEMA})"
            )
        intrinsics = data.get("intrinsics")
        return cls(
            intrinsics=None if intrinsics is None else Intrinsics.from_dict(intrinsics),
            cameras=tuple(CameraPose.from_dict(c) for c in _list(data, "cameras")),
            lights=tuple(LightCalibration.from_dict(x) for x in _list(data, "lights")),
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`to_dict` as JSON (for calibration kept outside a dataset)."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")


# --- validation helpers ------------------------------------------------------------------------


def _fields(data: Any, what: str, required: Sequence[str]) -> Mapping[str, Any]:
    if not isinstance(data, Mapping):
        raise DatasetError(f"calibration {what} must be a JSON object, got {data!r}")
    missing = [name for name in required if name not in data]
    if missing:
        raise DatasetError(f"calibration {what} is missing {', '.join(missing)}")
    return data


def _list(data: Mapping[str, Any], key: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list):
        raise DatasetError(f"calibration {key} must be a list, got {value!r}")
    return value


def _floats(values: Any, what: str, count: int) -> list[float]:
    if not isinstance(values, list | tuple) or len(values) != count:
        raise DatasetError(f"calibration {what} must be {count} numbers, got {values!r}")
    try:
        numbers = [float(v) for v in values]
    except (TypeError, ValueError):
        raise DatasetError(f"calibration {what} must be numbers, got {values!r}") from None
    if not all(math.isfinite(v) for v in numbers):
        raise DatasetError(f"calibration {what} must be finite, got {values!r}")
    return numbers
