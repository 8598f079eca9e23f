"""A world file's ``[material]`` table as a Mitsuba 3 BSDF.

The table is a Mitsuba BSDF dictionary (``type`` plus the plugin's parameters, nested BSDFs as
sub-tables with their own ``type``), with three conveniences TOML needs:

- a list of three numbers is an RGB value (``{"type": "rgb", "value": [...]}``);
- ``{ texture = "checker" | "noise" | "stripes", low, high, scale, resolution, seed }`` is a
  procedural texture (:mod:`sim.world.textures`), given to Mitsuba as an in-memory float
  ``bitmap`` mapped by the mesh's uv with ``raw = true`` (the values are used as written, no
  sRGB curve);
- ``{ image = "file", transfer = "srgb" | "linear", filter = "bilinear" | "nearest" }`` is an
  image texture, the path relative to the world file, read by :func:`core.image_io.read_linear`
  (8- and 16-bit files through ``transfer``, default ``"srgb"``: use ``"linear"`` for data such
  as roughness stored in 8 bits; EXR and HDR are linear) and handed over like a procedural one
  (image row 0 at v = 0).

Everything else (numbers, strings, booleans, nested plugin tables) passes through unchanged;
Mitsuba itself judges the parameter names and values when the world is loaded.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.image_io import read_linear
from sim.world.textures import TEXTURES, texture_filter, texture_image

__all__ = ["instantiate_bsdf", "material_dict", "material_files", "needs_uv"]

_TEXTURE_KEYS = {"texture", "low", "high", "scale", "resolution", "seed"}
_IMAGE_KEYS = {"image", "transfer", "filter"}
#: Parameters that need a tangent frame, which Mitsuba takes from the uv.
_ANISOTROPIC = {"alpha_u", "alpha_v", "anisotropic"}
MAX_TEXTURE_RESOLUTION = 4096


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _whole(value: Any, where: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(f"{where}: expected a whole number in {low}..{high}, got {value!r}")
    return int(value)


def _colour(value: list[Any], where: str) -> tuple[float, float, float]:
    if len(value) != 3:
        raise InputError(f"{where}: a colour has three values (r, g, b), got {len(value)}")
    r, g, b = (_number(c, where) for c in value)
    return (r, g, b)


def _level(value: Any, where: str) -> float | tuple[float, float, float]:
    """A texture's low or high: a number or three (an RGB colour)."""
    return _colour(value, where) if isinstance(value, list) else _number(value, where)


def _key(where: str, key: str) -> str:
    """The path of a key in error messages: ``file: [material] bsdf_0.alpha``."""
    return f"{where} {key}" if where.endswith("]") else f"{where}.{key}"


def _bitmap(mi: Any, pixels: NDArray[np.float32], filter_type: str) -> dict[str, Any]:
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(pixels, dtype=np.float32)),
        "raw": True,  # the values are linear already; no sRGB decoding by Mitsuba
        "filter_type": filter_type,
        "wrap_mode": "repeat",
    }


def _procedural(mi: Any, table: Mapping[str, Any], where: str) -> dict[str, Any]:
    unknown = sorted(set(table) - _TEXTURE_KEYS)
    if unknown:
        raise InputError(
            f"{where}: unknown texture key {unknown[0]!r}; a texture has {sorted(_TEXTURE_KEYS)}"
        )
    kind = table["texture"]
    if kind not in TEXTURES:
        raise InputError(
            f"{where}.texture: unknown texture {kind!r}; known textures: {', '.join(TEXTURES)}"
        )
    pixels = texture_image(
        kind,
        low=_level(table.get("low", 0.0), _key(where, "low")),
        high=_level(table.get("high", 1.0), _key(where, "high")),
        scale=_whole(
            table.get("scale", 4), _key(where, "scale"), 2 if kind == "noise" else 1, 1024
        ),
        resolution=_whole(
            table.get("resolution", 256), _key(where, "resolution"), 2, MAX_TEXTURE_RESOLUTION
        ),
        seed=_whole(table.get("seed", 0), _key(where, "seed"), 0, 2**32 - 1),
    )
    return _bitmap(mi, pixels, texture_filter(kind))


