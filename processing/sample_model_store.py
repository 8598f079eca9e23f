"""Fitted per-sample models on disk, so a field is fitted once and relit many times.

Fitting a 250 000-point field takes about a minute on two cores; relighting through the fit
takes milliseconds. :func:`models_for_field` reads the fit saved beside a field (``FIELD`` ->
``FIELD.models.npz``) when it was made from that same field, and fits and saves otherwise.

The file is a NumPy ``.npz`` archive (no pickled objects): ``format`` (``FORMAT_VERSION``),
the field's fingerprint (``field_shape``, ``field_lights``, ``field_points_digest``, and
``field_radiance_digest``: the store's digest of its data, so a fit of a replaced store is
never reused), the
:class:`SampleModels` arrays, and per fit ``NAME__ARRAY`` entries. It is written atomically
(temporary name, fsync, rename), so a crash leaves the old file or none.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.atomic import atomic_path, output_problem, write_problem, writer_tag
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField, companion_paths
from processing.sample_models import (
    BasisFit,
    Fit,
    LooError,
    ParametricFit,
    SampleModels,
    fit_sample_models,
)
from processing.sample_models.fitting import fit_blocks
from processing.sample_models.layout import FitLayout

__all__ = [
    "FORMAT_VERSION",
    "StaleFitError",
    "default_models_path",
    "fit_to_file",
    "models_for_field",
    "read_sample_models",
    "write_sample_models",
]

FORMAT_VERSION = 1
_PARAMETRIC_ARRAYS = ("normals", "rho_d", "f0", "alpha", "lit", "fitted")


def default_models_path(field_path: str | os.PathLike[str]) -> Path:
    """Where the fit of a field is kept: beside the store, ``NAME.models.npz``."""
    return companion_paths(field_path)[0]


def _points_digest(field: ReflectanceField) -> str:
    points = field.points
    data = b"" if points is None else np.ascontiguousarray(points, dtype=np.float32).tobytes()
    return hashlib.sha256(data).hexdigest()


def _header(
    field: ReflectanceField,
    kind: str,
    light_directions: NDArray[np.float64],
    camera_frame: NDArray[np.float64],
    sample_count: int,
    names: Sequence[str],
    optional: dict[str, NDArray[Any] | None],
) -> dict[str, Any]:
    """The file's arrays that are not per-sample fits: format, fingerprint, the models' frame."""
    arrays: dict[str, Any] = {
        "format": np.int64(FORMAT_VERSION),
        "field_shape": np.asarray(field.shape, dtype=np.int64),
        "field_lights": np.asarray(field.light_directions, dtype=np.float64),
        "field_points_digest": np.str_(_points_digest(field)),
        "field_radiance_digest": np.str_(field.radiance_digest or ""),
        "kind": np.str_(kind),
        "light_directions": light_directions,
        "camera_frame": camera_frame,
        "sample_count": np.int64(sample_count),
        "fit_names": np.asarray(list(names), dtype=np.str_),
    }
    arrays |= {name: value for name, value in optional.items() if value is not None}
    return arrays


def write_sample_models(
    path: str | os.PathLike[str], models: SampleModels, field: ReflectanceField
) -> Path:
    """Save ``models`` fitted to ``field`` at ``path`` (atomically); returns the path."""
    arrays = _header(
        field, models.kind, models.light_directions, models.camera_frame, models.sample_count,
        list(models.fits), {"view_direction": models.view_direction, "points": models.points,
                            "mark_directions": models.mark_directions},
    )  # fmt: skip
    for name, fit in models.fits.items():
        arrays[f"{name}__loo_squared_error"] = fit.loo.squared_error
        arrays[f"{name}__loo_energy"] = fit.loo.energy
        if isinstance(fit, ParametricFit):
            for key in _PARAMETRIC_ARRAYS:
                arrays[f"{name}__{key}"] = getattr(fit, key)
            arrays[f"{name}__normals_fitted"] = np.bool_(fit.normals_fitted)
        else:
            arrays[f"{name}__coefficients"] = fit.coefficients
    target = Path(path)
    with atomic_path(target) as temporary, open(temporary, "wb") as handle:
        np.savez(handle, **arrays)
    return target


#: Bytes copied at a time from a streamed array's part file into the fit file.
_COPY_BYTES = 16 << 20


def fit_to_file(
    field: ReflectanceField,
    path: str | os.PathLike[str],
    models: Sequence[str] | None = None,
    *,
    memory_bytes: int | None = None,
    client: Any = None,
) -> FitLayout:
    """Fit ``field`` block by block and write the fit to ``path`` as the blocks come.

    The file is the one :func:`write_sample_models` writes of :func:`fit_sample_models`'s
    result (the same arrays, read back by :func:`read_sample_models`), but no fit is ever held
    whole: each block's arrays are written at their place in a part file per array beside
    ``path`` (``.NAME.PID.TID.parts/``), and once every block is in, the parts are copied into
    the ``.npz`` archive one after the other and removed. Memory: one block and its fits
    (:func:`processing.sample_models.fitting.fit_blocks`); disk: the fit twice, for a moment.

    Parameters
    ----------
    field, models, memory_bytes, client : as :func:`fit_sample_models`
    path : the fit file to write (atomically: a failed fit leaves the old file or none)

    Returns
    -------
    FitLayout, what was fitted (its models, in order)
    """
    target = Path(path)
    layout, blocks = fit_blocks(field, models, memory_bytes=memory_bytes, client=client)
    problem = output_problem(target)
    if problem is not None:
        raise InputError(problem)
    target.parent.mkdir(parents=True, exist_ok=True)
    parts = target.with_name(f".{target.name}.{writer_tag()}.parts")
    shutil.rmtree(parts, ignore_errors=True)
    parts.mkdir()
    specs = layout.arrays()
    files = {key: parts / f"{index}.raw" for index, key in enumerate(specs)}
    handles: dict[str, Any] = {}
    try:
        for key, (dtype, shape) in specs.items():
            handles[key] = open(files[key], "wb+")
            # The whole array's size up front: blocks that finish out of order (a cluster)
            # are written at their own place.
            handles[key].truncate(layout.sample_count * dtype.itemsize * math.prod(shape))
        for part, fitted in blocks:
            for key, values in fitted.items():
                dtype, shape = specs[key]
                data = np.ascontiguousarray(values, dtype=dtype)
                os.pwrite(handles[key].fileno(), data.data,
                          part.start * dtype.itemsize * math.prod(shape))  # fmt: skip
        header = _header(
            field, layout.kind, layout.light_directions, layout.camera_frame,
            layout.sample_count, layout.names,
            {"view_direction": layout.view_direction, "points": layout.points},
        )  # fmt: skip
        header |= {
            f"{name}__normals_fitted": np.bool_(layout.normals_fitted)
            for name in layout.names
            if f"{name}__normals" in specs
        }
        with (
            atomic_path(target) as temporary,
            zipfile.ZipFile(temporary, "w", zipfile.ZIP_STORED, allowZip64=True) as archive,
        ):
            # As numpy.savez writes: one NAME.npy per array, stored (not compressed).
            for name, value in header.items():
                with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
            for key, (dtype, shape) in specs.items():
                with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array_header_1_0(member, {
                        "descr": np.lib.format.dtype_to_descr(dtype),
                        "fortran_order": False,
                        "shape": (layout.sample_count, *shape),
                    })  # fmt: skip
                    handles[key].seek(0)
                    shutil.copyfileobj(handles[key], member, _COPY_BYTES)
                # Its part is in the archive: the disk holds the fit twice only per array.
                handles.pop(key).close()
                files[key].unlink()
    except OSError as error:  # a full disk while writing the parts (the archive's is named)
        raise InputError(write_problem(target, error)) from None
    finally:
        for handle in handles.values():
            handle.close()
        shutil.rmtree(parts, ignore_errors=True)
    return layout


def read_sample_models(
    path: str | os.PathLike[str],
    field: ReflectanceField | None = None,
    *,
    models: Sequence[str] | None = None,
) -> SampleModels:
    """Load models saved by :func:`write_sample_models` (or :func:`fit_to_file`).

    Parameters
    ----------
    path : the fit file
    field : ReflectanceField, optional, the field the fit must be of (checked)
    models : names of the fits to load, optional (default every one). Only their arrays are
        read: a 24-megapixel capture's five fits are 13 GB, its PTM alone 2 GB. Names the
        file does not hold are left out (the result's ``fits`` says what was found).

    Raises
    ------
    DatasetError
        The file is missing, not a models file, of another format version, or (``field``
        given) fitted to another field: its shape, lights, points or radiance differ
        (:class:`StaleFitError`).
    """
    source = Path(path)
    try:
        # Our handle, closed whatever np.load raises (it leaks its own on a bad zip).
        with open(source, "rb") as handle, np.load(handle, allow_pickle=False) as archive:
            wanted = None if models is None else {f"{name}__" for name in models}
            data = {
                key: archive[key]
                for key in archive.files
                if wanted is None or "__" not in key or key[: key.index("__") + 2] in wanted
            }
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as error:
        raise DatasetError(f"{source}: not a readable models file ({error})") from error
    except AttributeError:  # np.load gave a bare array (.npy), which has no files
        raise DatasetError(f"{source}: not a models file (a single array)") from None
    if "format" not in data or int(data["format"]) != FORMAT_VERSION:
        found = data.get("format")
        raise DatasetError(
            f"{source}: models format {found!r}, this version reads {FORMAT_VERSION}; "
            "delete the file to fit again"
        )
    if field is not None:
        _check_same_field(source, data, field)
    fits: dict[str, Fit] = {}
    for name in (str(n) for n in data["fit_names"]):
        if models is not None and name not in models:
            continue
        loo = LooError(data[f"{name}__loo_squared_error"], data[f"{name}__loo_energy"])
        if f"{name}__coefficients" in data:
            fits[name] = BasisFit(name, data[f"{name}__coefficients"], loo)
        else:
            values = {key: data[f"{name}__{key}"] for key in _PARAMETRIC_ARRAYS}
            # Fits saved before the marks were bytes hold them as float32 0/1.
            values["lit"] = np.asarray(values["lit"]).astype(np.uint8, copy=False)
            fits[name] = ParametricFit(
                name=name,
                loo=loo,
                normals_fitted=bool(data[f"{name}__normals_fitted"]),
                **values,
            )
    return SampleModels(
        kind=str(data["kind"]),
        light_directions=data["light_directions"],
        camera_frame=data["camera_frame"],
        view_direction=data.get("view_direction"),
        points=data.get("points"),
        fits=fits,
        sample_count=int(data["sample_count"]),
        mark_directions=data.get("mark_directions"),
    )


class StaleFitError(DatasetError):
    """A saved fit belongs to another field (or to older data of this one)."""


def _check_same_field(source: Path, data: dict[str, NDArray[Any]], field: ReflectanceField) -> None:
    shape = tuple(int(v) for v in data["field_shape"])
    if shape != field.shape:
        raise StaleFitError(
            f"{source} was fitted to a field of shape {shape}, {field.path} is {field.shape}; "
            "delete the file to fit again"
        )
    same_lights = np.allclose(data["field_lights"], field.light_directions, atol=1e-9)
    if not same_lights or str(data["field_points_digest"]) != _points_digest(field):
        raise StaleFitError(
            f"{source} was fitted to another field than {field.path} (lights or points "
            "differ); delete the file to fit again"
        )
    # The geometry alone cannot tell two scenes of one layout apart: the data's digest can.
    # A fit that names a digest came from a store that had one: a store without one (written
    # before digests were recorded) is another field.
    saved = str(data.get("field_radiance_digest", ""))
    if saved != (field.radiance_digest or ""):
        raise StaleFitError(
            f"{source} was fitted to other data than {field.path} holds now (its radiance "
            f"digest {saved[:12] or 'is missing'}, the store's "
            f"{(field.radiance_digest or '')[:12] or 'is missing'}); delete the file to fit again"
        )


def models_for_field(
    field: ReflectanceField,
    path: str | os.PathLike[str] | None = None,
    *,
    models: Sequence[str] | None = None,
    memory_bytes: int | None = None,
    client: Any = None,
) -> SampleModels:
    """The fit of ``field``: read from ``path`` (default beside the field) or fitted and saved.

    A saved fit is used when it was made from this field's data and holds every requested model
    (``models``: default the fitting default); otherwise the field is fitted again and the file
    replaced. A stale fit at an explicit ``path`` is refused (:class:`StaleFitError`) rather
    than replaced: the caller named that file. A store in a read-only place is fitted without
    saving. Only the requested models are read from the file (``models`` None: every one).
    ``memory_bytes`` and ``client`` (a Dask client) are the fit's, when there is one.
    """
    target = default_models_path(field.path) if path is None else Path(path)
    if target.exists():
        try:
            saved = read_sample_models(target, field, models=models)
        except StaleFitError:
            if path is not None:
                raise
        else:
            if models is None or all(name in saved.fits for name in models):
                return saved
    if output_problem(target) is not None:
        # Relighting does not need the file (the next run fits again): fitted in memory.
        return fit_sample_models(field, models, memory_bytes=memory_bytes, client=client)
    # Written as it is fitted, then read: the fit is never held twice, nor whole while fitted.
    layout = fit_to_file(field, target, models, memory_bytes=memory_bytes, client=client)
    return read_sample_models(target, field, models=layout.names)
