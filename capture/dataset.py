"""The capture dataset directory: creating and opening it, its paths, writing its images.

A dataset is a directory::

    DATASET/
        manifest.json    schema version, rig config snapshot, plan, calibration, planned images,
                         one record per image (capture.manifest: the format and ImageRecord)
        journal.jsonl    append-only run documents (capture.journal): the source of truth for resume
        images/          the images (.dng .cr2 .nef .tif .tiff .png .exr .jpg)

Every file is written atomically (temporary name, fsync, rename; ``core.atomic``), so a file named
by the manifest or the journal is never half-written. Paths in records are relative to the
dataset, under ``images/``, in ``/``-separated canonical form; an absolute path, one that climbs
out with ``..`` or a symlink that leads out of the directory is refused.

Records reach the manifest when :meth:`Dataset.save` rewrites it (the executor does so at each
stop); between saves the journal holds them, and :meth:`Dataset.open` replays the journal's events
over the manifest's records, so a dataset whose writer was killed still lists every image taken.
:meth:`Dataset.verify` checks the files against the records (``capture.verify``). See
``docs/dataset.md``.
"""

from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from capture.dataset_lock import DatasetLock
from capture.image_identity import IDENTITY_FIELDS, is_png, with_identity
from capture.journal import (
    JOURNAL_NAME,
    ImageKey,
    Journal,
    JournalContents,
    completed_images,
    new_dataset_id,
    read_journal,
)
from capture.manifest import (
    IMAGES_DIR,
    MANIFEST_NAME,
    SCHEMA_VERSION,
    ImageRecord,
    check_image_file,
    check_relative,
    file_digest,
    plain_json,
    planned_from,
    read_manifest,
)
from capture.origin import Origin, origin_problems
from capture.verify import VerifyReport, partial_files, verify_files
from core.atomic import atomic_path, write_json_atomic
from core.errors import DatasetError, InputError

__all__ = ["Dataset", "ImageKey"]

