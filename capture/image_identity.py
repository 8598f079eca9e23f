"""An image's identity written into its own file: which dataset, which image, at which pose.

A record binds a file to an image by its SHA-256, but the record is JSON beside the file: a
script that swaps two images and writes their new checksums into the manifest and the journal
(or two records that name each other's files) leaves a dataset whose every checksum agrees and
whose poses belong to other pictures. So the dataset writes the image's identity into the image
itself, where re-writing checksums does not reach: the dataset's id, the image's key, its
exposure and its commanded and measured poses, as JSON in a PNG ``tEXt`` chunk (keyword
:data:`KEYWORD`) placed right after the header. Image readers skip such chunks; ``verify``
reads it back and compares it with the record.

Only PNG files carry one (what the simulated rig and the 8- and 16-bit cameras store). A file
the camera wrote (RAW, DNG) or a float TIFF is stored as it is: its pose is bound by the
records alone, which ``verify`` notes. See ``docs/dataset.md``.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from capture.journal import ImageKey, parse_json
from core.errors import DatasetError, InputError

__all__ = [
    "IDENTITY_FIELDS",
    "KEYWORD",
    "identity_problem",
    "is_png",
    "read_identity",
    "strip_identity",
    "with_identity",
]

#: The ``tEXt`` keyword of the identity chunk.
KEYWORD = b"rig-capture-identity"
#: What the identity holds: the dataset's id (None in a dataset made before ids), the image's
#: key, its exposure and its poses, exactly as its record states them.
IDENTITY_FIELDS = (
    "dataset_id",
    "kind",
    "camera_index",
    "light_index",
    "exposure_index",
    "exposure_ms",
    "commanded_pose",
    "measured_pose",
)

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: An identity is a few hundred bytes; a chunk claiming more is not one this tool wrote.
_MAX_TEXT = 64 * 1024
#: Chunks looked at before the image data; ours comes right after the header.
_MAX_CHUNKS = 64


def is_png(data: bytes) -> bool:
    """Whether ``data`` starts like a PNG file."""
    return data.startswith(_SIGNATURE)


def _chunk(kind: bytes, body: bytes) -> bytes:
    crc = zlib.crc32(kind + body) & 0xFFFFFFFF
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def _chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """The ``(type, body)`` of every chunk of a PNG (CRCs not checked)."""
    chunks: list[tuple[bytes, bytes]] = []
    offset = len(_SIGNATURE)
    while offset + 8 <= len(data):
        (length,) = struct.unpack(">I", data[offset : offset + 4])
        kind = data[offset + 4 : offset + 8]
        chunks.append((kind, data[offset + 8 : offset + 8 + length]))
        offset += 12 + length
    return chunks


def _is_identity(kind: bytes, body: bytes) -> bool:
    return kind == b"tEXt" and body.startswith(KEYWORD + b"\0")


def strip_identity(data: bytes) -> bytes:
    """A PNG's bytes without its identity chunk (other bytes unchanged); others as they are."""
    if not is_png(data):
        return data
    kept = [_chunk(kind, body) for kind, body in _chunks(data) if not _is_identity(kind, body)]
    return _SIGNATURE + b"".join(kept)


def with_identity(data: bytes, identity: Mapping[str, Any]) -> bytes:
    """A PNG's bytes with ``identity`` written after its header (replacing any there).

    Parameters
    ----------
    data : bytes
        A PNG file; anything else is returned unchanged (it cannot carry an identity).
    identity : mapping
        :data:`IDENTITY_FIELDS` and their values, plain JSON.

    Returns
    -------
    bytes
    """
    if not is_png(data):
        return data
    # ASCII JSON: tEXt holds Latin-1, and sorted keys give the same bytes for the same identity.
    text = json.dumps(dict(identity), sort_keys=True, separators=(",", ":"), allow_nan=False)
    body = KEYWORD + b"\0" + text.encode("ascii")
    chunks = _chunks(strip_identity(data))
    if not chunks or chunks[0][0] != b"IHDR":
        raise InputError("the PNG has no header chunk; it cannot carry an identity")
    out = [_chunk(*chunks[0]), _chunk(b"tEXt", body), *(_chunk(*c) for c in chunks[1:])]
    return _SIGNATURE + b"".join(out)


def read_identity(path: Path) -> dict[str, Any] | None:
    """The identity written into an image file, or None when it carries none.

    Parameters
    ----------
    path : Path
        The image file. Only a PNG can carry one; only the chunks before the image data are
        read.

    Returns
    -------
    dict or None

    Raises
    ------
    DatasetError
        The identity chunk is damaged (its CRC, or not a JSON object of
        :data:`IDENTITY_FIELDS`), naming the file.
    """
    with open(path, "rb") as handle:
        if handle.read(len(_SIGNATURE)) != _SIGNATURE:
            return None
        for _ in range(_MAX_CHUNKS):
            head = handle.read(8)
            if len(head) < 8:
                return None
            (length,) = struct.unpack(">I", head[:4])
            kind = head[4:]
            if kind in (b"IDAT", b"IEND"):
                return None
            if kind != b"tEXt" or length > _MAX_TEXT:
                handle.seek(length + 4, 1)
                continue
            body, crc = handle.read(length), handle.read(4)
            if not body.startswith(KEYWORD + b"\0"):
                continue
            if struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF) != crc:
                raise DatasetError(f"{path}: the identity written into the image is damaged")
            return _parse(body[len(KEYWORD) + 1 :], path)
    return None


def _parse(text: bytes, path: Path) -> dict[str, Any]:
    try:
        identity = parse_json(text.decode("ascii"), f"{path}: the identity in the image")
    except ValueError:
        identity = None
    if not isinstance(identity, dict) or set(identity) != set(IDENTITY_FIELDS):
        raise DatasetError(
            f"{path}: the identity written into the image is not one this tool wrote"
        )
    return identity


def identity_problem(
    identity: Mapping[str, Any], record: Mapping[str, Any], dataset_id: str | None
) -> str:
    """How an image's own identity disagrees with its record and dataset ("" if it agrees).

    Parameters
    ----------
    identity : mapping
        What :func:`read_identity` returned.
    record : mapping
        The record, as ``ImageRecord.to_dict()``.
    dataset_id : str or None
        The dataset's id (None in a dataset made before ids).

    Returns
    -------
    str
        The first disagreement, in words: another dataset's image, another image of this
        dataset, or a pose or exposure the record states otherwise.
    """
    if identity["dataset_id"] != dataset_id:
        return (
            f"an image of another dataset (dataset id {identity['dataset_id']}), not of this "
            f"one (dataset id {dataset_id})"
        )
    try:
        own = ImageKey.from_record(identity)
    except InputError as error:
        return f"the identity written into the image is not one this tool wrote ({error})"
    key = ImageKey.from_record(record)
    if own != key:
        return (
            f"holds the image of {own} (the identity written into it), not of {key}: images "
            "swapped or renamed"
        )
    for name in ("exposure_ms", "commanded_pose", "measured_pose"):
        if identity[name] != record[name]:
            return (
                f"was taken with {name} {identity[name]}, the record says {record[name]}: the "
                "record was edited"
            )
    return ""
