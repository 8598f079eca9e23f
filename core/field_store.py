"""The reflectance-field store on disk: a Zarr group (schema version 1).

Written by the simulator (``rig sim field``) and by processing (from captures) through
:class:`FieldStoreWriter`, read by everything downstream through :class:`ReflectanceField`:
schema, writer and reader live together so they cannot drift apart. Layout (S cameras, T
lights, P surface samples):

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
from collections import OrderedDict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import DatasetError, InputError

__all__ = ["CACHED_SLABS", "FIELD_SCHEMA_VERSION", "FieldStoreWriter", "ReflectanceField"]

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


# --- reading ------------------------------------------------------------------------------------
# Opening reads only the small arrays (directions, visibility, points, normals) and the
# attributes; radiance is read one camera's slab (T, P, 3) at a time, when relighting needs it,
# and the most recently used slabs stay in memory.

#: Camera slabs kept in memory by default (a 250k-point, T = 30 slab is 90 MB in float32).
CACHED_SLABS = 8


@dataclass(eq=False)
class ReflectanceField:
    """A measured or simulated reflectance field, opened from its store.

    Attributes
    ----------
    path : Path of the store
    light_directions : ndarray, shape (T, 3), float64, unit vectors toward the lights
    camera_directions : ndarray, shape (S, 3), float64, unit vectors toward the cameras
    cameras : list of PinholeCamera, length S
    visibility : ndarray, shape (S, P), bool, camera s sees sample p
    points, normals : ndarray, shape (P, 3), float32, or None (pixel fields may have neither)
    image_shape : (height, width) for a field of the pixels of one view, None for points
    light_model, provenance : dict, the store's attributes
    """

    path: Path
    light_directions: NDArray[np.float64]
    camera_directions: NDArray[np.float64]
    cameras: list[PinholeCamera]
    visibility: NDArray[np.bool_]
    points: NDArray[np.float32] | None
    normals: NDArray[np.float32] | None
    image_shape: tuple[int, int] | None
    light_model: dict[str, Any]
    provenance: dict[str, Any]
    radiance: Any = field(repr=False)  # the zarr array (S, T, P, 3), read on demand
    cached_slabs: int = CACHED_SLABS
    _slabs: OrderedDict[int, NDArray[np.float32]] = field(default_factory=OrderedDict, repr=False)

    @classmethod
    def open(
        cls, path: str | os.PathLike[str], cached_slabs: int = CACHED_SLABS
    ) -> ReflectanceField:
        """Open the store at ``path``; DatasetError names what is missing or inconsistent."""
        where = Path(path)
        if not where.exists():
            raise DatasetError(f"{where}: no such field store")
        try:
            group: Any = zarr.open_group(str(where), mode="r")
        except Exception as error:  # zarr raises several types for non-stores
            raise DatasetError(f"{where}: not a field store ({error})") from error
        attrs: dict[str, Any] = dict(group.attrs)
        version = attrs.get("schema_version")
        if version != FIELD_SCHEMA_VERSION:
            raise DatasetError(
                f"{where}: field schema version {version!r}, this tool reads "
                f"{FIELD_SCHEMA_VERSION}; rebuild the field with this version"
            )
        names = set(group.array_keys())
        for required in ("radiance", "visibility", "light_directions", "camera_directions"):
            if required not in names:
                raise DatasetError(f"{where}: the field store has no {required!r} array")
        radiance = group["radiance"]
        if len(radiance.shape) != 4 or radiance.shape[3] != 3:
            raise DatasetError(f"{where}: radiance must be (S, T, P, 3), got {radiance.shape}")
        s, t, p, _ = radiance.shape
        samples = attrs.get("samples", {"kind": "points"})
        image_shape = None
        if samples.get("kind") == "pixels":
            image_shape = (int(samples["height"]), int(samples["width"]))
        elif samples.get("kind") != "points":
            raise DatasetError(f"{where}: unknown sample kind {samples.get('kind')!r}")

        def read(name: str, shape: tuple[int, ...]) -> NDArray[Any] | None:
            if name not in names:
                return None
            values = np.asarray(group[name][...])
            if values.shape != shape:
                raise DatasetError(f"{where}: {name} has shape {values.shape}, expected {shape}")
            return values

        light_directions = read("light_directions", (t, 3))
        camera_directions = read("camera_directions", (s, 3))
        visibility = read("visibility", (s, p))
        points, normals = read("points", (p, 3)), read("normals", (p, 3))
        if image_shape is None and (points is None or normals is None):
            raise DatasetError(f"{where}: a field of surface points needs points and normals")
        if image_shape is not None and image_shape[0] * image_shape[1] != p:
            raise DatasetError(f"{where}: {image_shape} pixels do not match P = {p}")
        try:
            cameras = [PinholeCamera(**c) for c in attrs["cameras"]]
        except (KeyError, TypeError, InputError) as error:
            raise DatasetError(f"{where}: bad camera records: {error}") from error
        if len(cameras) != s:
            raise DatasetError(f"{where}: {len(cameras)} camera records for S = {s}")
        assert light_directions is not None and camera_directions is not None
        assert visibility is not None
        return cls(
            path=where,
            light_directions=light_directions.astype(np.float64),
            camera_directions=camera_directions.astype(np.float64),
            cameras=cameras,
            visibility=visibility.astype(bool),
            points=None if points is None else points.astype(np.float32),
            normals=None if normals is None else normals.astype(np.float32),
            image_shape=image_shape,
            light_model=dict(attrs.get("light_model", {})),
            provenance=dict(attrs.get("provenance", {})),
            radiance=radiance,
            cached_slabs=cached_slabs,
        )

    @property
    def shape(self) -> tuple[int, int, int]:
        """(S, T, P): cameras, lights, samples."""
        s, t, p, _ = self.radiance.shape
        return int(s), int(t), int(p)

    @property
    def dtype(self) -> np.dtype[Any]:
        """Storage dtype of the radiance (float16 or float32)."""
        return np.dtype(self.radiance.dtype)

    @property
    def sample_kind(self) -> str:
        """Kind of sample: ``"points"`` (3D surface samples) or ``"pixels"`` (one fixed view)."""
        return "points" if self.image_shape is None else "pixels"

    def camera_slab(self, camera: int) -> NDArray[np.float32]:
        """Radiance (T, P, 3), float32, of every sample under every light, seen by ``camera``.

        Read from the store on first use (float16 stores are widened: the relighting kernels
        work in float32) and kept among the ``cached_slabs`` most recent.
        """
        s = self.shape[0]
        if not 0 <= camera < s:
            raise InputError(f"camera index {camera} outside 0..{s - 1} of {self.path}")
        slab = self._slabs.pop(camera, None)
        if slab is None:
            slab = np.asarray(self.radiance[camera], dtype=np.float32)
        self._slabs[camera] = slab
        while len(self._slabs) > max(self.cached_slabs, 1):
            self._slabs.popitem(last=False)
        return slab

    def load(self) -> NDArray[np.floating]:
        """The whole radiance array (S, T, P, 3) in memory, in its storage dtype."""
        return np.asarray(self.radiance[...])

    def subset(
        self,
        *,
        cameras: NDArray[np.integer] | None = None,
        lights: NDArray[np.integer] | None = None,
        samples: NDArray[np.integer] | None = None,
    ) -> ReflectanceField:
        """A part of the field, held in memory: the chosen cameras, lights and samples.

        Hold-out tests (:mod:`render.advisor`) fit and relight such parts the way they would
        the whole field. Pixel fields keep all their pixels (their image shape).

        Parameters
        ----------
        cameras, lights, samples : ndarray of int, optional; indices to keep (default all)
        """
        s_count, t_count, p_count = self.shape
        keep_s = np.arange(s_count) if cameras is None else np.asarray(cameras, dtype=np.int64)
        keep_t = np.arange(t_count) if lights is None else np.asarray(lights, dtype=np.int64)
        keep_p = np.arange(p_count) if samples is None else np.asarray(samples, dtype=np.int64)
        for name, index, count in (("camera", keep_s, s_count), ("light", keep_t, t_count),
                                   ("sample", keep_p, p_count)):  # fmt: skip
            if index.size == 0 or index.min() < 0 or index.max() >= count:
                raise InputError(f"{self.path}: {name} indices must be in 0..{count - 1}")
        if self.image_shape is not None and samples is not None:
            raise InputError(f"{self.path}: a pixel field keeps all its pixels")
        radiance = np.stack(
            [self.camera_slab(int(s))[keep_t][:, keep_p] for s in keep_s]
        )  # (S', T', P', 3) in memory: subsets are small by purpose
        return ReflectanceField(
            # A path of its own: nothing beside the store (a saved model fit) belongs to it.
            path=self.path.with_name(self.path.name + "[subset]"),
            light_directions=self.light_directions[keep_t],
            camera_directions=self.camera_directions[keep_s],
            cameras=[self.cameras[int(s)] for s in keep_s],
            visibility=self.visibility[keep_s][:, keep_p],
            points=None if self.points is None else self.points[keep_p],
            normals=None if self.normals is None else self.normals[keep_p],
            image_shape=self.image_shape,
            light_model=self.light_model,
            provenance=self.provenance | {"subset_of": str(self.path)},
            radiance=radiance,
            cached_slabs=len(keep_s),
        )
