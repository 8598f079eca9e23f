"""Reading a field store's arrays so that damage is an error, never data.

Zarr reads a chunk that is not there as the array's fill value, and a truncated chunk as a
codec exception deep in the decompressor: neither says which store or chunk is damaged, and
the first one silently turns a lost image into black radiance. :mod:`core.field_store` reads
through these functions: a missing chunk, a chunk that does not decode, and a non-finite
value are each a :class:`~core.errors.DatasetError` naming the store, the chunk's file and
(for values) the count and the first location.

Before any of that, :func:`open_array` holds an array's metadata (its ``zarr.json``) to the
layout (:data:`core.store.schema.ARRAYS`): a shape with a negative size, chunks of another
rank, a dtype the store never holds (float32 edited to int32 reads the same bytes as other
numbers) are named with the store, the array and the value, not in zarr's words (" `chunk_shape`
and `shape` need to have the same number of dimensions").

Stores are local directories (zarr's ``LocalStore``); a chunk's file is
``STORE/ARRAY/<chunk key>``, the key as the array's metadata encodes it (``c/s/t/0/0``).
"""

from __future__ import annotations

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
from core.progress import progress_bar
from core.store.attributes import direction_problem, read_attributes
from core.store.digests import (
    REBUILD,
    array_document,
    binding_problems,
    combined_digest,
    read_record,
    slab_digest,
    unbound_note,
)
from core.store.schema import ARRAYS

__all__ = [
    "CHUNK_MEANING",
    "StoreCheck",
    "array_names",
    "check_store",
    "chunk_file",
    "metadata_problem",
    "missing_chunks",
    "non_finite",
    "open_array",
    "open_arrays",
    "radiance_digest",
    "read_checked",
    "require_complete",
    "slab_digest",
]


# --- an array's metadata ----------------------------------------------------------------------


def array_names(root: Path) -> list[str]:
    """The arrays of the store at ``root``, by their folders.

    Not zarr's listing: it leaves out, with only a warning, an array whose metadata it cannot
    parse, and the store would then seem to lack it.
    """
    return sorted(
        folder.name
        for folder in root.iterdir()
        if folder.is_dir() and any((folder / name).is_file() for name in ("zarr.json", ".zarray"))
    )


def _sizes(value: object) -> bool:
    return isinstance(value, list) and all(
        isinstance(n, int) and not isinstance(n, bool) for n in value
    )


def _dtype_name(value: object) -> str:
    try:
        return np.dtype(value).name if isinstance(value, str) else repr(value)
    except TypeError:
        return repr(value)


def metadata_problem(root: Path, name: str) -> str | None:
    """What in array ``name``'s metadata document no field store holds, or None.

    Raises
    ------
    DatasetError
        The document is not readable JSON (named by :func:`core.store.digests.array_document`).
    """
    document = array_document(root, name)
    if document.get("node_type", "array") != "array":
        return f"it is a {document.get('node_type')!r}, not an array"
    shape = document.get("shape")
    grid = document.get("chunk_grid")
    configuration = grid.get("configuration") if isinstance(grid, dict) else None
    chunks = (configuration.get("chunk_shape") if isinstance(configuration, dict)
              else document.get("chunks"))  # fmt: skip
    if shape is None:
        return "it states no shape"
    if not _sizes(shape):
        return f"its shape {shape!r} is not a list of sizes"
    assert isinstance(shape, list)
    if any(n < 0 for n in shape):
        return f"its shape {shape} holds a negative size"
    if not _sizes(chunks):
        return f"its chunk shape {chunks!r} is not a list of sizes"
    assert isinstance(chunks, list)
    if len(chunks) != len(shape):
        return (
            f"its shape {shape} has {len(shape)} dimensions and its chunk shape {chunks} "
            f"{len(chunks)}"
        )
    if any(c < 1 for c in chunks):
        return f"its chunk shape {chunks} holds a size below 1"
    spec = ARRAYS.get(name)
    if spec is None:
        return None
    if len(shape) != spec.rank:
        return f"its shape {shape} has {len(shape)} dimensions; {name} is {spec.shape}"
    dtype = _dtype_name(document.get("data_type", document.get("dtype")))
    if dtype not in spec.dtypes:
        return f"its dtype is {dtype}; a field store holds {name} in {' or '.join(spec.dtypes)}"
    return None


