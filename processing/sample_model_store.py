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
import os
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.atomic import atomic_path
from core.errors import DatasetError
from core.field_store import ReflectanceField, companion_paths
from processing.sample_models import (
    BasisFit,
    Fit,
    LooError,
    ParametricFit,
    SampleModels,
    fit_sample_models,
)

__all__ = [
    "FORMAT_VERSION",
    "StaleFitError",
    "default_models_path",
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


def write_sample_models(
    path: str | os.PathLike[str], models: SampleModels, field: ReflectanceField
) -> Path:
    """Save ``models`` fitted to ``field`` at ``path`` (atomically); returns the path."""
    arrays: dict[str, Any] = {
        "format": np.int64(FORMAT_VERSION),
        "field_shape": np.asarray(field.shape, dtype=np.int64),
        "field_lights": np.asarray(field.light_directions, dtype=np.float64),
        "field_points_digest": np.str_(_points_digest(field)),
        "field_radiance_digest": np.str_(field.radiance_digest or ""),
        "kind": np.str_(models.kind),
        "light_directions": models.light_directions,
        "camera_frame": models.camera_frame,
        "sample_count": np.int64(models.sample_count),
        "fit_names": np.asarray(list(models.fits), dtype=np.str_),
    }
    for name, value in (
        ("view_direction", models.view_direction),
        ("points", models.points),
        ("mark_directions", models.mark_directions),
    ):
        if value is not None:
            arrays[name] = value
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


def read_sample_models(
    path: str | os.PathLike[str], field: ReflectanceField | None = None
) -> SampleModels:
    """Load models saved by :func:`write_sample_models`.

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
            data = {key: archive[key] for key in archive.files}
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
    saved = str(data.get("field_radiance_digest", ""))
    if field.radiance_digest and saved != field.radiance_digest:
        raise StaleFitError(
            f"{source} was fitted to other data than {field.path} holds now (its radiance "
            f"digest {saved[:12] or 'is missing'}, the store's {field.radiance_digest[:12]}); "
            "delete the file to fit again"
        )


def models_for_field(
    field: ReflectanceField,
    path: str | os.PathLike[str] | None = None,
    *,
    models: Sequence[str] | None = None,
    progress: bool = False,
) -> SampleModels:
    """The fit of ``field``: read from ``path`` (default beside the field) or fitted and saved.

    A saved fit is used when it was made from this field's data and holds every requested model
    (``models``: default the fitting default); otherwise the field is fitted again and the file
    replaced. A stale fit at an explicit ``path`` is refused (:class:`StaleFitError`) rather
    than replaced: the caller named that file. A store in a read-only place is fitted without
    saving.
    """
    target = default_models_path(field.path) if path is None else Path(path)
    if target.exists():
        try:
            saved = read_sample_models(target, field)
        except StaleFitError:
            if path is not None:
                raise
        else:
            if models is None or all(name in saved.fits for name in models):
                return saved
    fitted = fit_sample_models(field, models, progress=progress)
    try:
        write_sample_models(target, fitted, field)
    except PermissionError:
        pass  # relighting does not need the file; the next run fits again
    return fitted
