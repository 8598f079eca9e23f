"""The object's surface samples for field building: points, normals and their spacing.

Read from a scan (``.ply`` or ``.npz``) or given as arrays; the spacing sizes the splats of the
depth test (:func:`core.splat.camera_splats`) and defaults to
:func:`core.point_spacing.point_spacing`.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.directions import normalize
from core.errors import DatasetError, InputError
from core.file_kinds import special_file_problem
from core.point_spacing import point_spacing

__all__ = ["PointCloud", "read_point_cloud"]


@dataclass(frozen=True)
class PointCloud:
    """The object's surface samples.

    Attributes
    ----------
    points, normals : ndarray, shape (P, 3), float32 (normals unit, outward), rig frame
    spacing : float, sqrt(surface area / P), scene units (sizes the splats of the depth test)
    """

    points: NDArray[np.float32]
    normals: NDArray[np.float32]
    spacing: float

    @classmethod
    def from_arrays(
        cls, points: ArrayLike, normals: ArrayLike, spacing: float | None = None
    ) -> PointCloud:
        """Check and wrap arrays; ``spacing`` defaults to :func:`core.point_spacing.point_spacing`.

        Pass the spacing when it is known (the scanner's, or the simulator's).
        """
        p = np.asarray(points, dtype=np.float32)
        n = np.asarray(normals, dtype=np.float32)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2 or n.shape != p.shape:
            raise InputError(
                f"points and normals must both be (P, 3) with P >= 2, got {p.shape}, {n.shape}"
            )
        if not (np.isfinite(p).all() and np.isfinite(n).all()):
            raise InputError("points and normals must be finite")
        n = normalize(n).astype(np.float32)
        if spacing is None:
            spacing = point_spacing(p)
        if not (np.isfinite(spacing) and spacing > 0):
            raise InputError(f"point spacing must be positive, got {spacing}")
        return cls(p, n, float(spacing))


def read_point_cloud(path: str | os.PathLike[str]) -> PointCloud:
    """Read the object's points and normals from ``.npz`` or ``.ply``.

    ``.npz``: arrays ``points`` and ``normals`` (P, 3), optional scalar ``spacing``. ``.ply``:
    the ``vertex`` element (the first) with float properties x, y, z, nx, ny, nz, in ASCII or
    binary little/big-endian encoding; spacing is estimated (:meth:`PointCloud.from_arrays`).

    Raises
    ------
    DatasetError
        Unreadable, truncated or missing the needed arrays or properties; names the file.
    """
    file = Path(path)
    problem = special_file_problem(file)  # a FIFO would block the read forever
    if problem is not None:
        raise DatasetError(problem)
    if not file.is_file():
        raise DatasetError(f"{file}: no such point cloud file")
    suffix = file.suffix.lower()
    try:
        if suffix == ".npz":
            # Our handle, closed whatever np.load raises (it leaks its own on a bad zip).
            with open(file, "rb") as handle, np.load(handle, allow_pickle=False) as data:
                spacing = float(data["spacing"]) if "spacing" in data else None
                return PointCloud.from_arrays(data["points"], data["normals"], spacing)
        if suffix == ".ply":
            columns = _read_ply_vertices(file)
            missing = [c for c in ("x", "y", "z", "nx", "ny", "nz") if c not in columns]
            if missing:
                raise DatasetError(f"{file}: PLY vertices lack {', '.join(missing)}")
            points = np.stack([columns[c] for c in "xyz"], axis=1)
            normals = np.stack([columns[c] for c in ("nx", "ny", "nz")], axis=1)
            return PointCloud.from_arrays(points, normals)
    except (KeyError, ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as error:
        raise DatasetError(f"{file}: cannot read the point cloud: {error}") from error
    except (TypeError, AttributeError) as error:  # a bare .npy array saved as .npz
        raise DatasetError(f"{file}: not an .npz archive of points and normals") from error
    raise DatasetError(f"{file}: point clouds are read from .npz or .ply, not {suffix!r}")


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def _check_vertex_count(
    file: Path, encoding: str, count: int, properties: int, left: int, *, record: int
) -> None:
    """Refuse a vertex count the bytes after the header cannot hold, before reading any.

    A header claiming 99,999,999,999 vertices over one line of data looped over the claim
    (ASCII) or asked for terabytes (binary). An ASCII vertex takes at least two bytes per
    property (a digit and a space or newline), a binary one its record's size.
    """
    if properties == 0:
        raise DatasetError(f"{file}: the PLY vertex element has no properties")
    if count < 0:
        raise DatasetError(f"{file}: the PLY header claims {count} vertices")
    # The last ASCII vertex may end without its newline.
    least, slack = (2 * properties, 1) if encoding == "ascii" else (record, 0)
    if count * least - slack > left:
        raise DatasetError(
            f"{file}: PLY vertex data is truncated: the header claims {count} vertices, the "
            f"{left} bytes after it hold at most {(left + slack) // least} (or the header is "
            "wrong)"
        )


def _read_ply_vertices(file: Path) -> dict[str, NDArray[np.float64]]:
    with open(file, "rb") as handle:
        if handle.readline().strip() != b"ply":
            raise DatasetError(f"{file}: not a PLY file")
        encoding, count, names, types, element = "", 0, [], [], ""
        while True:
            line = handle.readline()
            if not line:
                raise DatasetError(f"{file}: PLY header has no end_header")
            words = line.decode("ascii", errors="replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                encoding = words[1]
            elif words[0] == "element":
                if element == "" and words[1] != "vertex":
                    raise DatasetError(f"{file}: the first PLY element must be vertex")
                element = words[1]
                if element == "vertex":
                    count = int(words[2])
            elif words[0] == "property" and element == "vertex":
                if words[1] == "list" or words[1] not in _PLY_TYPES:
                    raise DatasetError(f"{file}: unsupported vertex property {' '.join(words[1:])}")
                types.append(_PLY_TYPES[words[1]])
                names.append(words[2])
        left = os.fstat(handle.fileno()).st_size - handle.tell()
        record = sum(np.dtype(kind).itemsize for kind in types)
        _check_vertex_count(file, encoding, count, len(names), left, record=record)
        if encoding == "ascii":
            rows = [handle.readline().split()[: len(names)] for _ in range(count)]
            if any(len(row) < len(names) for row in rows):
                raise DatasetError(f"{file}: PLY vertex list is truncated")
            table = np.array(rows, dtype=np.float64).reshape(count, len(names))
            return {name: table[:, k] for k, name in enumerate(names)}
        order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(encoding)
        if order is None:
            raise DatasetError(f"{file}: unknown PLY format {encoding!r}")
        dtype = np.dtype([(name, order + kind) for name, kind in zip(names, types, strict=True)])
        raw = handle.read(dtype.itemsize * count)
        if len(raw) < dtype.itemsize * count:
            raise DatasetError(f"{file}: PLY vertex data is truncated")
        vertices = np.frombuffer(raw, dtype=dtype, count=count)
        return {name: vertices[name].astype(np.float64) for name in names}
