"""Binding a field store's arrays and attributes to the digests its writer recorded.

A store is a folder of JSON and chunk files that anything can edit: swap two cameras'
visibility chunks, scale the points, copy a radiance chunk from another store, change a
``zarr.json``'s dtype from float32 to int32 (the same bytes then read as other numbers). Each
edit leaves a store zarr reads without complaint. The writer (:mod:`core.store.writer`)
therefore records, in the group attribute ``digests``, a SHA-256 of

- every array's values (``data``): the radiance over its slabs (the ``radiance_digest``, as
  before), the visibility over its cameras' rows, the other arrays whole, each in its storage
  dtype;
- every array's metadata document (``metadata``): its ``zarr.json`` as parsed, so a shape,
  dtype, chunk grid, codec or attribute edited there is seen;
- every attribute of the group but ``digests`` itself (``attributes``), by name, so one
  altered, added or removed is named.

The digests catch accidents and careless edits, not forgers (whoever edits a store can
recompute them). The radiance array carries the attribute ``digested`` (:data:`DIGESTED_MARK`),
so a store whose ``digests`` attribute was removed is damage, not a store written before
digests were recorded: those have neither, stay readable, and ``rig verify`` says what no
digest binds in them (:func:`unbound_note`). Opening a store checks everything but the
radiance's values (:mod:`core.field_store`); ``rig verify`` checks the radiance too
(:func:`core.store.integrity.check_store`).
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import DatasetError
from core.store.schema import DIGESTED_MARK, DIGESTS_ATTRIBUTE

__all__ = [
    "DIGEST_VERSION",
    "REBUILD",
    "StoreDigests",
    "array_digest",
    "array_document",
    "binding_problems",
    "combined_digest",
    "is_marked",
    "metadata_digests",
    "read_record",
    "require_bound",
    "slab_digest",
    "unbound_note",
]

DIGEST_VERSION = 1

#: What to do with a store that no longer holds what was written.
REBUILD = (
    "rebuild the store from its source (rig process DATASET -o STORE --overwrite, or rig sim "
    "field ... --overwrite) or restore it from a copy"
)

_HEX = re.compile(r"[0-9a-f]{64}")


def slab_digest(values: NDArray[Any]) -> bytes:
    """SHA-256 of one slab or row (a camera's visibility) in its storage dtype."""
    # The array's own buffer, not a copy of it (a 24-megapixel float32 slab is 288 MB).
    return hashlib.sha256(np.ascontiguousarray(values).data).digest()


def combined_digest(digests: Iterable[bytes]) -> str:
    """SHA-256 over a sequence of digests (slabs in camera then light order, or rows)."""
    digest = hashlib.sha256()
    for value in digests:
        digest.update(value)
    return digest.hexdigest()


def array_digest(name: str, values: NDArray[Any]) -> str:
    """The recorded digest of a whole array other than the radiance (read whole).

    The visibility's is over its cameras' rows, as the writer receives them one at a time;
    any other array's is over its values at once.
    """
    if name == "visibility":
        return combined_digest(slab_digest(row) for row in values)
    return hashlib.sha256(np.ascontiguousarray(values).data).hexdigest()


def _text_digest(value: Any) -> str:
    # Sorted keys and no spaces: the same JSON value gives the same digest whichever way a
    # tool wrote its file.
    text = json.dumps(value, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def array_document(root: Path, name: str) -> dict[str, Any]:
    """The metadata of array ``name`` as its files hold it (zarr v3; v2 with its ``.zattrs``).

    Raises
    ------
    DatasetError
        The file is not readable JSON of an object, named.
    """
    folder = root / name
    files = [folder / "zarr.json"] if (folder / "zarr.json").is_file() else [folder / ".zarray"]
    if not (folder / "zarr.json").is_file() and (folder / ".zattrs").is_file():
        files.append(folder / ".zattrs")
    documents = []
    for path in files:
        try:
            document = json.loads(path.read_bytes())
        except (OSError, ValueError, RecursionError) as error:
            raise DatasetError(
                f"{root}: cannot read the metadata of array {name!r} ({path.relative_to(root)}:"
                f" {type(error).__name__}: {error}); {REBUILD}"
            ) from None
        if not isinstance(document, dict):
            raise DatasetError(
                f"{root}: the metadata of array {name!r} ({path.relative_to(root)}) is not a "
                f"JSON object; {REBUILD}"
            )
        documents.append(document)
    if len(documents) == 2:  # zarr v2: the attributes live beside the metadata
        return documents[0] | {"attributes": documents[1]}
    return documents[0]


def is_marked(root: Path) -> bool:
    """Whether the radiance array says its writer recorded digests (:data:`DIGESTED_MARK`)."""
    try:
        attributes = array_document(root, "radiance").get("attributes")
    except DatasetError:
        return False  # unreadable: named where the array is opened
    return isinstance(attributes, dict) and attributes.get(DIGESTED_MARK) is True


def metadata_digests(
    root: Path, attrs: Mapping[str, Any], names: Iterable[str]
) -> tuple[dict[str, str], dict[str, str]]:
    """The digests of the group's attributes (by name) and of the arrays' metadata (by name)."""
    attributes = {key: _text_digest(value) for key, value in attrs.items()
                  if key != DIGESTS_ATTRIBUTE}  # fmt: skip
    arrays = {name: _text_digest(array_document(root, name)) for name in sorted(names)}
    return attributes, arrays


@dataclass(frozen=True)
class StoreDigests:
    """A store's digest record (the ``digests`` attribute).

    Attributes
    ----------
    data : dict, array name -> SHA-256 of its values (the radiance's over its slabs)
    metadata : dict, array name -> SHA-256 of its metadata document
    attributes : dict, attribute name -> SHA-256 of its value
    """

    data: dict[str, str]
    metadata: dict[str, str]
    attributes: dict[str, str]

    def to_attribute(self) -> dict[str, Any]:
        """The record as the store keeps it."""
        return {"version": DIGEST_VERSION, "data": self.data, "metadata": self.metadata,
                "attributes": self.attributes}  # fmt: skip


def _digest_map(value: object) -> dict[str, str] | None:
    if not isinstance(value, Mapping):
        return None
    if not all(isinstance(k, str) and isinstance(v, str) and _HEX.fullmatch(v)
               for k, v in value.items()):  # fmt: skip
        return None
    return dict(value)


def read_record(where: Path, attrs: Mapping[str, Any]) -> StoreDigests | None:
    """The store's digest record, or None when it has none.

    Raises
    ------
    DatasetError
        The attribute is not a record of this version (named with its value).
    """
    value = attrs.get(DIGESTS_ATTRIBUTE)
    if value is None:
        return None
    maps = {}
    if isinstance(value, Mapping) and value.get("version") == DIGEST_VERSION:
        maps = {key: _digest_map(value.get(key)) for key in ("data", "metadata", "attributes")}
    if not maps or any(found is None for found in maps.values()):
        shown = repr(value)
        raise DatasetError(
            f"{where}: attribute {DIGESTS_ATTRIBUTE} is "
            f"{shown if len(shown) <= 60 else shown[:57] + '...'}, expected the writer's "
            f"record (version {DIGEST_VERSION}: data, metadata and attributes, each a map of "
            f"names to SHA-256 digests); the store's metadata was altered: {REBUILD}"
        )
    return StoreDigests(
        data=maps["data"] or {}, metadata=maps["metadata"] or {},
        attributes=maps["attributes"] or {},
    )  # fmt: skip


def _describe_array(root: Path, name: str) -> str:
    document = array_document(root, name)
    grid = document.get("chunk_grid")
    chunks = grid.get("configuration", {}).get("chunk_shape") if isinstance(grid, dict) else None
    dtype = document.get("data_type", document.get("dtype"))
    return (
        f"now shape {document.get('shape')}, dtype {dtype}, chunks "
        f"{chunks if chunks is not None else document.get('chunks')}"
    )


def _compared(
    what: str, recorded: Mapping[str, str], found: Mapping[str, str], changed: Any
) -> list[str]:
    """Names removed, added or changed between the record and the store (``changed(name)``)."""
    problems = []
    for name in sorted(set(recorded) | set(found)):
        if name not in found:
            problems.append(f"{what} {name} was removed after the store was written")
        elif name not in recorded:
            problems.append(f"{what} {name} was added after the store was written")
        elif found[name] != recorded[name]:
            problems.append(changed(name))
    return problems


def binding_problems(
    root: Path,
    attrs: Mapping[str, Any],
    names: Iterable[str],
    values: Mapping[str, NDArray[Any]],
) -> list[str]:
    """What in the store differs from the digests its writer recorded; empty when bound.

    Checks the record's presence (a store marked :data:`DIGESTED_MARK` must have one), every
    attribute, every array's metadata, and the values of the arrays in ``values`` (the
    radiance's are checked over its slabs by :func:`core.store.integrity.check_store`). A
    store without a record and without the mark (written before digests were recorded) has
    no problem here: see :func:`unbound_note`.

    Raises
    ------
    DatasetError
        The record is malformed (see :func:`read_record`).
    """
    record = read_record(root, attrs)
    if record is None:
        if not is_marked(root):
            return []
        return [
            f"attribute {DIGESTS_ATTRIBUTE} was removed (the radiance array says its writer "
            "recorded one): whether the arrays and attributes are the ones written cannot be "
            "told"
        ]
    attributes, metadata = metadata_digests(root, attrs, names)
    problems = _compared(
        "attribute",
        record.attributes,
        attributes,
        lambda name: f"attribute {name} differs from what was written",
    )
    problems += _compared(
        "array", record.metadata, metadata,
        lambda name: f"the metadata of array {name} ({name}/zarr.json) differs from what was "
        f"written ({_describe_array(root, name)})",
    )  # fmt: skip
    for name, array in sorted(values.items()):
        expected = record.data.get(name)
        if expected is not None and array_digest(name, array) != expected:
            problems.append(
                f"the values of {name!r} differ from what was written (their digest does not "
                "match): the array was altered, or its chunks swapped or replaced"
            )
    return problems


def require_bound(
    where: Path,
    attrs: Mapping[str, Any],
    names: Iterable[str],
    values: Mapping[str, NDArray[Any] | None],
) -> None:
    """Raise when :func:`binding_problems` finds any (``values`` None: an array the store lacks).

    Raises
    ------
    DatasetError
        Naming the store and the first three problems, and what to do.
    """
    read = {name: array for name, array in values.items() if array is not None}
    problems = binding_problems(where, attrs, names, read)
    if problems:
        listed = "; ".join(problems[:3]) + ("; ..." if len(problems) > 3 else "")
        raise DatasetError(
            f"{where}: the store was altered after it was written: {listed}; {REBUILD}"
        )


def unbound_note(attrs: Mapping[str, Any], names: Iterable[str], root: Path) -> str | None:
    """What no digest binds in a store written before digests were recorded, and what to do."""
    if DIGESTS_ATTRIBUTE in attrs or is_marked(root):
        return None
    unbound = [name for name in sorted(names)
               if not (name == "radiance" and "radiance_digest" in attrs)]  # fmt: skip
    return (
        f"written before digests were recorded: no digest of {', '.join(unbound)} or its "
        "attributes, so an alteration of them cannot be seen; to bind them, rebuild the store "
        "from its source (rig process DATASET -o STORE --overwrite, or rig sim field ... "
        "--overwrite; a model fit saved beside it is then fitted again)"
    )