def open_array(root: Path, group: Any, name: str) -> Any:
    """Array ``name`` of the store's ``group``, its metadata held to the layout first.

    Raises
    ------
    DatasetError
        Naming the store, the array, its metadata file and what is wrong there.
    """
    problem = metadata_problem(root, name)
    if problem is None:
        try:
            array = group[name]
        except Exception as error:  # zarr raises several types for metadata it cannot parse
            problem = f"zarr cannot read it ({type(error).__name__}: {error})"
        else:
            if isinstance(array, zarr.Array):
                return array
            problem = "it is not an array"
    raise DatasetError(
        f"{root}: array {name!r} ({name}/zarr.json): {problem}: its metadata was altered; {REBUILD}"
    )


def open_arrays(root: Path, group: Any, names: Iterable[str]) -> dict[str, Any]:
    """The arrays ``names`` (:func:`open_array`), each with all its chunks (or DatasetError)."""
    arrays = {name: open_array(root, group, name) for name in sorted(names)}
    for array in arrays.values():
        require_complete(root, array)
    return arrays


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


def radiance_digest(slab_digests: Iterable[bytes]) -> str:
    """The store's ``radiance_digest``: SHA-256 over the slabs' digests, camera then light order.

    Each slab's is :func:`slab_digest` (SHA-256 of the slab (P, 3) in its storage dtype).
    """
    return combined_digest(slab_digests)


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
    notes : list of str, what the check could not bind (a store written before its writer
        recorded digests of every array and attribute), and what to do
    """

    path: Path
    shape: tuple[int, int, int] | None
    chunks: int
    digest: str
    problems: tuple[str, ...]
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Whether the store is intact."""
        return not self.problems

    def summary(self) -> str:
        """The verdict, then each problem on a line of its own, then each note."""
        if self.shape is None:
            head = f"{self.path}: not a readable field store"
        else:
            s, t, p = self.shape
            head = (
                f"{self.path}: field store of {s} cameras x {t} lights x {p} samples, "
                f"{self.chunks} radiance slabs read, radiance digest {self.digest}"
            )
        verdict = "intact" if self.ok else f"DAMAGED ({len(self.problems)} problems)"
        return "\n".join(
            [f"{head}: {verdict}", *(f"  {line}" for line in self.problems),
             *(f"  note: {line}" for line in self.notes)]
        )  # fmt: skip


def _problem(path: Path, error: DatasetError) -> str:
    return str(error).removeprefix(f"{path}: ")


def _attribute_problems(
    path: Path, attrs: dict[str, Any], shape: tuple[int, int, int], values: dict[str, Any]
) -> list[str]:
    """What :mod:`core.store.attributes` refuses in the store's attributes and directions."""
    problems = []
    try:
        read_attributes(path, attrs, shape)
    except DatasetError as error:
        problems.append(_problem(path, error))
    for name, singular in (("light_directions", "light direction"),
                           ("camera_directions", "camera direction")):  # fmt: skip
        if name in values:
            problem = direction_problem(singular, values[name])
            if problem is not None and np.isfinite(values[name]).all():  # non-finite: said above
                problems.append(problem)
    return problems


def _opened(path: Path) -> tuple[Any, dict[str, Any], list[str]]:
    """The store's group, its arrays that open (by name) and the problems of those that don't.

    Raises
    ------
    DatasetError
        Not a store, or a store without radiance.
    """
    try:
        group: Any = zarr.open_group(str(path), mode="r")
        names = array_names(path)
    except Exception as error:  # zarr raises several types for non-stores
        raise DatasetError(f"cannot open: {error}") from None
    if "radiance" not in names:
        raise DatasetError("the store has no 'radiance' array")
    arrays: dict[str, Any] = {}
    problems = []
    for name in names:
        try:
            arrays[name] = open_array(path, group, name)
        except DatasetError as error:
            problems.append(_problem(path, error))
    return group, arrays, problems


