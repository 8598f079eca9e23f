"""The field store's names and numbers: schema version, chunking, horizon statement, files.

Shared by the writer (:mod:`core.field_writer`) and the reader (:mod:`core.field_store`), so
the two agree on them by construction.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal, get_args

__all__ = [
    "BELOW_HORIZON",
    "FIELD_SCHEMA_VERSION",
    "SAMPLE_CHUNK",
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