log = logging.getLogger(__name__)


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
        dataset_id: str | None = None,
    ) -> None:
        self.path = path
        self.dataset_id = dataset_id
        """The dataset's id, written into its journal's runs and its images (None: made before
        datasets had ids)."""
        self.origin = Origin()
        """Whether the manifest, journal and images are of one capture (``capture.origin``)."""
        self.created = created
        self.rig_config = rig_config
        self.plan = plan
        self.calibration = calibration
        self.planned = planned
        self.journal: JournalContents | None = None
        self.journaled = False
        """Whether the executor keeps a journal here (then it must vouch for every record)."""
        self.lock = DatasetLock(path)
        """Held while a capture writes into the dataset (one process at a time)."""
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
            rig_config=plain_json(rig_config, "rig_config"),
            plan=plain_json(plan, "plan"),
            calibration=plain_json(calibration or {}, "calibration"),
            planned=keys,
            dataset_id=new_dataset_id(),
        )
        (root / IMAGES_DIR).mkdir(parents=True, exist_ok=True)
        dataset.save()
        return dataset

    @classmethod
    def open(cls, path: str | os.PathLike[str], *, strict: bool = True) -> Dataset:
        """Load a dataset: its manifest, then the journal's events replayed over the records.

        Parameters
        ----------
        path : the dataset directory
        strict : bool
            Refuse a dataset whose manifest, journal and images are not of one capture (a
            journal or a manifest of another dataset, a plan edited after the capture). False
            keeps the problems in :attr:`origin` for :meth:`verify` to report, and does not
            replay another dataset's journal.

        Raises
        ------
        DatasetError
            No such directory or manifest; a manifest that is not JSON, has an unknown schema
            version, unknown or missing fields, a bad record, duplicate images or files; a record
            path that is absolute, leaves the directory or is a symlink out of it (the message
            names the manifest, the record and the path); a corrupt journal; when ``strict``, a
            dataset not of one capture (the message names the file and what to do).
        """
        root = Path(path)
        manifest = root / MANIFEST_NAME
        if not root.is_dir():
            raise DatasetError(f"{root}: no such dataset directory")
        document = read_manifest(manifest)
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
            planned=planned_from(document["planned_images"], where),
            dataset_id=document.get("dataset_id"),
        )
        dataset.journaled = bool(document.get("journaled", False))
        images = document["images"]
        if not isinstance(images, list):
            raise DatasetError(f"{where}: images must be a list of records")
        for index, data in enumerate(images):
            dataset._add(data, f"{where}, record {index}", replay=False)
        contents = None
        if (root / JOURNAL_NAME).exists():
            contents = read_journal(root / JOURNAL_NAME)
            dataset.journal = contents
        dataset.origin = origin_problems(
            root, dataset.dataset_id, dataset.plan, dataset.records, contents
        )
        if strict and dataset.origin.problems:
            raise DatasetError(dataset.origin.problems[0])
        if strict and dataset.dataset_id is None and dataset.records:
            # (rig verify says it in its report instead: it opens with strict=False)
            log.warning(
                "note: %s was made before datasets had ids: its images carry no identity of "
                "their own, so only the records bind them to their poses (rig verify checks "
                "what it can)",
                root,
            )
        if contents is not None and not dataset.origin.foreign_journal:
            # (another capture's records are not this dataset's)
            for line, document in zip(contents.lines, contents.documents, strict=True):
                if document["type"] == "event":
                    where = f"{contents.path}, line {line}"
                    dataset._add(document["record"], where, replay=True)
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
        return (
            {
                "schema_version": SCHEMA_VERSION,
                "created": self.created,
                "rig_config": self.rig_config,
                "plan": self.plan,
                "calibration": self.calibration,
                "planned_images": planned,
                "images": [record.to_dict() for record in self._records.values()],
            }
            | ({"journaled": True} if self.journaled else {})
            | ({} if self.dataset_id is None else {"dataset_id": self.dataset_id})
        )

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

    def refuse_output_in_images(self, output: str | os.PathLike[str], flag: str = "-o") -> None:
        """Refuse to write ``output`` among the captured images (verify would call it foreign).

        Raises
        ------
        InputError
            ``output`` is (or lies inside) the dataset's ``images`` folder.
        """
        images = self.images_path.resolve()
        target = Path(output).resolve()
        if target == images or target.is_relative_to(images):
            raise InputError(
                f"{flag} {output}: inside the dataset's images folder {self.images_path}, which "
                "holds only the captured images (rig verify would report the output as an "
                "unexpected file); write it elsewhere, e.g. beside the dataset"
            )

    def _confined(self, relative: str, where: str) -> Path:
        try:
            check_relative(relative)
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
            With the SHA-256 and size of the file written: a PNG with the image's identity
            written into it (``capture.image_identity``: the dataset id, the key, the exposure and
            the poses), any other file as given. The record is in memory: the executor
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
            file=check_image_file(f"{IMAGES_DIR}/{name}"),
            sha256="0" * 64,
            size_bytes=0,
        )
        owner = self._files.get(draft.file)
        if owner is not None and owner != key:
            raise InputError(f"{draft.file} is already the image of {owner}")
        target = self._confined(draft.file, str(self.path))
        identity = {"dataset_id": self.dataset_id} | {
            name: value for name, value in draft.to_dict().items() if name in IDENTITY_FIELDS
        }
        with atomic_path(target) as temporary:
            if isinstance(data, bytes | bytearray | memoryview):
                payload = with_identity(bytes(data), identity)
                temporary.write_bytes(payload)
                digest, size = hashlib.sha256(payload).hexdigest(), len(payload)
            else:
                data(temporary)
                if not temporary.is_file():
                    raise DatasetError(f"{target}: the image writer did not create the file")
                if _png_file(temporary):
                    temporary.write_bytes(with_identity(temporary.read_bytes(), identity))
                digest, size = file_digest(temporary)
        record = replace(draft, sha256=digest, size_bytes=size)
        self._put(record)
        return record

    def set_calibration(self, calibration: Mapping[str, Any]) -> None:
        """Replace the calibration (plain JSON data); :meth:`save` writes it."""
        self.calibration = plain_json(calibration, "calibration")

    def open_journal(self) -> Journal:
        """The dataset's journal, opened for appending (an unfinished last line is cut off).

        Its runs carry the dataset's id, binding them to this dataset.
        """
        return Journal(self.journal_path, dataset_id=self.dataset_id)

    # -- integrity ----------------------------------------------------------------------------

    def verify(self) -> VerifyReport:
        """Check completeness and integrity: every file's size and SHA-256, and stray files.

        Returns
        -------
        VerifyReport
            Names each image not taken, each missing, corrupt or unexpected file.
        """
        journaled, torn = None, None
        if self.journal_path.exists():  # as it is now (a run may have added to it)
            contents = read_journal(self.journal_path)
            torn = None if contents.truncated is None else contents.truncated.line
            # Another capture's journal vouches for nothing here: the origin problem says so.
            if self.journaled and not self.origin.foreign_journal:
                journaled = completed_images(contents.documents)
        elif self.journaled:
            journaled = set()
        report = verify_files(
            self.path, self.records, self.planned, self.image_path, journaled, self.dataset_id
        )
        return replace(report, torn_journal_line=torn, origin=self.origin.problems)

    def remove_partials(self) -> list[str]:
        """Delete the temporary files a crash left (in ``images/`` and beside the manifest)."""
        removed = partial_files(self.path)
        for relative in removed:
            (self.path / relative).unlink(missing_ok=True)
        return removed


def _png_file(path: Path) -> bool:
    with open(path, "rb") as handle:
        return is_png(handle.read(8))
