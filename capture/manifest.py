"""The dataset manifest's format: ``manifest.json``'s schema, its image records and their paths.

``manifest.json`` holds the schema version, the creation time, snapshots of the rig config, the
plan and the calibration, the planned images and one :class:`ImageRecord` per image. This module
says what a valid manifest and a valid record are; :class:`capture.dataset.Dataset` reads and
writes them. Paths in records are relative to the dataset, under ``images/``, in ``/``-separated
canonical form with portable names; an absolute path or one that climbs out with ``..`` is
refused here, a symlink out of the directory by the dataset (it needs the directory). See
``docs/dataset.md``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from capture.journal import ImageKey, is_dataset_id, parse_json
from core.errors import DatasetError, InputError

__all__ = [
    "IMAGES_DIR",
    "IMAGE_EXTENSIONS",
    "MANIFEST_NAME",
    "SCHEMA_VERSION",
    "ImageRecord",
    "check_image_file",
    "check_relative",
    "file_digest",
    "named_key",
    "plain_json",
    "planned_from",
    "read_manifest",
]

#: Version of the manifest layout this module reads and writes.
SCHEMA_VERSION = 1
MANIFEST_NAME = "manifest.json"
IMAGES_DIR = "images"
#: Image file suffixes a record may name (compared case-insensitively).
IMAGE_EXTENSIONS = frozenset({".dng", ".cr2", ".nef", ".tif", ".tiff", ".png", ".exr", ".jpg"})

_MANIFEST_KEYS = (
    "schema_version",
    "created",
    "rig_config",
    "plan",
    "calibration",
    "planned_images",
    "images",
)
#: ``journaled`` (bool): the executor keeps a journal for the dataset, which must vouch for
#: every record. Absent in datasets written without the executor. ``dataset_id`` (a UUID): the
#: dataset's identity, written into every run of its journal and every image it stores, so a
#: journal, a manifest or an image of another dataset shows; absent in datasets made before.
_OPTIONAL_MANIFEST_KEYS = ("journaled", "dataset_id")
#: tests/capture/test_dataset.py spells this list out again on purpose: it pins the format.
_RECORD_KEYS = (
    "kind",
    "camera_index",
    "light_index",
    "exposure_index",
    "exposure_ms",
    "commanded_pose",
    "measured_pose",
    "file",
    "sha256",
    "size_bytes",
)
# Portable names that RTI tools (which split .lp lines on whitespace) and every OS accept.
_SEGMENT = re.compile(r"[A-Za-z0-9_+-][A-Za-z0-9._+-]*")
_SHA256 = re.compile(r"[0-9a-f]{64}")
# The name ImageKey.stem() gives (any zero padding), plus a calibration capture's "_<name>".
_STEM = re.compile(r"(light|dark|calibration)_c(\d+)(?:_l(\d+))?_e(\d+)(?:_[a-z0-9-]+)?")


def check_relative(path: object) -> str:
    """Refuse a dataset path that is not relative, canonical and inside the directory.

    Parameters
    ----------
    path : object
        The candidate path, dataset-relative.

    Returns
    -------
    str
        ``path`` unchanged.

    Raises
    ------
    InputError
        ``path`` is not a non-empty string, uses a backslash or NUL, is absolute, climbs out
        with ``..`` or is not in canonical form.
    """
    if not isinstance(path, str) or not path:
        raise InputError(f"path {path!r} must be a non-empty string")
    if "\\" in path or "\0" in path:
        raise InputError(f"path {path!r} must use '/' separators and no NUL")
    if PurePosixPath(path).is_absolute() or PureWindowsPath(path).anchor:
        raise InputError(f"path {path!r} is absolute; dataset paths are relative to the dataset")
    normal = os.path.normpath(path)
    if normal == ".." or normal.startswith("../"):
        raise InputError(f"path {path!r} leaves the dataset directory")
    if normal != path or path.endswith("/"):
        raise InputError(f"path {path!r} is not canonical (use {normal!r})")
    return path


def check_image_file(path: object) -> str:
    """Refuse a record's file path that is not a portable image name under ``images/``.

    Takes ``path`` and returns it unchanged as :func:`check_relative` does.

    Raises
    ------
    InputError
        As :func:`check_relative`, or the path is not under ``images/``, a segment uses other
        than letters, digits and ``._+-`` or starts with ``.``, or the suffix is not one of
        :data:`IMAGE_EXTENSIONS`.
    """
    file = check_relative(path)
    parts = file.split("/")
    if len(parts) < 2 or parts[0] != IMAGES_DIR:
        raise InputError(f"image path {file!r} is not under {IMAGES_DIR}/")
    for part in parts[1:]:
        if not _SEGMENT.fullmatch(part):
            raise InputError(
                f"image path {file!r}: {part!r} may use only letters, digits and ._+- and may not "
                f"start with '.'"
            )
    if PurePosixPath(file).suffix.lower() not in IMAGE_EXTENSIONS:
        raise InputError(
            f"image path {file!r}: the suffix must be one of {' '.join(sorted(IMAGE_EXTENSIONS))}"
        )
    return file


def named_key(path: str) -> ImageKey | None:
    """The image a file's name says it holds (``light_c000_l012_e0.png``), or None.

    The executor names every file ``ImageKey.stem()`` and its suffix, so a record naming a file
    of another image's name names another image's file. Names of another form (datasets made by
    hand) say nothing.

    Parameters
    ----------
    path : str
        A record's file, dataset-relative.

    Returns
    -------
    ImageKey or None
    """
    match = _STEM.fullmatch(PurePosixPath(path).stem)
    if match is None:
        return None
    kind, camera, light, exposure = match.groups()
    try:
        return ImageKey(kind, int(camera), None if light is None else int(light), int(exposure))
    except InputError:  # e.g. a dark frame's name with a light index: no image's name
        return None


def _check_pose(pose: object, name: str) -> dict[str, float]:
    if not isinstance(pose, Mapping):
        raise InputError(f"{name} must be a mapping of axis angles, got {type(pose).__name__}")
    checked: dict[str, float] = {}
    for key, value in pose.items():
        if not isinstance(key, str) or not key.endswith("_deg"):
            raise InputError(f"{name} key {key!r} must be a name ending in _deg")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"{name}[{key!r}] must be a number of degrees, got {value!r}")
        if value != value or value in (float("inf"), float("-inf")):
            raise InputError(f"{name}[{key!r}] must be finite, got {value}")
        checked[key] = float(value)
    return checked


@dataclass(frozen=True)
class ImageRecord:
    """One image of a dataset, as the manifest and the journal record it.

    Attributes
    ----------
    kind : {"light", "dark", "calibration"}
    camera_index, light_index, exposure_index : int (light_index None for dark frames)
    exposure_ms : float, > 0
    commanded_pose, measured_pose : dict of str to float, axis angles in degrees (keys end in
        ``_deg``, as ``rig.pose.RigPose.to_dict``)
    file : str, path relative to the dataset, under ``images/``
    sha256 : str, 64 lowercase hex digits of the file's bytes
    size_bytes : int
    """

    kind: str
    camera_index: int
    light_index: int | None
    exposure_index: int
    exposure_ms: float
    commanded_pose: dict[str, float]
    measured_pose: dict[str, float]
    file: str
    sha256: str
    size_bytes: int

    def __post_init__(self) -> None:
        ImageKey(self.kind, self.camera_index, self.light_index, self.exposure_index)
        exposure = self.exposure_ms
        if isinstance(exposure, bool) or not isinstance(exposure, int | float):
            raise InputError(f"exposure_ms must be a number, got {exposure!r}")
        if not 0.0 < exposure < float("inf"):
            raise InputError(f"exposure_ms must be positive and finite, got {exposure}")
        # Copies, so a caller's later change to its dicts cannot alter the record.
        object.__setattr__(self, "exposure_ms", float(exposure))
        object.__setattr__(self, "commanded_pose", _check_pose(self.commanded_pose, "commanded"))
        object.__setattr__(self, "measured_pose", _check_pose(self.measured_pose, "measured"))
        check_image_file(self.file)
        if not isinstance(self.sha256, str) or not _SHA256.fullmatch(self.sha256):
            raise InputError(f"sha256 must be 64 lowercase hex digits, got {self.sha256!r}")
        size = self.size_bytes
        if isinstance(size, bool) or not isinstance(size, int) or size < 0:
            raise InputError(f"size_bytes must be a non-negative integer, got {size!r}")

    @property
    def key(self) -> ImageKey:
        """The image's identity (kind and indices)."""
        return ImageKey(self.kind, self.camera_index, self.light_index, self.exposure_index)

    def to_dict(self) -> dict[str, Any]:
        """The record as plain JSON data (the manifest's and the journal's form)."""
        return {name: getattr(self, name) for name in _RECORD_KEYS} | {
            "commanded_pose": dict(self.commanded_pose),
            "measured_pose": dict(self.measured_pose),
        }

    @classmethod
    def from_dict(cls, data: object) -> ImageRecord:
        """Build a record from its dict form; missing or unknown fields are refused."""
        if not isinstance(data, Mapping):
            raise InputError(f"an image record must be an object, got {type(data).__name__}")
        missing = [name for name in _RECORD_KEYS if name not in data]
        unknown = sorted(str(name) for name in data if name not in _RECORD_KEYS)
        if missing or unknown:
            raise InputError(f"image record: missing fields {missing}, unknown fields {unknown}")
        return cls(**{name: data[name] for name in _RECORD_KEYS})


