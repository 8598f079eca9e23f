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

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.atomic import write_json_atomic
from core.calibrated_camera import (
    CalibratedCamera,
    CameraPose,
    Intrinsics,
    Vec3,
    record_fields,
    record_floats,
    record_list,
    vec3,
)
from core.colour import REC709_WEIGHTS, linear_to_srgb, srgb_to_linear
from core.directions import normalize
from core.errors import DatasetError, InputError
from core.image_io import ImageFileError, read_pixels

__all__ = [
    "CALIBRATION_SCHEMA",
    "Calibration",
    "ImageInput",
    "LightCalibration",
    "gray8",
    "linear_luminance",
    "load_image",
]

CALIBRATION_SCHEMA = 1
F64 = NDArray[np.float64]
#: An image array (H, W) or (H, W, 3), or a path cv2 can read.
ImageInput = NDArray[Any] | str | os.PathLike[str]


# --- images ----------------------------------------------------------------------------------


def load_image(image: ImageInput, name: str) -> NDArray[Any]:
    """An image as an array (RGB channel order); paths are read as stored (:mod:`core.image_io`)."""
    if isinstance(image, str | os.PathLike):
        try:
            return read_pixels(image)
        except ImageFileError as error:
            where = os.fspath(image)
            raise InputError(f"{name}: cannot read image file {where!r}: {error}") from error
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
    r, g, b = REC709_WEIGHTS
    return r * linear[..., 0] + g * linear[..., 1] + b * linear[..., 2]


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
    return np.rint(linear_to_srgb(encoded) * 255.0).astype(np.uint8)


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
        d = record_fields(data, "light", ("direction",))
        position = d.get("position")
        intensity = d.get("intensity")
        exponent = d.get("falloff_exponent")
        return cls(
            direction=vec3(normalize(record_floats(d["direction"], "light.direction", 3))),
            position=None
            if position is None
            else vec3(record_floats(position, "light.position", 3)),
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
                    direction=vec3(direction),
                    position=None if position is None else vec3(position),
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
            cameras=tuple(CameraPose.from_dict(c) for c in record_list(data, "cameras")),
            lights=tuple(LightCalibration.from_dict(x) for x in record_list(data, "lights")),
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`to_dict` as JSON (for calibration kept outside a dataset)."""
        write_json_atomic(path, self.to_dict())  # checked and atomic
