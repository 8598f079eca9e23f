"""A field store's attributes and directions, checked as the store is opened.

The attributes (``samples``, ``cameras``, ``light_model``, ``provenance``, ``radiance_digest``,
``dark_cameras``; the layout is in :mod:`core.field_store`) are JSON in ``zarr.json``: a store
edited by hand, or by another tool, may hold any JSON there. :func:`read_attributes` is the one
place they are read: a value of the wrong type or out of range is a
:class:`~core.errors.DatasetError` naming the store, the attribute and the value, never an
``AttributeError`` or ``KeyError`` from deep inside a command. :func:`direction_problem` holds
the light and camera directions to finite unit vectors, for the writer and the reader alike.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import DatasetError

__all__ = [
    "UNIT_TOLERANCE",
    "StoreAttributes",
    "check_directions",
    "direction_problem",
    "read_attributes",
]

#: How far from 1 a stored direction's length may be (float32 round trips, hand-made stores).
UNIT_TOLERANCE = 1e-3

_DIGEST = re.compile(r"[0-9a-f]{64}")


@dataclass(frozen=True)
class StoreAttributes:
    """The attributes of a store, checked (see :func:`read_attributes`)."""

    image_shape: tuple[int, int] | None
    cameras: list[PinholeCamera]
    light_model: dict[str, Any]
    provenance: dict[str, Any]
    radiance_digest: str | None
    dark_cameras: tuple[int, ...] | None


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _bad(where: Path, name: str, value: object, expected: str) -> DatasetError:
    return DatasetError(
        f"{where}: attribute {name} is {_shown(value)}, expected {expected}; the store's "
        "metadata was altered: rebuild the store from its source"
    )


def _count(value: object) -> TypeGuard[int]:
    """An integer of JSON (bool is not one)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _mapping(where: Path, attrs: Mapping[str, Any], name: str) -> dict[str, Any]:
    value = attrs.get(name, {})
    if not isinstance(value, Mapping):
        raise _bad(where, name, value, "an object (a mapping of names to values)")
    return dict(value)


def _image_shape(where: Path, attrs: Mapping[str, Any], samples: int) -> tuple[int, int] | None:
    kind = attrs.get("samples", {"kind": "points"})  # stores of points once stated nothing
    if not isinstance(kind, Mapping):
        raise _bad(where, "samples", kind, '{"kind": "points"} or {"kind": "pixels", ...}')
    if kind.get("kind") == "points":
        return None
    if kind.get("kind") != "pixels":
        raise _bad(where, "samples", dict(kind), 'a kind of "points" or "pixels"')
    height, width = kind.get("height"), kind.get("width")
    if not (_count(height) and _count(width) and height >= 1 and width >= 1):
        raise _bad(where, "samples", dict(kind), "pixels of a height and width of at least 1")
    if height * width != samples:
        raise DatasetError(
            f"{where}: attribute samples says {height} x {width} pixels, the radiance holds "
            f"P = {samples} samples; the store's metadata was altered: rebuild the store"
        )
    return height, width


def _cameras(where: Path, attrs: Mapping[str, Any], count: int) -> list[PinholeCamera]:
    records = attrs.get("cameras")
    if not isinstance(records, list):
        raise _bad(where, "cameras", records, "a list of camera records")
    if len(records) != count:
        raise DatasetError(f"{where}: {len(records)} camera records for S = {count}")
    cameras = []
    for index, record in enumerate(records):
        if not isinstance(record, Mapping):
            raise _bad(where, f"cameras[{index}]", record, "a camera record (an object)")
        try:
            cameras.append(PinholeCamera(**record))
        except (TypeError, ValueError) as error:  # InputError is a ValueError
            raise DatasetError(
                f"{where}: bad camera records: camera {index} {_shown(dict(record))}: {error}"
            ) from None
    return cameras


def _digest(where: Path, attrs: Mapping[str, Any]) -> str | None:
    value = attrs.get("radiance_digest")
    if value is None:
        return None
    if not (isinstance(value, str) and _DIGEST.fullmatch(value)):
        raise _bad(where, "radiance_digest", value, "a SHA-256 in 64 hexadecimal digits")
    return value


def _dark(where: Path, attrs: Mapping[str, Any], count: int) -> tuple[int, ...] | None:
    value = attrs.get("dark_cameras")
    if value is None:
        return None
    if not (isinstance(value, list) and all(_count(c) and 0 <= c < count for c in value)):
        raise _bad(where, "dark_cameras", value, f"a list of camera indices in 0..{count - 1}")
    return tuple(value)


def read_attributes(
    where: Path, attrs: Mapping[str, Any], shape: tuple[int, int, int]
) -> StoreAttributes:
    """The attributes of the store at ``where`` of radiance ``shape`` (S, T, P), checked.

    Attributes a store may lack take their defaults (points, no light model, no provenance,
    no digest, no dark cameras: stores written before they were recorded).

    Raises
    ------
    DatasetError
        An attribute of the wrong type or out of range, named with its value.
    """
    cameras, _, samples = shape
    return StoreAttributes(
        image_shape=_image_shape(where, attrs, samples),
        cameras=_cameras(where, attrs, cameras),
        light_model=_mapping(where, attrs, "light_model"),
        provenance=_mapping(where, attrs, "provenance"),
        radiance_digest=_digest(where, attrs),
        dark_cameras=_dark(where, attrs, cameras),
    )


def direction_problem(name: str, directions: NDArray[np.floating]) -> str | None:
    """Why ``directions`` (N, 3) are not finite unit vectors (the first named by index), or None.

    ``name`` is the singular of what they are ("light direction").
    """
    values = np.asarray(directions, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != 3:
        return f"{name}s must have shape (N, 3), got {values.shape}"
    with np.errstate(invalid="ignore", over="ignore"):
        lengths = np.linalg.norm(values, axis=1)
        bad = ~np.isfinite(values).all(axis=1) | ~(np.abs(lengths - 1.0) <= UNIT_TOLERANCE)
    if not bad.any():
        return None
    index = int(np.flatnonzero(bad)[0])
    vector = ", ".join(f"{v:.6g}" for v in values[index])
    count = int(bad.sum())
    others = f" ({count - 1} more)" if count > 1 else ""
    return (
        f"{name} {index} is ({vector}), of length {lengths[index]:.6g}{others}; {name}s must be "
        "finite unit vectors"
    )


def check_directions(where: Path, name: str, directions: NDArray[np.floating]) -> None:
    """:func:`direction_problem` of a store's array as a DatasetError naming the store."""
    problem = direction_problem(name, directions)
    if problem is not None:
        raise DatasetError(f"{where}: {problem}: rebuild the store from its source")
