"""The field store's names and numbers: schema version, chunking, horizon statement, files.

Shared by the writer (:mod:`core.store.writer`) and the reader (:mod:`core.field_store`), so
the two agree on them by construction.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

# Names, then a Literal and its values: render.live_session's head has the same shape
# (duplicates pairs them), but they share no logic, only Python's way of listing names.
__all__ = [
    "ARRAYS",
    "BELOW_HORIZON",
    "DIGESTED_MARK",
    "DIGESTS_ATTRIBUTE",
    "FIELD_SCHEMA_VERSION",
    "SAMPLE_CHUNK",
    "ArraySpec",
    "BelowHorizon",
    "companion_paths",
    "is_field_store",
]

BelowHorizon = Literal["blocked", "open"]
#: What lies below the rig's horizon (the plane of the object's base, rig z = 0), as a capture
#: states it in ``light_model["below_horizon"]``. ``blocked``: a base, table or turntable hides
#: the environment below the horizon from the object (the usual case: captures default to it),
#: so relighting drops that light; ``open``: the object is lit from every direction (a floating
#: object, the simulator's scenes). Stores that state nothing were relit as ``open``.
BELOW_HORIZON: tuple[BelowHorizon, ...] = get_args(BelowHorizon)

FIELD_SCHEMA_VERSION = 1

#: Samples per radiance chunk. Building writes and relighting reads whole (camera, light)
#: slabs; fitting and evaluation read every slab's part for a block of samples. Measured on
#: this 2-core machine (``python -m bench.scale --chunking``, 1M samples of a simulated
#: sphere, float16, two runs): against one chunk per slab, 65,536 samples writes slabs at
#: 0.84-0.90x the speed and reads a camera at 0.64-0.75x (540-580 MB/s), and reads a block of
#: samples 2.0-2.2x faster (the whole slab is no longer decompressed for a part of it); 262,144
#: reads cameras faster but blocks slower, and a block that size (2.8 GB in float32 at
#: S = T = 30) is more than a fit's default budget. Stores written before with one chunk per
#: slab read as they are.
SAMPLE_CHUNK = 65536


@dataclass(frozen=True)
class ArraySpec:
    """What an array of the store must be, whatever its zarr metadata says.

    Attributes
    ----------
    shape : str, the shape as the layout names it ("(S, T, P, 3)")
    rank : int, its number of dimensions
    dtypes : tuple of str, the dtypes a store may hold it in (the reader widens them)
    """

    shape: str
    rank: int
    dtypes: tuple[str, ...]


_FLOATS = ("float16", "float32", "float64")

#: The store's arrays (the layout in :mod:`core.field_store`). A zarr.json edited to another
#: dtype of the same width (float32 -> int32) reads the same bytes as other numbers: the
#: reader holds every array to these before it reads one.
ARRAYS: dict[str, ArraySpec] = {
    "radiance": ArraySpec("(S, T, P, 3)", 4, ("float16", "float32")),
    "visibility": ArraySpec("(S, P)", 2, ("bool",)),
    "points": ArraySpec("(P, 3)", 2, _FLOATS),
    "normals": ArraySpec("(P, 3)", 2, _FLOATS),
    "light_directions": ArraySpec("(T, 3)", 2, _FLOATS),
    "camera_directions": ArraySpec("(S, 3)", 2, _FLOATS),
}

#: The group attribute where the writer records the digest of every array and attribute
#: (:mod:`core.store.digests`); stores written before it was recorded have none.
DIGESTS_ATTRIBUTE = "digests"
#: The radiance array's attribute by which a store says its writer recorded
#: :data:`DIGESTS_ATTRIBUTE`: a store that says so and lacks the record was altered.
DIGESTED_MARK = "digested"


def companion_paths(store: str | os.PathLike[str]) -> list[Path]:
    """Files that belong to a store and live beside it: its saved model fit, ``NAME.models.npz``.

    A store replaced by another leaves none of them behind (they describe the old data).
    """
    path = Path(store)
    return [path.with_name(path.name + ".models.npz")]


def is_field_store(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a Zarr store (a field store's directory), by its metadata file."""
    path = Path(path)
    return (path / "zarr.json").is_file() or (path / ".zgroup").is_file()
