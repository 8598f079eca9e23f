"""A calibrated camera: intrinsics with distortion, a pose, rays and projection (OpenCV).

The ideal :class:`core.camera_model.PinholeCamera` of the rig's kinematics becomes, once
calibrated (:mod:`processing.charuco`), an :class:`Intrinsics` (focal lengths, principal point,
OpenCV's ``(k1, k2, p1, p2, k3)`` distortion) and a :class:`CameraPose` in the rig frame;
:class:`CalibratedCamera` casts rays through pixels and projects points with them. Pixel
coordinates follow :mod:`core.camera_model` (pixel (row i, col j) centred at (j + 0.5, i + 0.5));
OpenCV puts pixel centres at integers, and the half-pixel conversion happens only here
(:meth:`Intrinsics.camera_matrix`). The plain-JSON forms are what a dataset's manifest stores
(``docs/calibration.md``); the ``record_*`` helpers validate them with messages that name the
field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.camera_model import PinholeCamera
from core.directions import angles_deg_from_direction, normalize
from core.errors import DatasetError

__all__ = [
    "CalibratedCamera",
    "CameraPose",
    "Intrinsics",
    "Mat3",
    "PoseDisagreement",
    "Vec3",
    "as_calibrated",
    "mat3",
    "record_fields",
    "record_floats",
    "record_list",
    "vec3",
]

F64 = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


def vec3(values: ArrayLike) -> Vec3:
    """Three floats of an array-like of 3 numbers."""
    v = np.asarray(values, dtype=np.float64).reshape(3)
    return (float(v[0]), float(v[1]), float(v[2]))


def mat3(values: ArrayLike) -> Mat3:
    """A 3 x 3 tuple of floats of an array-like of 9 numbers."""
    m = np.asarray(values, dtype=np.float64).reshape(3, 3)
    return (vec3(m[0]), vec3(m[1]), vec3(m[2]))


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
        d = record_fields(
            data, "intrinsics", ("width", "height", "fx", "fy", "cx", "cy", "distortion")
        )
        distortion = record_floats(d["distortion"], "intrinsics.distortion", 5)
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
        d = record_fields(data, "disagreement", names)
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
        return cls(position=vec3(camera.position), axes=mat3(camera.axes()))

    @classmethod
    def from_opencv(cls, rotation: ArrayLike, translation: ArrayLike) -> CameraPose:
        """From OpenCV's world-to-camera ``R`` (3, 3) and ``t`` (3,), world = rig frame."""
        r = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        axes = np.stack([r[0], -r[1], r[2]])  # OpenCV's y points down the image
        return cls(position=vec3(-r.T @ t), axes=mat3(axes))

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
        d = record_fields(data, "camera", ("position", "axes"))
        axes = np.asarray([record_floats(row, "camera.axes", 3) for row in d["axes"]])
        if axes.shape != (3, 3) or not np.allclose(axes @ axes.T, np.eye(3), atol=1e-6):
            raise DatasetError(f"calibration camera.axes must be 3 orthonormal rows: {d['axes']}")
        disagreement = d.get("disagreement")
        return cls(
            position=vec3(record_floats(d["position"], "camera.position", 3)),
            axes=mat3(axes),
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


def record_fields(data: Any, what: str, required: Sequence[str]) -> Mapping[str, Any]:
    """``data`` as a mapping with the ``required`` keys; DatasetError naming ``what`` if not."""
    if not isinstance(data, Mapping):
        raise DatasetError(f"calibration {what} must be a JSON object, got {data!r}")
    missing = [name for name in required if name not in data]
    if missing:
        raise DatasetError(f"calibration {what} is missing {', '.join(missing)}")
    return data


def record_list(data: Mapping[str, Any], key: str) -> list[Any]:
    """The list under ``key`` (empty if absent); DatasetError if it is not a list."""
    value = data.get(key, [])
    if not isinstance(value, list):
        raise DatasetError(f"calibration {key} must be a list, got {value!r}")
    return value


def record_floats(values: Any, what: str, count: int) -> list[float]:
    """``count`` finite numbers; DatasetError naming ``what`` otherwise."""
    if not isinstance(values, list | tuple) or len(values) != count:
        raise DatasetError(f"calibration {what} must be {count} numbers, got {values!r}")
    try:
        numbers = [float(v) for v in values]
    except (TypeError, ValueError):
        raise DatasetError(f"calibration {what} must be numbers, got {values!r}") from None
    if not all(math.isfinite(v) for v in numbers):
        raise DatasetError(f"calibration {what} must be finite, got {values!r}")
    return numbers
