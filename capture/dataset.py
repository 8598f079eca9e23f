"""The capture dataset on disk: ``manifest.json``, ``journal.jsonl`` and ``images/``.

A dataset is a directory::

    DATASET/
        manifest.json    schema version, rig config snapshot, plan, calibration, planned images,
                         one record per image (see ImageRecord)
        journal.jsonl    append-only run documents (capture.journal): the source of truth for resume
        images/          the images (.dng .cr2 .nef .tif .tiff .png .exr .jpg)

Every file is written atomically (temporary name, fsync, rename; ``core.atomic``), so a file named
by the manifest or the journal is never half-written. Paths in records are relative to the
dataset, under ``images/``, in ``/``-separated canonical form; an absolute path, one that climbs
out with ``..`` or a symlink that leads out of the directory is refused.

Records reach the manifest when :meth:`Dataset.save` rewrites it (the executor does so at each
stop); between saves the journal holds them, and :meth:`Dataset.open` replays the journal's events
over the manifest's records, so a dataset whose writer was killed still lists every image taken.
See ``docs/dataset.md``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from capture.journal import JOURNAL_NAME, ImageKey, Journal, JournalContents, read_journal
from core.atomic import atomic_path, write_json_atomic
from core.errors import DatasetError, InputError

__all__ = [
    "IMAGES_DIR",
    "IMAGE_EXTENSIONS",
    "MANIFEST_NAME",
    "SCHEMA_VERSION",
    "CorruptImage",
    "Dataset",
    "ImageKey",
    "ImageRecord",
    "VerifyReport",
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
# core.atomic's temporary names: ".<stem>.<pid>.partial<suffix>".
_PARTIAL = re.compile(r"\..*\.\d+\.partial(\.[^.]*)?")


def _check_relative(path: object) -> str:
    """Refuse a dataset path that is not relative, canonical and inside the directory."""
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


def _check_image_file(path: object) -> str:
    file = _check_relative(path)
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
        _check_image_file(self.file)
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


@dataclass(frozen=True)
class CorruptImage:
    """A record whose file is present but does not match it; ``reason`` says how."""

    record: ImageRecord
    reason: str


@dataclass(frozen=True)
class VerifyReport:
    """What :meth:`Dataset.verify` found.

    Attributes
    ----------
    path : Path, the dataset directory
    checked : int, records checked
    planned_known : bool, whether the manifest lists the planned images
    not_taken : planned images with no record
    missing : records whose file does not exist
    corrupt : records whose file's size or SHA-256 differs (or is not a regular file)
    unexpected : files under ``images/`` that no record names (dataset-relative)
    partials : temporary files a crash left behind (harmless; ``remove_partials`` deletes them)
    """

    path: Path
    checked: int
    planned_known: bool
    not_taken: tuple[ImageKey, ...] = ()
    missing: tuple[ImageRecord, ...] = ()
    corrupt: tuple[CorruptImage, ...] = ()
    unexpected: tuple[str, ...] = ()
    partials: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        """Every planned image has a record whose file is present and intact."""
        return self.planned_known and not (self.not_taken or self.missing or self.corrupt)

    @property
    def ok(self) -> bool:
        """Nothing missing, corrupt, unexpected or not taken."""
        return not (self.not_taken or self.missing or self.corrupt or self.unexpected)

    @property
    def retake(self) -> set[ImageKey]:
        """The images a resumed capture must take (again)."""
        bad = [record.key for record in self.missing] + [bad.record.key for bad in self.corrupt]
        return set(self.not_taken) | set(bad)

    def problems(self) -> list[str]:
        """One line per problem, naming the file (or image) concerned."""
        lines = [f"not taken: {key}" for key in self.not_taken]
        lines += [f"missing: {record.file} ({record.key})" for record in self.missing]
        lines += [
            f"corrupt: {bad.record.file} ({bad.record.key}): {bad.reason}" for bad in self.corrupt
        ]
        lines += [f"unexpected: {name} (named by no record)" for name in self.unexpected]
        return lines

    def summary(self) -> str:
        """A paragraph for people: the verdict, then each problem."""
        verdict = "complete and intact" if self.complete and self.ok else "NOT OK"
        if self.ok and not self.planned_known:
            verdict = "intact (completeness unknown: no planned images listed)"
        head = f"{self.path}: {self.checked} images checked, {verdict}"
        notes = [f"leftover temporary file: {name}" for name in self.partials]
        return "\n".join([head, *(f"  {line}" for line in self.problems() + notes)])


def _file_digest(path: Path) -> tuple[str, int]:
    with open(path, "rb") as handle:
        digest = hashlib.file_digest(handle, "sha256").hexdigest()
        return digest, os.fstat(handle.fileno()).st_size


def _plain_json(value: object, name: str) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise InputError(f"{name} must be a mapping, got {type(value).__name__}")
    try:
        # A round trip both checks (no NaN, no datetimes from TOML) and deep-copies.
        result: dict[str, Any] = json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as error:
        raise InputError(f"{name} is not plain JSON data: {error}") from None
    return result


class Dataset:
    """A capture dataset directory; make one with :meth:`create` or :meth:`open`."""

    def __init__(
        self,
        path: Path,
        *,
        created: str,
        rig_config: dict[str, Any],
        plan: dict[str, Any],
        calibration: dict[str, Any],
        planned: tuple[ImageKey, ...] | None,
        records: Iterable[ImageRecord] = (),
    ) -> None:
        self.path = path
        self.created = created
        self.rig_config = rig_config
        self.plan = plan
        self.calibration = calibration
        self.planned = planned
        self.journal: JournalContents | None = None
        self._records: dict[ImageKey, ImageRecord] = {}
        self._files: dict[str, ImageKey] = {}
        for record in records:
            self._put(record)

    # -- creation and loading -----------------------------------------------------------------

    @classmethod
    def create(
        cls,
        path: str | os.PathLike[str],
        *,
        rig_config: Mapping[str, Any],
        plan: Mapping[str, Any],
        planned: Iterable[ImageKey] | None = None,
        calibration: Mapping[str, Any] | None = None,
    ) -> Dataset:
        """Make a new dataset directory and write its manifest.

        Parameters
        ----------
        path : the directory; it must not exist or be empty
        rig_config, plan, calibration : plain JSON-able mappings, snapshotted into the manifest
        planned : the images the plan will take, so :meth:`verify` can judge completeness

        Raises
        ------
        InputError
            ``path`` is a file or a non-empty directory, or a mapping is not plain JSON.
        """
        root = Path(path)
        if root.exists() and (not root.is_dir() or any(root.iterdir())):
            raise InputError(
                f"{root}: exists and is not an empty directory; a new dataset needs a fresh "
                f"directory (to continue a capture, resume it instead)"
            )
        keys = None if planned is None else tuple(planned)
        if keys is not None and len(set(keys)) != len(keys):
            raise InputError("planned images contain duplicates")
        dataset = cls(
            root,
            created=datetime.now(UTC).isoformat(timespec="seconds"),
            rig_config=_plain_json(rig_config, "rig_config"),
            plan=_plain_json(plan, "plan"),
            calibration=_plain_json(calibration or {}, "calibration"),
            planned=keys,
        )
        (root / IMAGES_DIR).mkdir(parents=True, exist_ok=True)
        dataset.save()
        return dataset

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> Dataset:
        """Load a dataset: its manifest, then the journal's events replayed over the records.

        Raises
        ------
        DatasetError
            No such directory or manifest; a manifest that is not JSON, has an unknown schema
            version, unknown or missing fields, a bad record, duplicate images or files; a record
            path that is absolute, leaves the directory or is a symlink out of it (the message
            names the manifest, the record and the path); a corrupt journal.
        """
        root = Path(path)
        manifest = root / MANIFEST_NAME
        if not root.is_dir():
            raise DatasetError(f"{root}: no such dataset directory")
        document = _read_manifest(manifest)
        where = str(manifest)
        for name in ("rig_config", "plan", "calibration"):
            if not isinstance(document[name], dict):
                raise DatasetError(f"{where}: {name} must be an object")
        dataset = cls(
            root,
            created=str(document["created"]),
            rig_config=document["rig_config"],
            plan=document["plan"],
            calibration=document["calibration"],
            planned=_planned_from(document["planned_images"], where),
        )
        images = document["images"]
        if not isinstance(images, list):
            raise DatasetError(f"{where}: images must be a list of records")
        for index, data in enumerate(images):
            dataset._add(data, f"{where}, record {index}", replay=False)
        if (root / JOURNAL_NAME).exists():
            contents = read_journal(root / JOURNAL_NAME)
            dataset.journal = contents
            for line, document in zip(contents.lines, contents.documents, strict=True):
                if document["type"] == "event":
                    dataset._add(document["record"], f"{contents.path}, line {line}", replay=True)
        return dataset

    def _add(self, data: object, where: str, *, replay: bool) -> None:
        """Add a record read from a file; ``where`` names the file and the record."""
        file = data.get("file") if isinstance(data, Mapping) else None
        try:
            record = ImageRecord.from_dict(data)
        except InputError as error:
            raise DatasetError(f"{where} (file {file!r}): {error}") from None
        self._confined(record.file, f"{where} ({record.key})")
        owner = self._files.get(record.file)
        if owner is not None and owner != record.key:
            raise DatasetError(f"{where}: file {record.file!r} is already the image of {owner}")
        if record.key in self._records and not replay:
            raise DatasetError(f"{where}: a second record of {record.key}")
        # Replayed events override: a later event of the same image is a re-take.
        self._put(record)

    def _put(self, record: ImageRecord) -> None:
        """Add or replace (a re-take keeps the image's place) a record."""
        previous = self._records.get(record.key)
        if previous is not None:
            del self._files[previous.file]
        self._records[record.key] = record
        self._files[record.file] = record.key

    def save(self) -> None:
        """Rewrite ``manifest.json`` atomically with the current records."""
        write_json_atomic(self.manifest_path, self._manifest())

    def _manifest(self) -> dict[str, Any]:
        planned = None if self.planned is None else [key.to_dict() for key in self.planned]
        return {
            "schema_version": SCHEMA_VERSION,
            "created": self.created,
            "rig_config": self.rig_config,
            "plan": self.plan,
            "calibration": self.calibration,
            "planned_images": planned,
            "images": [record.to_dict() for record in self._records.values()],
        }

    # -- paths --------------------------------------------------------------------------------

    @property
    def manifest_path(self) -> Path:
        """``DATASET/manifest.json``."""
        return self.path / MANIFEST_NAME

    @property
    def journal_path(self) -> Path:
        """``DATASET/journal.jsonl``."""
        return self.path / JOURNAL_NAME

    @property
    def images_path(self) -> Path:
        """``DATASET/images``."""
        return self.path / IMAGES_DIR

    def _confined(self, relative: str, where: str) -> Path:
        try:
            _check_relative(relative)
        except InputError as error:
            raise DatasetError(f"{where}: {error}") from None
        candidate = self.path / relative
        root = self.path.resolve()
        real = candidate.resolve()
        if not real.is_relative_to(root):
            raise DatasetError(
                f"{where}: path {relative!r} is a symlink out of the dataset directory (to {real})"
            )
        return candidate

    def resolve(self, relative: str) -> Path:
        """The path of a dataset-relative name, refusing any that leads out of the directory.

        Raises
        ------
        DatasetError
            ``relative`` is absolute, not canonical, climbs out with ``..`` or passes through a
            symlink that leads outside.
        """
        return self._confined(relative, str(self.path))

    def image_path(self, record: ImageRecord) -> Path:
        """The path of a record's image file (confinement re-checked)."""
        return self._confined(record.file, f"{self.manifest_path}, {record.key}")

    # -- records ------------------------------------------------------------------------------

    @property
    def records(self) -> tuple[ImageRecord, ...]:
        """The image records, in the order first taken."""
        return tuple(self._records.values())

    def get(self, key: ImageKey) -> ImageRecord | None:
        """The record of an image, or None if it was not taken."""
        return self._records.get(key)

    def write_image(
        self,
        name: str,
        data: bytes | Callable[[Path], object],
        *,
        key: ImageKey,
        exposure_ms: float,
        commanded_pose: Mapping[str, float],
        measured_pose: Mapping[str, float],
    ) -> ImageRecord:
        """Write an image file atomically and record it (replacing any earlier take).

        Parameters
        ----------
        name : str, the file name inside ``images/`` (e.g. ``key.stem() + ".dng"``)
        data : bytes, or a writer called with a temporary path (same suffix) to write the file to
        key : the image's identity
        exposure_ms, commanded_pose, measured_pose : as in :class:`ImageRecord`

        Returns
        -------
        ImageRecord
            With the SHA-256 and size of the bytes written. The record is in memory: the executor
            journals it (:meth:`capture.journal.Journal.event`) and :meth:`save` writes it to the
            manifest.

        Raises
        ------
        InputError
            A bad name, pose or exposure, or a name that another image already uses; nothing is
            written.
        DatasetError
            The writer did not create the file. Whatever the writer raises propagates; in every
            failure no file is left under the final name (an earlier take stays as it was).
        """
        draft = ImageRecord(
            **key.to_dict(),
            exposure_ms=exposure_ms,
            commanded_pose=dict(commanded_pose),
            measured_pose=dict(measured_pose),
            file=_check_image_file(f"{IMAGES_DIR}/{name}"),
            sha256="0" * 64,
            size_bytes=0,
        )
        owner = self._files.get(draft.file)
        if owner is not None and owner != key:
            raise InputError(f"{draft.file} is already the image of {owner}")
        target = self._confined(draft.file, str(self.path))
        with atomic_path(target) as temporary:
            if isinstance(data, bytes | bytearray | memoryview):
                payload = bytes(data)
                temporary.write_bytes(payload)
                digest, size = hashlib.sha256(payload).hexdigest(), len(payload)
            else:
                data(temporary)
                if not temporary.is_file():
                    raise DatasetError(f"{target}: the image writer did not create the file")
                digest, size = _file_digest(temporary)
        record = replace(draft, sha256=digest, size_bytes=size)
        self._put(record)
        return record

    def set_calibration(self, calibration: Mapping[str, Any]) -> None:
        """Replace the calibration (plain JSON data); :meth:`save` writes it."""
        self.calibration = _plain_json(calibration, "calibration")

    def open_journal(self) -> Journal:
        """The dataset's journal, opened for appending (an unfinished last line is cut off)."""
        return Journal(self.journal_path)

    # -- integrity ----------------------------------------------------------------------------

    def verify(self) -> VerifyReport:
        """Check completeness and integrity: every file's size and SHA-256, and stray files.

        Returns
        -------
        VerifyReport
            Names each image not taken, each missing, corrupt or unexpected file.
        """
        missing: list[ImageRecord] = []
        corrupt: list[CorruptImage] = []
        for record in self._records.values():
            try:
                path = self.image_path(record)
            except DatasetError as error:
                corrupt.append(CorruptImage(record, str(error)))
                continue
            reason = _file_problem(path, record)
            if reason == "missing":
                missing.append(record)
            elif reason:
                corrupt.append(CorruptImage(record, reason))
        named = {record.file for record in self._records.values()}
        unexpected, partials = self._strays(named)
        not_taken = (
            []
            if self.planned is None
            else [key for key in self.planned if key not in self._records]
        )
        return VerifyReport(
            path=self.path,
            checked=len(self._records),
            planned_known=self.planned is not None,
            not_taken=tuple(not_taken),
            missing=tuple(missing),
            corrupt=tuple(corrupt),
            unexpected=tuple(unexpected),
            partials=tuple(partials),
        )

    def _strays(self, named: set[str]) -> tuple[list[str], list[str]]:
        """Files under ``images/`` no record names, split into temporaries and the rest."""
        unexpected: list[str] = []
        partials: list[str] = []
        for directory, subdirectories, files in os.walk(self.images_path):
            base = Path(directory).relative_to(self.path)
            # A symlinked directory is not walked into (os.walk's default); report it instead.
            links = [name for name in subdirectories if Path(directory, name).is_symlink()]
            for name in sorted(files + links):
                relative = (base / name).as_posix()
                if relative in named:
                    continue
                (partials if _PARTIAL.fullmatch(name) else unexpected).append(relative)
        return unexpected, partials

    def remove_partials(self) -> list[str]:
        """Delete the temporary files a crash left (in ``images/`` and beside the manifest)."""
        removed = self._strays(set())[1]
        removed += [p.name for p in self.path.iterdir() if _PARTIAL.fullmatch(p.name)]
        for relative in removed:
            (self.path / relative).unlink(missing_ok=True)
        return removed


def _file_problem(path: Path, record: ImageRecord) -> str:
    """What is wrong with a record's file: nothing (""), "missing", or how it differs."""
    if not path.exists():
        return "missing"
    if not path.is_file():
        return "not a regular file"
    size = path.stat().st_size
    if size != record.size_bytes:
        return f"size {size} bytes, the record says {record.size_bytes}"
    digest, _ = _file_digest(path)
    if digest != record.sha256:
        return f"SHA-256 {digest}, the record says {record.sha256}"
    return ""


def _read_manifest(manifest: Path) -> dict[str, Any]:
    try:
        text = manifest.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetError(f"{manifest}: missing; {manifest.parent} is not a dataset") from None
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(f"{manifest}: cannot read: {error}") from None
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise DatasetError(
            f"{manifest}, line {error.lineno} column {error.colno}: not valid JSON ({error.msg})"
        ) from None
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
    unknown = sorted(name for name in document if name not in _MANIFEST_KEYS)
    if missing or unknown:
        raise DatasetError(f"{manifest}: missing fields {missing}, unknown fields {unknown}")
    return document


def _planned_from(data: object, where: str) -> tuple[ImageKey, ...] | None:
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