def _image(mi: Any, table: Mapping[str, Any], where: str, folder: Path) -> dict[str, Any]:
    unknown = sorted(set(table) - _IMAGE_KEYS)
    if unknown:
        raise InputError(
            f"{where}: unknown image key {unknown[0]!r}; an image texture has {sorted(_IMAGE_KEYS)}"
        )
    transfer, filter_type = table.get("transfer", "srgb"), table.get("filter", "bilinear")
    if transfer not in ("srgb", "linear"):
        raise InputError(f"{where}.transfer: expected 'srgb' or 'linear', got {transfer!r}")
    if filter_type not in ("bilinear", "nearest"):
        raise InputError(f"{where}.filter: expected 'bilinear' or 'nearest', got {filter_type!r}")
    if not isinstance(table["image"], str):
        raise InputError(f"{where}.image: expected a file name, got {table['image']!r}")
    try:
        pixels = read_linear(folder / table["image"], transfer=transfer)
    except InputError as error:
        raise InputError(f"{where}.image: {error}") from error
    return _bitmap(mi, pixels, filter_type)


def _value(mi: Any, value: Any, where: str, folder: Path) -> Any:
    if isinstance(value, bool | str):
        return value
    if isinstance(value, int | float):
        return _number(value, where)
    if isinstance(value, list):
        return {"type": "rgb", "value": list(_colour(value, where))}
    if isinstance(value, Mapping):
        if "texture" in value:
            return _procedural(mi, value, where)
        if "image" in value:
            return _image(mi, value, where, folder)
        if "type" in value:
            return material_dict(mi, value, where=where, folder=folder)
        raise InputError(
            f"{where}: a table needs 'type' (a Mitsuba plugin), 'texture' "
            f"({', '.join(TEXTURES)}) or 'image' (a file)"
        )
    raise InputError(f"{where}: cannot use {value!r} as a Mitsuba parameter")


def material_dict(mi: Any, table: Mapping[str, Any], *, where: str, folder: Path) -> dict[str, Any]:
    """The Mitsuba dictionary of a ``[material]`` table (module docstring).

    Parameters
    ----------
    mi : the ``mitsuba`` module with a variant set (for the textures' bitmaps)
    table : the parsed table
    where : names the table in errors (``"world.toml: [material]"``)
    folder : the world file's folder, which image paths are relative to

    Raises
    ------
    InputError
        No ``type``, or a value that cannot be a parameter (an unknown texture, a bad number,
        an unreadable image); the message names the key.
    """
    kind = table.get("type")
    if not isinstance(kind, str) or not kind:
        raise InputError(f"{where}: needs a 'type' (a Mitsuba BSDF plugin such as 'principled')")
    return {
        key: kind if key == "type" else _value(mi, value, _key(where, key), folder)
        for key, value in table.items()
    }


def _walk(table: Mapping[str, Any]) -> Iterator[tuple[str, Any]]:
    for key, value in table.items():
        yield key, value
        if isinstance(value, Mapping):
            yield from _walk(value)


def needs_uv(table: Mapping[str, Any]) -> bool:
    """Whether a material reads the mesh's uv: textures, or anisotropic roughness."""
    return any(
        key in _ANISOTROPIC
        or (isinstance(value, Mapping) and ("texture" in value or "image" in value))
        for key, value in _walk(table)
    )


def material_files(table: Mapping[str, Any], folder: Path) -> list[Path]:
    """The image files a material reads, in the table's order (for the world's digest)."""
    return [folder / value["image"] for _, value in _walk(table)
            if isinstance(value, Mapping) and isinstance(value.get("image"), str)]  # fmt: skip


#: Mitsuba's source locations and parser node names: noise in a message about a world file.
_MITSUBA_PREFIX = re.compile(
    r"\[[\w.]+:\d+\]\s*|(?:At|While loading) dictionary node \"[^\"]*\":\s*"
)


def instantiate_bsdf(mi: Any, bsdf: Mapping[str, Any], where: str) -> Any:
    """Load a BSDF dictionary in Mitsuba; Mitsuba's refusal becomes an InputError at ``where``.

    Raises
    ------
    InputError
        Mitsuba refuses the dictionary (unknown plugin, unknown or ill-typed parameter, an IOR
        name it does not have) or it is not a BSDF; the message carries Mitsuba's reason.
    """
    try:
        loaded = mi.load_dict(dict(bsdf))
    except RuntimeError as error:
        reason = " ".join(_MITSUBA_PREFIX.sub("", str(error)).split())
        hint = ""
        if "data/ior" in reason:
            hint = "; conductor 'material' names are Mitsuba's IOR tables (Au, Cu, Al, Ag, Cr, ...)"
        raise InputError(f"{where}: Mitsuba refuses the material: {reason}{hint}") from None
    if not isinstance(loaded, mi.BSDF):
        raise InputError(f"{where}: type {bsdf.get('type')!r} is not a Mitsuba BSDF")
    return loaded