def file_digest(path: Path) -> tuple[str, int]:
    """The SHA-256 (lowercase hex) and size in bytes of a file, as a record stores them.

    Parameters
    ----------
    path : Path
        The file.

    Returns
    -------
    tuple of (str, int)
        ``(sha256, size_bytes)``, both of the one open file.
    """
    with open(path, "rb") as handle:
        digest = hashlib.file_digest(handle, "sha256").hexdigest()
        return digest, os.fstat(handle.fileno()).st_size


def plain_json(value: object, name: str) -> dict[str, Any]:
    """A deep copy of a mapping that the manifest can store (plain JSON, no NaN).

    Parameters
    ----------
    value : object
        The mapping (a rig config, plan or calibration snapshot).
    name : str
        What it is, for the error message.

    Returns
    -------
    dict of str to Any

    Raises
    ------
    InputError
        ``value`` is not a mapping or holds anything JSON cannot (NaN, datetimes from TOML).
    """
    if not isinstance(value, Mapping):
        raise InputError(f"{name} must be a mapping, got {type(value).__name__}")
    try:
        # A round trip both checks (no NaN, no datetimes from TOML) and deep-copies.
        result: dict[str, Any] = json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as error:
        raise InputError(f"{name} is not plain JSON data: {error}") from None
    return result


