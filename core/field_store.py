"""The reflectance-field store on disk: a Zarr group (schema version 1).

Written by the simulator (``rig sim field``) and by processing (from captures) through
:class:`FieldStoreWriter` (:mod:`core.store.writer`), read by everything downstream through
:class:`ReflectanceField` (here); the names and numbers both follow are :mod:`core.store.schema`
(both re-exported here). Layout (S cameras, T lights, P surface samples):

===================== =============== ======================================================
array                 shape, dtype    meaning
===================== =============== ======================================================
``radiance``          (S, T, P, 3)    linear radiance of each sample, camera s, light t of unit
                      float16/32      intensity; chunks of (1, 1, SAMPLE_CHUNK, 3): one image
                                      is one slab of a few chunks, a block of samples under
                                      every camera and light is one chunk per (s, t)
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
with its distance; ``below_horizon``: what the capture states of the environment below the
rig's horizon, see :data:`BELOW_HORIZON`), ``provenance`` (free-form dict: scene, tool,
creation time...), ``radiance_digest``, ``dark_cameras`` and ``digests``, which bind every
array and attribute to what was written: opening compares all but the radiance's values (read
on demand; ``rig verify`` checks them) with them (:mod:`core.store.digests`,
``docs/field-store.md``).
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import DatasetError, InputError
from core.store.attributes import check_directions, read_attributes
from core.store.digests import require_bound
from core.store.integrity import array_names, non_finite, open_arrays, read_checked
from core.store.schema import (
    BELOW_HORIZON,
    FIELD_SCHEMA_VERSION,
    SAMPLE_CHUNK,
    BelowHorizon,
    companion_paths,
    is_field_store,
)
from core.store.writer import FieldStoreWriter, SlabWriter

__all__ = [
    "BELOW_HORIZON",
    "CACHED_SLABS",
    "FIELD_SCHEMA_VERSION",
    "SAMPLE_CHUNK",
    "BelowHorizon",
    "FieldStoreWriter",
    "ReflectanceField",
    "SlabWriter",
    "companion_paths",
    "is_field_store",
]


# --- reading ------------------------------------------------------------------------------------
# Opening reads only the small arrays (directions, visibility, points, normals) and the
# attributes; radiance is read one camera's slab (T, P, 3) at a time, when relighting needs it,
# and the most recently used slabs stay in memory.

#: Camera slabs kept in memory by default (a 250k-point, T = 30 slab is 90 MB in float32)...
CACHED_SLABS = 8
#: ...and at most this many bytes of them, whatever the field's size (a 2M-point slab is
#: 720 MB: two stay, not eight).
CACHED_SLAB_BYTES = 2 << 30
#: Stored radiance :meth:`ReflectanceField.tiles` reads at once (a band of image rows).
TILE_READ_BYTES = 64 << 20


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
    radiance_digest : str or None, the SHA-256 the writer recorded over the radiance (None for
        stores written before it was recorded, and for in-memory subsets)
    dark_cameras : tuple of int or None, the cameras the writer found to record no light
        (None when not recorded: older stores, in-memory subsets)
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
    radiance_digest: str | None = None
    dark_cameras: tuple[int, ...] | None = None
    cached_slabs: int = CACHED_SLABS
    _slabs: OrderedDict[int, NDArray[np.float32]] = field(default_factory=OrderedDict, repr=False)

    @classmethod
    def open(
        cls, path: str | os.PathLike[str], cached_slabs: int = CACHED_SLABS
    ) -> ReflectanceField:
        """Open the store at ``path``; DatasetError names what is missing, altered or wrong."""
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
        names = set(array_names(where))
        for required in ("radiance", "visibility", "light_directions", "camera_directions"):
            if required not in names:
                raise DatasetError(f"{where}: the field store has no {required!r} array")
        arrays = open_arrays(where, group, names)
        radiance = arrays["radiance"]
        if len(radiance.shape) != 4 or radiance.shape[3] != 3:
            raise DatasetError(f"{where}: radiance must be (S, T, P, 3), got {radiance.shape}")
        s, t, p, _ = radiance.shape
        checked = read_attributes(where, attrs, (s, t, p))
        image_shape = checked.image_shape

        def read(name: str, shape: tuple[int, ...]) -> NDArray[Any] | None:
            if name not in names:
                return None
            values = read_checked(where, arrays[name])
            if values.shape != shape:
                raise DatasetError(f"{where}: {name} has shape {values.shape}, expected {shape}")
            return values

        light_directions = read("light_directions", (t, 3))
        camera_directions = read("camera_directions", (s, 3))
        visibility = read("visibility", (s, p))
        points, normals = read("points", (p, 3)), read("normals", (p, 3))
        if image_shape is None and (points is None or normals is None):
            raise DatasetError(f"{where}: a field of surface points needs points and normals")
        assert light_directions is not None and camera_directions is not None
        assert visibility is not None
        check_directions(where, "light direction", light_directions)
        check_directions(where, "camera direction", camera_directions)
        for name, values in (("points", points), ("normals", normals)):
            if values is not None and not np.isfinite(values).all():
                row = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
                raise DatasetError(
                    f"{where}: {name} {row} is {values[row].tolist()}, not finite: rebuild the "
                    "store from its source"
                )
        read_values = {"light_directions": light_directions, "points": points, "normals": normals,
                       "camera_directions": camera_directions, "visibility": visibility}
        require_bound(where, attrs, names, read_values)
        return cls(
            path=where,
            light_directions=light_directions.astype(np.float64),
            camera_directions=camera_directions.astype(np.float64),
            cameras=checked.cameras,
            visibility=visibility.astype(bool),
            points=None if points is None else points.astype(np.float32),
            normals=None if normals is None else normals.astype(np.float32),
            image_shape=image_shape,
            light_model=checked.light_model,
            provenance=checked.provenance,
            radiance=radiance,
            radiance_digest=checked.radiance_digest,
            dark_cameras=checked.dark_cameras,
            cached_slabs=cached_slabs,
        )

    def __getstate__(self) -> dict[str, Any]:
        # Pickled into a Dask task: the store is reopened by its path there, the slab cache
        # stays behind (a subset's radiance, in memory, goes along).
        state = dict(self.__dict__)
        state["_slabs"] = OrderedDict()
        return state

    @property
    def below_horizon(self) -> BelowHorizon:
        """What the capture states lies below the horizon (:data:`BELOW_HORIZON`)."""
        value = self.light_model.get("below_horizon", "open")
        if value not in BELOW_HORIZON:
            raise DatasetError(
                f"{self.path}: light_model below_horizon is {value!r}; the store must state "
                f"one of {', '.join(BELOW_HORIZON)}"
            )
        return value

    def stating(self, *, below_horizon: BelowHorizon) -> ReflectanceField:
        """The same field (same store, same data) with another statement of what lies below."""
        if below_horizon not in BELOW_HORIZON:
            raise InputError(
                f"below the horizon must be one of {', '.join(BELOW_HORIZON)}, got "
                f"{below_horizon!r}"
            )
        return replace(self, light_model=self.light_model | {"below_horizon": below_horizon})

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
        work in float32) and kept among the ``cached_slabs`` most recent, within
        :data:`CACHED_SLAB_BYTES` (the newest is always kept).
        """
        s = self.shape[0]
        if not 0 <= camera < s:
            raise InputError(f"camera index {camera} outside 0..{s - 1} of {self.path}")
        slab = self._slabs.pop(camera, None)
        if slab is None:
            slab = self.camera_radiance(camera).astype(np.float32)
        self._slabs[camera] = slab
        room = max(1, min(self.cached_slabs, CACHED_SLAB_BYTES // max(slab.nbytes, 1)))
        while len(self._slabs) > room:
            self._slabs.popitem(last=False)
        return slab

    def camera_radiance(self, camera: int, samples: slice = slice(None)) -> NDArray[np.floating]:
        """Radiance (T, P', 3) of ``samples`` seen by ``camera``, in the storage dtype, uncached.

        Read through :mod:`core.store.integrity`: a chunk that does not decode, and NaN or
        infinity, are errors naming the store, camera, light and sample.
        """
        values = read_checked(self.path, self.radiance, (camera, slice(None), samples))
        offset = samples.indices(self.shape[2])[0]
        found = non_finite(values)
        if found is not None:
            light, sample = found[1][0], found[1][1] + offset
            raise DatasetError(
                f"{self.path}: {found[0]} non-finite radiance values (NaN or infinity) seen by "
                f"camera {camera}, the first at light {light}, sample {sample}: radiance "
                "cannot be NaN; rebuild the store from its source"
            )
        return values

    def light_radiance(
        self, camera: int, light: int, *, widen: bool = True
    ) -> NDArray[np.floating]:
        """Radiance (P, 3) of every sample under one light seen by ``camera``.

        One captured image of a field of pixels: a read of that light's chunks only, uncached,
        checked for NaN and infinity. ``widen``: float32 (default), else the storage dtype
        (a float16 store's widening costs more than its read: a caller that keeps part of the
        image widens only that).
        """
        s, t, _ = self.shape
        if not (0 <= camera < s and 0 <= light < t):
            raise InputError(f"camera {camera}, light {light} outside the {s} x {t} of {self.path}")
        values = read_checked(self.path, self.radiance, (camera, light))
        if not _all_finite(values):
            raise DatasetError(
                f"{self.path}: non-finite radiance (NaN or infinity) seen by camera {camera} "
                f"under light {light}: rebuild the store from its source"
            )
        return np.asarray(values, dtype=np.float32) if widen else values

    @property
    def sample_chunk(self) -> int:
        """Samples per stored radiance chunk (P for stores of one chunk per slab)."""
        return int(self.radiance.chunks[2]) if hasattr(self.radiance, "chunks") else self.shape[2]

    def sample_block(self, start: int, stop: int) -> NDArray[np.float32]:
        """Radiance (stop - start, S, T, 3), float32, of samples start..stop.

        One sample's values together, as fitting and evaluation read them: a read of one chunk
        per (camera, light) when the block is aligned to :attr:`sample_chunk`. Damage is named
        as by :meth:`camera_radiance`.
        """
        block = (slice(None), slice(None), slice(start, stop))
        values = read_checked(self.path, self.radiance, block)
        found = non_finite(values)
        if found is not None:
            camera, light, sample = found[1][0], found[1][1], found[1][2] + start
            raise DatasetError(
                f"{self.path}: {found[0]} non-finite radiance values (NaN or infinity) in "
                f"samples {start}..{stop - 1}, the first seen by camera {camera} at light "
                f"{light}, sample {sample}: radiance cannot be NaN; rebuild the store from its "
                "source"
            )
        return np.ascontiguousarray(values.transpose(2, 0, 1, 3), dtype=np.float32)

    def load(self) -> NDArray[np.floating]:
        """The whole radiance array (S, T, P, 3) in memory, in its storage dtype."""
        return np.stack([self.camera_radiance(s) for s in range(self.shape[0])])

    def tiles(
        self, origins: Sequence[tuple[int, int]], side: int, columns: int
    ) -> ReflectanceField:
        """Square windows of a pixel field's view side by side in one image, held in memory.

        What a view too large to score whole is scored on (:mod:`render.evaluation`): each
        window's pixels keep their neighbours, so image metrics (SSIM) see the same
        neighbourhoods as in the whole view. Read band by band of image rows (at most
        :data:`TILE_READ_BYTES` of stored radiance at once), so a 24-megapixel view is never
        read whole.

        Parameters
        ----------
        origins : sequence of (row, column), the top-left pixel of each window in the view;
            every window lies inside the view
        side : int, the windows' side in pixels
        columns : int, windows per row of the mosaic; window i is at mosaic row i // columns,
            column i % columns (cells left over at the end are black and not visible)

        Returns
        -------
        ReflectanceField
            Every light, radiance (1, T, P', 3) float32 of the mosaic (``rows side`` x
            ``columns side`` pixels, row-major), its visibility, the camera with the mosaic's
            size; ``provenance["tiles_of"]`` names the store and the windows.

        Raises
        ------
        InputError
            A field of points, no windows, a window outside the view, a side or column count
            below 1.
        """
        if self.image_shape is None:
            raise InputError(f"{self.path}: windows of a view need a field of pixels")
        height, width = self.image_shape
        if not origins or side < 1 or columns < 1:
            raise InputError(f"{self.path}: windows need origins, a side and columns >= 1")
        for row, column in origins:
            if not (0 <= row <= height - side and 0 <= column <= width - side):
                raise InputError(
                    f"{self.path}: a {side} x {side} window at row {row}, column {column} is "
                    f"not inside the {width} x {height} view"
                )
        _, t_count, _ = self.shape
        rows = -(-len(origins) // columns)
        mosaic = np.zeros((t_count, rows * side, columns * side, 3), dtype=np.float32)
        seen = np.zeros((rows * side, columns * side), dtype=bool)
        visible = self.visibility[0].reshape(height, width)
        step = max(1, TILE_READ_BYTES // (t_count * width * 3 * self.dtype.itemsize))
        for top in range(0, height, step):
            bottom = min(top + step, height)
            covering = [(i, r, c) for i, (r, c) in enumerate(origins)
                        if r < bottom and r + side > top]  # fmt: skip
            if not covering:
                continue
            band = self.camera_radiance(0, slice(top * width, bottom * width))
            band = band.reshape(t_count, bottom - top, width, 3)
            for index, row, column in covering:
                first, last = max(row, top), min(row + side, bottom)
                y = index // columns * side + first - row
                x = index % columns * side
                mosaic[:, y : y + last - first, x : x + side] = band[
                    :, first - top : last - top, column : column + side
                ]
                seen[y : y + last - first, x : x + side] = visible[
                    first:last, column : column + side
                ]
        camera = replace(self.cameras[0], width=columns * side, height=rows * side)
        return ReflectanceField(
            # A path of its own: nothing beside the store (a saved model fit) belongs to it.
            path=self.path.with_name(self.path.name + "[tiles]"),
            light_directions=self.light_directions,
            camera_directions=self.camera_directions,
            cameras=[camera],
            visibility=seen.reshape(1, -1),
            points=None,
            normals=None if self.normals is None else self._tiled_normals(origins, side, columns),
            image_shape=(rows * side, columns * side),
            light_model=self.light_model,
            provenance=self.provenance | {"tiles_of": {
                "store": str(self.path), "side": side, "columns": columns,
                "origins": [[int(r), int(c)] for r, c in origins],
            }},
            radiance=mosaic.reshape(1, t_count, -1, 3),
            cached_slabs=1,
        )  # fmt: skip

    def _tiled_normals(
        self, origins: Sequence[tuple[int, int]], side: int, columns: int
    ) -> NDArray[np.float32]:
        """The stored normals (P, 3) of :meth:`tiles`'s windows, laid out as its mosaic."""
        assert self.normals is not None and self.image_shape is not None
        height, width = self.image_shape
        rows = -(-len(origins) // columns)
        out = np.zeros((rows * side, columns * side, 3), dtype=np.float32)
        grid = self.normals.reshape(height, width, 3)
        for index, (row, column) in enumerate(origins):
            y, x = index // columns * side, index % columns * side
            out[y : y + side, x : x + side] = grid[row : row + side, column : column + side]
        return out.reshape(-1, 3)

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
        # (S', T', P', 3) in memory: subsets are small by purpose. Read block by block of the
        # store's chunks, so a few samples of a large field never bring whole slabs in.
        radiance = np.empty((len(keep_s), len(keep_t), len(keep_p), 3), dtype=np.float32)
        step = self.sample_chunk
        for start in range(0, p_count, step):
            inside = (keep_p >= start) & (keep_p < start + step)
            if not inside.any():
                continue
            stop = int(keep_p[inside].max()) + 1
            for row, s in enumerate(keep_s):
                block = self.camera_radiance(int(s), slice(start, stop))
                radiance[row][:, inside] = block[keep_t][:, keep_p[inside] - start]
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


def _all_finite(values: NDArray[np.floating]) -> bool:
    """Whether no value is NaN or infinite (float16 by its exponent bits: numpy's test is slow)."""
    flat = values.reshape(-1)
    step = 1 << 20  # blocks that stay in cache: a whole image's temporaries cost seconds
    for start in range(0, len(flat), step):
        block = flat[start : start + step]
        if block.dtype == np.float16:
            if np.any((block.view(np.uint16) & 0x7C00) == 0x7C00):
                return False
        elif not np.isfinite(block).all():
            return False
    return True
