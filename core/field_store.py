"""The reflectance-field store on disk: a Zarr group (schema version 1).

Written by the simulator (``rig sim field``) and by processing (from captures), read by
relighting. It lives in ``rig`` because both writers and the reader may import ``rig`` and
nothing else in common. Layout (S cameras, T lights, P surface samples):

===================== =============== ======================================================
array                 shape, dtype    meaning
===================== =============== ======================================================
``radiance``          (S, T, P, 3)    linear radiance of each sample, camera s, light t of unit
                      float16/32      intensity; one chunk per (s, t): one image is one slab
``visibility``        (S, P) bool     camera s sees sample p (depth test)
``points``            (P, 3) float32  sample positions, rig frame (point samples only)
``normals``           (P, 3) float32  unit normals (point samples; optional for pixels)
``light_directions``  (T, 3) float64  unit vectors toward each light
``camera_directions`` (S, 3) float64  unit vectors toward each camera
===================== =============== ======================================================

Attributes: ``schema_version``, ``samples`` (``{"kind": "points"}``: 3D surface points, novel
views by splatting; or ``{"kind": "pixels", "height": h, "width": w}``: the pixels of one fixed
view in row-major order, P = h w, as RTI data), ``cameras`` (one dict per camera: azimuth_deg,
inclination_deg, distance, fov_deg, width, height), ``light_model`` ("directional" or "point"
with its distance), ``provenance`` (free-form dict: scene, tool, creation time...).
"""

from __future__ import annotations

import os
from dataclasses import asdict
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import DatasetError, InputError

__all__ = ["FIELD_SCHEMA_VERSION", "FieldStoreWriter"]

FIELD_SCHEMA_VERSION = 1


class FieldStoreWriter:
    """Create a field store and fill it slab by slab (a crash leaves written slabs intact)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        points: NDArray[np.floating] | None,
        normals: NDArray[np.floating] | None,
        light_directions: NDArray[np.floating],
        cameras: list[PinholeCamera],
        image_shape: tuple[int, int] | None = None,
        dtype: str = "float32",
        light_model: dict[str, Any] | None = None,
        provenance: dict[str, Any] | None = None,
    ) -> None:
        if dtype not in ("float16", "float32"):
            raise InputError(f"field dtype must be float16 or float32, got {dtype!r}")
        if image_shape is None:
            if points is None or normals is None:
                raise InputError("a field of surface points needs their points and normals")
            p = len(points)
            samples: dict[str, Any] = {"kind": "points"}
        else:
            p = image_shape[0] * image_shape[1]
            samples = {"kind": "pixels", "height": image_shape[0], "width": image_shape[1]}
            if len(cameras) != 1:
                raise InputError(f"a field of pixels has exactly one camera, got {len(cameras)}")
        t, s = len(light_directions), len(cameras)
        if min(p, t, s) < 1:
            raise InputError(f"a field needs samples, lights and cameras, got P={p} T={t} S={s}")
        for name, values in (("points", points), ("normals", normals)):
            if values is not None and np.shape(values) != (p, 3):
                raise InputError(f"field {name} must have shape ({p}, 3), got {np.shape(values)}")
        try:
            self.group = zarr.open_group(str(path), mode="w")
        except Exception as error:  # zarr raises several types for unwritable paths
            raise DatasetError(f"{path}: cannot create the field store: {error}") from error
        self.radiance = self.group.create_array(
            "radiance", shape=(s, t, p, 3), chunks=(1, 1, p, 3), dtype=dtype, fill_value=0.0
        )
        self.visibility = self.group.create_array(
            "visibility", shape=(s, p), chunks=(1, p), dtype="bool", fill_value=False
        )
        constants: dict[str, NDArray[Any]] = {
            "light_directions": np.asarray(light_directions, dtype=np.float64),
            "camera_directions": np.array([c.direction for c in cameras], dtype=np.float64),
        }
        if points is not None:
            constants["points"] = np.asarray(points, dtype=np.float32)
        if normals is not None:
            constants["normals"] = np.asarray(normals, dtype=np.float32)
        for name, values in constants.items():
            self.group.create_array(name, shape=values.shape, dtype=values.dtype)[...] = values
        self.group.attrs.update(
            {
                "schema_version": FIELD_SCHEMA_VERSION,
                "samples": samples,
                "cameras": [asdict(c) for c in cameras],
                "light_model": light_model or {"type": "directional", "irradiance": 1.0},
                "provenance": provenance or {},
            }
        )

    def write_slab(self, camera: int, light: int, radiance: NDArray[np.floating]) -> None:
        """Store the radiance (P, 3) of every sample for one camera and one light."""
        self.radiance[camera, light] = np.asarray(radiance, dtype=self.radiance.dtype)

    def write_visibility(self, camera: int, visible: NDArray[np.bool_]) -> None:
        """Store which samples (P,) camera ``camera`` sees."""
        self.visibility[camera] = np.asarray(visible, dtype=bool)