def read_manifest(manifest: Path) -> dict[str, Any]:
    """Read ``manifest.json`` and check its schema version and its top-level fields.

    Parameters
    ----------
    manifest : Path
        The manifest file.

    Returns
    -------
    dict of str to Any
        The document, with exactly the fields of this schema version (their values unchecked).

    Raises
    ------
    DatasetError
        The file is missing, unreadable or not a JSON object, its schema version is not
        :data:`SCHEMA_VERSION`, or it has missing or unknown fields.
    """
    try:
        text = manifest.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetError(f"{manifest}: missing; {manifest.parent} is not a dataset") from None
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(f"{manifest}: cannot read: {error}") from None
    try:
        document = parse_json(text, str(manifest))
    except json.JSONDecodeError as error:
        raise DatasetError(
            f"{manifest}, line {error.lineno} column {error.colno}: not valid JSON ({error.msg})"
        ) from None
    except ValueError as error:  # a number of more digits than Python converts
        raise DatasetError(f"{manifest}: not valid JSON ({error})") from None
    if not isinstance(document, dict):
        raise DatasetError(f"{manifest}: expected a JSON object, got {type(document).__name__}")
    # The version first: another version may have other fields.
    version = document.get("schema_version")
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        raise DatasetError(
            f"{manifest}: schema version {version!r} is not supported; this program reads "
            f"schema version {SCHEMA_VERSION}"
        )
    missing = [name for name in _MANIFEST_KEYS if name not in document]
    known = (*_MANIFEST_KEYS, *_OPTIONAL_MANIFEST_KEYS)
    unknown = sorted(name for name in document if name not in known)
    if missing or unknown:
        raise DatasetError(f"{manifest}: missing fields {missing}, unknown fields {unknown}")
    if not isinstance(document.get("journaled", False), bool):
        raise DatasetError(f"{manifest}: journaled must be true or false")
    if "dataset_id" in document and not is_dataset_id(document["dataset_id"]):
        raise DatasetError(
            f"{manifest}: dataset_id {document['dataset_id']!r} is not a dataset id (a UUID)"
        )
    return document


def planned_from(data: object, where: str) -> tuple[ImageKey, ...] | None:
    """The manifest's ``planned_images``: the image keys, or None when the plan did not list them.

    Parameters
    ----------
    data : object
        The ``planned_images`` value: null or a list of key objects.
    where : str
        The manifest's name, for error messages.

    Returns
    -------
    tuple of ImageKey or None

    Raises
    ------
    DatasetError
        Not a list or null, a key that is not exactly ``{kind, camera_index, light_index,
        exposure_index}`` or is invalid, or an image listed twice.
    """
    if data is None:
        return None
    if not isinstance(data, list):
        raise DatasetError(f"{where}: planned_images must be a list or null")
    keys: list[ImageKey] = []
    for index, item in enumerate(data):
        try:
            if not isinstance(item, dict) or set(item) != set(ImageKey.__dataclass_fields__):
                raise InputError("expected {kind, camera_index, light_index, exposure_index}")
            keys.append(ImageKey.from_record(item))
        except InputError as error:
            raise DatasetError(f"{where}, planned image {index}: {error}") from None
    if len(set(keys)) != len(keys):
        raise DatasetError(f"{where}: planned_images lists an image twice")
    return tuple(keys)
