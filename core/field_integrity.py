"""Reading a field store's arrays so that damage is an error, never data.

Zarr reads a chunk that is not there as the array's fill value, and a truncated chunk as a
codec exception deep in the decompressor: neither says which store or chunk is damaged, and
the first one silently turns a lost image into black radiance. :mod:`core.field_store` reads
through these functions: a missing chunk, a chunk that does not decode, and a non-finite
value are each a :class:`~core.errors.DatasetError` naming the store, the chunk's file and
(for values) the count and the first location.

Stores are local directories (zarr's ``LocalStore``); a chunk's file is
``STORE/ARRAY/<chunk key>``, the key as the array's metadata encodes it (``c/s/t/0/0``).
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from core.errors import DatasetError
from core.field_attributes import direction_problem, read_attributes
from core.progress import progress_bar

__all__ = [
    "CHUNK_MEANING",
    "StoreCheck",
    "check_store",
    "chunk_file",
    "missing_chunks",
    "non_finite",
    "radiance_digest",
    "read_checked",
    "require_complete",
    "slab_digest",
]


def _chunk_grid(array: Any) -> list[int]:
    return [math.ceil(n / c) for n, c in zip(array.shape, array.chunks, strict=True)]


def chunk_file(root: Path, array: Any, index: tuple[int, ...]) -> Path:
    """The file holding chunk ``index`` (chunk-grid coordinates) of ``array`` in store ``root``."""
    return root / array.path / array.metadata.encode_chunk_key(index)


def missing_chunks(root: Path, array: Any) -> list[tuple[int, ...]]:
    """The chunk-grid indices of ``array`` whose file is absent, in C order."""
    grid = _chunk_grid(array)
    return [
        index
        for index in itertools.product(*(range(n) for n in grid))
        if not chunk_file(root, array, index).is_file()
    ]


def require_complete(root: Path, array: Any) -> None:
    """Raise when a chunk of ``array`` is absent (read, it would be the fill value).

    Parameters
    ----------
    root : the store's directory
    array : zarr array of the store (its chunks named by :data:`CHUNK_MEANING`)

    Raises
    ------
    DatasetError
        Naming the count, the first chunks and their files.
    """
    missing = missing_chunks(root, array)
    if missing:
        raise DatasetError(f"{root}: {_missing_message(root, array, missing)}")


def _missing_message(root: Path, array: Any, missing: list[tuple[int, ...]]) -> str:
    describe = CHUNK_MEANING.get(array.path, array.path)
    listed = ", ".join(
        f"{describe.format(*index)} ({chunk_file(root, array, index).relative_to(root)})"
        for index in missing[:3]
    )
    return (
        f"{len(missing)} of the {math.prod(_chunk_grid(array))} chunks of {array.path!r} are "
        f"missing ({listed}{', ...' if len(missing) > 3 else ''}): the store was damaged or "
        "cut short, and a missing chunk would read as zeros; rebuild it (rig process / rig sim "
        "field --overwrite) or restore it from a copy"
    )


#: A basic selection of leading axes: an index or a slice per axis.
Selection = tuple[int | slice, ...]


def read_checked(root: Path, array: Any, selection: Selection = ()) -> NDArray[Any]:
    """``array[selection]`` in memory; a chunk that does not decode is named.

    Parameters
    ----------
    root : the store's directory
    array : zarr array
    selection : indices or slices of the leading axes (all of an axis not named)

    Raises
    ------
    DatasetError
        A chunk failed to read or decompress: the store, the chunk and its file, the error.
    """
    try:
        return np.asarray(array[selection])
    except Exception as error:  # numcodecs/zstd, blosc, OSError: whatever the codec raises
        bad = _first_unreadable(array, selection)
        if bad is None:
            where = f"{array.path}{list(selection)}"
        else:
            describe = CHUNK_MEANING.get(array.path, array.path)
            where = f"{describe.format(*bad)} ({chunk_file(root, array, bad).relative_to(root)})"
        raise DatasetError(
            f"{root}: cannot read {where}: {type(error).__name__}: {error}; the chunk is "
            "damaged (truncated or overwritten): rebuild the store or restore it from a copy"
        ) from None


def _first_unreadable(array: Any, selection: Selection) -> tuple[int, ...] | None:
    """The first chunk under ``selection`` that fails on its own (chunk-grid index)."""
    covered: list[range] = []
    for axis, (n, c) in enumerate(zip(array.shape, array.chunks, strict=True)):
        part = selection[axis] if axis < len(selection) else slice(None)
        if isinstance(part, slice):
            start, stop, _ = part.indices(n)
            covered.append(range(start // c, max(math.ceil(stop / c), start // c + 1)))
        else:
            covered.append(range(part // c, part // c + 1))
    for index in itertools.product(*covered):
        region = tuple(
            slice(i * c, min((i + 1) * c, n))
            for i, c, n in zip(index, array.chunks, array.shape, strict=True)
        )
        try:
            array[region]
        except Exception:
            return index
    return None


def non_finite(values: NDArray[np.floating]) -> tuple[int, tuple[int, ...]] | None:
    """The count of NaN and infinite values in ``values`` and the index of the first, or None."""
    finite = np.isfinite(values)
    if finite.all():
        return None
    bad = np.argwhere(~finite)
    return len(bad), tuple(int(i) for i in bad[0])


# --- the radiance digest --------------------------------------------------------------------


def slab_digest(values: NDArray[np.floating]) -> bytes:
    """SHA-256 of one (camera, light) slab (P, 3) in its storage dtype."""
    # The array's own buffer, not a copy of it (a 24-megapixel float32 slab is 288 MB).
    return hashlib.sha256(np.ascontiguousarray(values).data).digest()


def radiance_digest(slab_digests: Iterable[bytes]) -> str:
    """The store's ``radiance_digest``: SHA-256 over the slabs' digests, camera then light order."""
    digest = hashlib.sha256()
    for value in slab_digests:
        digest.update(value)
    return digest.hexdigest()


# --- a whole store --------------------------------------------------------------------------

#: What a chunk index of each array means (the store's layout: a slab is one or more chunks
#: of samples).
CHUNK_MEANING = {
    "radiance": "camera {0} light {1} sample block {2}",
    "visibility": "camera {0}",
}


@dataclass(frozen=True)
class StoreCheck:
    """What :func:`check_store` found.

    Attributes
    ----------
    path : Path of the store
    shape : (S, T, P) or None when the store could not be opened
    chunks : int, radiance slabs (camera, light) read whole
    digest : "matches", "differs", "not recorded" (stores written before it was) or
        "not checked" (chunks could not be read)
    problems : list of str, each a damage found (empty: intact)
    """

    path: Path
    shape: tuple[int, int, int] | None
    chunks: int
    digest: str
    problems: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Whether the store is intact."""
        return not self.problems

    def summary(self) -> str:
        """The verdict, then each problem on a line of its own."""
        if self.shape is None:
            head = f"{self.path}: not a readable field store"
        else:
            s, t, p = self.shape
            head = (
                f"{self.path}: field store of {s} cameras x {t} lights x {p} samples, "
                f"{self.chunks} radiance slabs read, radiance digest {self.digest}"
            )
        verdict = "intact" if self.ok else f"DAMAGED ({len(self.problems)} problems)"
        return "\n".join([f"{head}: {verdict}", *(f"  {line}" for line in self.problems)])