def check_store(path: Path) -> StoreCheck:
    """Read every chunk of the field store at ``path``: present, decodable, finite, digests.

    Every array's metadata is held to the layout, every value read, and every array and
    attribute compared with the digests its writer recorded (:mod:`core.store.digests`).

    Parameters
    ----------
    path : the store's directory
    """
    try:
        group, arrays, problems = _opened(path)
    except DatasetError as error:
        return StoreCheck(path, None, 0, "not checked", (str(error),))
    if "radiance" not in arrays:
        return StoreCheck(path, None, 0, "not checked", tuple(problems))
    radiance = arrays["radiance"]
    incomplete: set[tuple[int, int]] = set()  # slabs with a chunk missing
    values: dict[str, NDArray[Any]] = {}  # the other arrays, read whole
    for name, array in arrays.items():
        missing = missing_chunks(path, array)
        if missing:
            problems.append(_missing_message(path, array, missing))
            if name == "radiance":
                incomplete = {(index[0], index[1]) for index in missing}
        elif name != "radiance":
            try:
                values[name] = read_checked(path, array)
            except DatasetError as error:
                problems.append(_problem(path, error))
                continue
            if values[name].dtype.kind == "f" and (found := non_finite(values[name])):
                problems.append(f"{found[0]} non-finite values in {name!r}, first at {found[1]}")
    s, t, p, _ = radiance.shape
    attrs = dict(group.attrs)
    problems += _attribute_problems(path, attrs, (s, t, p), values)
    digests, unreadable = _radiance_slabs(path, radiance, incomplete, problems)
    digest = _radiance_verdict(path, attrs, None if unreadable else digests, problems)
    try:
        problems += binding_problems(path, attrs, arrays, values)
    except DatasetError as error:
        if _problem(path, error) not in problems:
            problems.append(_problem(path, error))
    note = unbound_note(attrs, arrays, path)
    return StoreCheck(path, (s, t, p), len(digests), digest, tuple(problems),
                      () if note is None else (note,))  # fmt: skip


def _radiance_slabs(
    path: Path,
    radiance: Any,
    incomplete: set[tuple[int, int]],
    problems: list[str],
) -> tuple[list[bytes], bool]:
    """Every slab's digest (camera then light order) and whether any was unreadable.

    Damage and non-finite values are appended to ``problems``.
    """
    s, t = radiance.shape[:2]
    digests: list[bytes] = []
    unreadable = False
    keys = [(a, b) for a in range(s) for b in range(t)]
    for a, b in progress_bar(keys, desc="verify", unit="slab"):
        if (a, b) in incomplete:
            unreadable = True
            continue
        try:
            values = read_checked(path, radiance, (a, b))
        except DatasetError as error:
            problems.append(_problem(path, error))
            unreadable = True
            continue
        found = non_finite(values)
        if found is not None:
            problems.append(
                f"{found[0]} non-finite radiance values in camera {a} light {b}, the first at "
                f"sample {found[1][0]}"
            )
        digests.append(slab_digest(values))
    return digests, unreadable


def _radiance_verdict(
    path: Path, attrs: dict[str, Any], digests: list[bytes] | None, problems: list[str]
) -> str:
    """The radiance digest's verdict ("matches", ...); a difference goes to ``problems``."""
    try:
        record = read_record(path, attrs)
    except DatasetError:  # named with the other bindings
        record = None
    recorded = attrs.get("radiance_digest") if record is None else record.data.get("radiance")
    if digests is None:
        return "not checked"
    if recorded is None:
        return "not recorded"
    if radiance_digest(digests) == recorded:
        return "matches"
    problems.append(
        "the radiance differs from what was written (its digest does not match the one "
        "recorded): a chunk was altered or replaced"
    )
    return "differs"