def _attribute_problems(path: Path, group: Any, shape: tuple[int, int, int]) -> list[str]:
    """What :mod:`core.field_attributes` refuses in the store's attributes and directions."""
    problems = []
    try:
        read_attributes(path, dict(group.attrs), shape)
    except DatasetError as error:
        problems.append(str(error).removeprefix(f"{path}: "))
    names = set(group.array_keys())
    for name, singular in (("light_directions", "light direction"),
                           ("camera_directions", "camera direction")):  # fmt: skip
        if name in names:
            try:
                values = np.asarray(group[name][...])
            except Exception:  # unreadable: reported with the arrays
                continue
            problem = direction_problem(singular, values)
            if problem is not None and np.isfinite(values).all():  # non-finite: said above
                problems.append(problem)
    return problems


def check_store(path: Path, *, progress: bool = False) -> StoreCheck:
    """Read every chunk of the field store at ``path``: present, decodable, finite, digest.

    Parameters
    ----------
    path : the store's directory
    progress : bool, show a progress bar over the radiance chunks
    """
    try:
        group: Any = zarr.open_group(str(path), mode="r")
        radiance = group["radiance"]
    except Exception as error:  # zarr raises several types for non-stores
        return StoreCheck(path, None, 0, "not checked", (f"cannot open: {error}",))
    problems: list[str] = []
    incomplete: set[tuple[int, int]] = set()  # slabs with a chunk missing
    for name in sorted(group.array_keys()):
        array = group[name]
        missing = missing_chunks(path, array)
        if missing:
            problems.append(_missing_message(path, array, missing))
            if name == "radiance":
                incomplete = {(index[0], index[1]) for index in missing}
        elif name != "radiance":
            try:
                values = read_checked(path, array)
            except DatasetError as error:
                problems.append(str(error).removeprefix(f"{path}: "))
                continue
            if values.dtype.kind == "f" and (found := non_finite(values)) is not None:
                problems.append(f"{found[0]} non-finite values in {name!r}, first at {found[1]}")
    s, t, p, _ = radiance.shape
    problems += _attribute_problems(path, group, (s, t, p))
    digests: list[bytes] = []
    unreadable = False
    keys = [(a, b) for a in range(s) for b in range(t)]
    for a, b in progress_bar(keys, desc="verify", unit="slab", show=progress):
        if (a, b) in incomplete:
            unreadable = True
            continue
        try:
            values = read_checked(path, radiance, (a, b))
        except DatasetError as error:
            problems.append(str(error).removeprefix(f"{path}: "))
            unreadable = True
            continue
        found = non_finite(values)
        if found is not None:
            problems.append(
                f"{found[0]} non-finite radiance values in camera {a} light {b}, the first at "
                f"sample {found[1][0]}"
            )
        digests.append(slab_digest(values))
    recorded = group.attrs.get("radiance_digest")
    if unreadable:
        digest = "not checked"
    elif recorded is None:
        digest = "not recorded"
    elif radiance_digest(digests) == recorded:
        digest = "matches"
    else:
        digest = "differs"
        problems.append(
            "the radiance differs from what was written (its digest does not match the one "
            "recorded): a chunk was altered or replaced"
        )
    return StoreCheck(path, (s, t, p), len(digests), digest, tuple(problems))
