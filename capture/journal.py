"""Over 500 lines because the documents, their reader and the writer stay together, in step.

The capture journal: ``journal.jsonl``, append-only run documents in the bluesky manner.

Each line is one JSON object, a *document*:

- ``start``: one per run (a first run or a resumed one): ``uid``, ``time``, ``plan`` (a summary),
  ``rig_config_digest`` (see :func:`config_digest`), ``resumed_from`` (the previous run's uid or
  None), ``journal_version`` and ``dataset_id`` (the manifest's, binding the run to its dataset;
  absent in datasets made before datasets had ids).
- ``event``: one per completed image: ``uid``, ``run_start``, ``seq_num``, ``time``,
  ``time_start``/``time_end`` (the exposure, epoch seconds) and ``record`` (the image record of
  ``capture.manifest``: indices, kind, commanded and measured pose, exposure, file, SHA-256, size).
- ``stop``: ``uid``, ``run_start``, ``time``, ``exit_status`` (success, paused, aborted, failed),
  ``reason``, ``num_events`` and ``counts``.

Every line is written with one ``write`` on an ``O_APPEND`` descriptor and fsynced before the call
returns, so a process killed at any instant leaves at most one truncated LAST line. A line counts
only once its newline is on disk: a last line without one, or one that is not JSON, is the mark of
a crash and is ignored (its image is re-taken); a bad line anywhere else is corruption and an error.
The journal, not the manifest, is the source of truth for resume (:func:`completed_images`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import time
import uuid
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Protocol, get_args

from core.errors import DatasetError, InputError

__all__ = [
    "EXIT_STATUSES",
    "IMAGE_KINDS",
    "JOURNAL_NAME",
    "JOURNAL_VERSION",
    "ExitStatus",
    "ImageKey",
    "ImageKind",
    "Journal",
    "JournalContents",
    "RunStatus",
    "RunSummary",
    "TruncatedLine",
    "capture_identity",
    "completed_images",
    "config_digest",
    "is_dataset_id",
    "last_run_status",
    "new_dataset_id",
    "parse_json",
    "read_journal",
    "runs",
]

log = logging.getLogger(__name__)

#: File name of the journal inside a dataset directory.
JOURNAL_NAME = "journal.jsonl"
#: Version of the document layout, written in every start document.
JOURNAL_VERSION = 1

#: Deepest nesting a dataset's JSON may hold (a manifest's records, rig config and plan are
#: a few levels deep): a deeper document is not one this tool wrote, and would break the code
#: that walks it (Python's recursion limit) well after it was read.
MAX_JSON_DEPTH = 32

ImageKind = Literal["light", "dark", "calibration"]
IMAGE_KINDS: tuple[str, ...] = get_args(ImageKind)
ExitStatus = Literal["success", "paused", "aborted", "failed"]
EXIT_STATUSES: tuple[str, ...] = get_args(ExitStatus)
_DATASET_ID = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")
#: A run's status: its stop document's exit status, or "interrupted" when it has none (killed).
RunStatus = Literal["success", "paused", "aborted", "failed", "interrupted"]

_DOCUMENT_KEYS = {
    "start": {
        "type",
        "uid",
        "time",
        "plan",
        "rig_config_digest",
        "resumed_from",
        "journal_version",
    },
    "event": {"type", "uid", "run_start", "seq_num", "time", "time_start", "time_end", "record"},
    "stop": {"type", "uid", "run_start", "time", "exit_status", "reason", "num_events", "counts"},
}
#: Fields a document may lack: a start's ``dataset_id`` (the manifest's, binding the journal to
#: its dataset) is absent in journals written before datasets had ids, and in their runs since.
_OPTIONAL_KEYS = {"start": {"dataset_id"}, "event": set[str](), "stop": set[str]()}


def _index(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError(f"{name} must be a non-negative integer, got {value!r}")
    return value


@dataclass(frozen=True)
class ImageKey:
    """The identity of one planned image: what a plan asks for and a journal event completes.

    Attributes
    ----------
    kind : {"light", "dark", "calibration"}
    camera_index : int, >= 0, the camera pose
    light_index : int >= 0, or None for images without a light position (dark frames)
    exposure_index : int, >= 0, the place in the exposure bracket
    """

    kind: str
    camera_index: int
    light_index: int | None
    exposure_index: int = 0

    def __post_init__(self) -> None:
        if self.kind not in IMAGE_KINDS:
            raise InputError(
                f"image kind must be one of {', '.join(IMAGE_KINDS)}, got {self.kind!r}"
            )
        _index(self.camera_index, "camera_index")
        _index(self.exposure_index, "exposure_index")
        if self.light_index is not None:
            _index(self.light_index, "light_index")
        if self.kind == "light" and self.light_index is None:
            raise InputError("a light image needs a light_index")
        if self.kind == "dark" and self.light_index is not None:
            raise InputError(f"a dark frame has no light_index, got {self.light_index}")

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> ImageKey:
        """The key of an image record (a mapping with the four key fields)."""
        try:
            return cls(
                record["kind"],
                record["camera_index"],
                record["light_index"],
                record["exposure_index"],
            )
        except KeyError as missing:
            raise InputError(f"image record has no {missing}") from None

    def to_dict(self) -> dict[str, Any]:
        """``{"kind", "camera_index", "light_index", "exposure_index"}``."""
        return {
            "kind": self.kind,
            "camera_index": self.camera_index,
            "light_index": self.light_index,
            "exposure_index": self.exposure_index,
        }

    def order(self) -> tuple[str, int, int, int]:
        """A sort key (``light_index`` None sorts first)."""
        light = -1 if self.light_index is None else self.light_index
        return (self.kind, self.camera_index, light, self.exposure_index)

    def stem(self) -> str:
        """A file stem naming the image, e.g. ``light_c000_l012_e0``."""
        light = "" if self.light_index is None else f"_l{self.light_index:03d}"
        return f"{self.kind}_c{self.camera_index:03d}{light}_e{self.exposure_index}"

    def __str__(self) -> str:
        light = "" if self.light_index is None else f" light {self.light_index}"
        return f"{self.kind} camera {self.camera_index}{light} exposure {self.exposure_index}"


def new_dataset_id() -> str:
    """A fresh dataset id (a random UUID), written into the manifest, the runs and the images."""
    return str(uuid.uuid4())


def is_dataset_id(value: object) -> bool:
    """Whether ``value`` has a dataset id's form (a UUID's 36 characters)."""
    return isinstance(value, str) and _DATASET_ID.fullmatch(value) is not None


def capture_identity(config: Mapping[str, Any]) -> dict[str, Any]:
    """What of a rig config a dataset's images depend on: all of it but its serial ports.

    Ports move between sessions (USB devices renumber, an emulator's pty) without changing a
    single image; an axis, the camera, the light or the scene do.
    """
    identity = {key: value for key, value in config.items() if key != "name"}
    for section in ("servos", "gantry"):
        if isinstance(identity.get(section), Mapping):
            identity[section] = {
                k: v for k, v in identity[section].items() if k not in ("port", "baudrate")
            }
    return identity


def config_digest(config: Mapping[str, Any]) -> str:
    """``"sha256:<hex>"`` of a rig config's canonical JSON (sorted keys, no spaces).

    A resumed run compares it with the first run's to notice a changed rig.
    """
    try:
        text = json.dumps(config, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as error:
        raise InputError(f"rig config is not plain JSON data: {error}") from None
    return "sha256:" + hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class TruncatedLine:
    """The uncommitted last line of a journal: the mark of a crash.

    Attributes
    ----------
    line : int, 1-based line number
    offset : int, byte offset where it starts (the committed journal's length)
    text : str, its beginning, for the report
    """

    line: int
    offset: int
    text: str


@dataclass(frozen=True)
class JournalContents:
    """What :func:`read_journal` found.

    Attributes
    ----------
    path : Path
    documents : list of dict, the committed documents in file order
    lines : list of int, the 1-based line of each document
    truncated : TruncatedLine or None, an ignored last line
    """

    path: Path
    documents: list[dict[str, Any]]
    lines: list[int]
    truncated: TruncatedLine | None

    def report(self) -> str:
        """One line for people: how many documents, and any ignored last line."""
        text = f"{self.path}: {len(self.documents)} documents"
        if self.truncated is not None:
            text += (
                f"; line {self.truncated.line} was never completed (a crash) and is ignored: "
                f"{self.truncated.text!r}"
            )
        return text


def _check_document(document: object, where: str, open_run: str | None) -> dict[str, Any]:
    """Validate one document's structure against the run it belongs to; return it."""
    if not isinstance(document, dict):
        raise DatasetError(f"{where}: expected a JSON object, got {type(document).__name__}")
    kind = document.get("type")
    if kind not in _DOCUMENT_KEYS:
        raise DatasetError(f"{where}: unknown document type {kind!r}; expected start/event/stop")
    keys = set(document) - _OPTIONAL_KEYS[kind]
    if keys != _DOCUMENT_KEYS[kind]:
        missing = sorted(_DOCUMENT_KEYS[kind] - keys)
        unknown = sorted(keys - _DOCUMENT_KEYS[kind])
        raise DatasetError(f"{where}: {kind} document: missing {missing}, unknown {unknown}")
    if not isinstance(document["uid"], str) or not document["uid"]:
        raise DatasetError(f"{where}: {kind} document has no uid")
    dataset_id = document.get("dataset_id")
    if dataset_id is not None and not is_dataset_id(dataset_id):
        raise DatasetError(f"{where}: dataset_id {dataset_id!r} is not a dataset id")
    if kind != "start" and document["run_start"] != open_run:
        raise DatasetError(
            f"{where}: {kind} document belongs to run {document['run_start']!r}, but the open run "
            f"is {open_run!r}"
        )
    if kind == "event":
        if not isinstance(document["record"], dict):
            raise DatasetError(f"{where}: event document's record is not an object")
        try:
            ImageKey.from_record(document["record"])
        except InputError as error:
            raise DatasetError(f"{where}: {error}") from None
    if kind == "stop" and document["exit_status"] not in EXIT_STATUSES:
        raise DatasetError(f"{where}: unknown exit status {document['exit_status']!r}")
    return document


def parse_json(text: str | bytes, where: str) -> Any:
    """The JSON document ``text`` of a dataset's file, ``where`` naming the file and line.

    The one parser of the manifest and the journal. A document nested deeper than
    :data:`MAX_JSON_DEPTH` (200,000 brackets exhausted Python's recursion) is a DatasetError
    naming ``where``; text that is not JSON raises ``ValueError`` (a ``JSONDecodeError``, or
    ``UnicodeDecodeError`` for bytes) for the caller to report in its words.
    """
    try:
        document = json.loads(text)
    except RecursionError:
        raise DatasetError(
            f"{where}: JSON nested too deeply to read (more than {MAX_JSON_DEPTH} levels); "
            "this is not a file this tool wrote"
        ) from None
    pending: list[tuple[Any, int]] = [(document, 0)]
    while pending:
        value, depth = pending.pop()
        if not isinstance(value, dict | list):
            continue
        if depth >= MAX_JSON_DEPTH:
            raise DatasetError(
                f"{where}: JSON nested more than {MAX_JSON_DEPTH} levels deep; this is not a "
                "file this tool wrote"
            )
        children = value.values() if isinstance(value, dict) else value
        pending.extend((child, depth + 1) for child in children)
    return document


def read_journal(path: str | os.PathLike[str]) -> JournalContents:
    """Read a journal.

    Parameters
    ----------
    path : path of ``journal.jsonl``

    Returns
    -------
    JournalContents
        The committed documents. A last line without a newline, or that is not JSON, is the
        trace of a crash: it is reported (``truncated``, and a logged warning) and ignored.

    Raises
    ------
    DatasetError
        A missing file; a bad line before the last (named by file and line number); a document
        of unknown type, with missing or unknown fields, or outside its run.
    """
    file = Path(path)
    try:
        raw = file.read_bytes()
    except FileNotFoundError:
        raise DatasetError(f"{file}: no such journal") from None
    except OSError as error:
        raise DatasetError(f"{file}: cannot read the journal: {error}") from None
    chunks = raw.split(b"\n")
    # The element after the last newline is b"" for a complete file, else an unfinished line.
    complete, tail = chunks[:-1], chunks[-1]
    truncated: TruncatedLine | None = None
    if tail:
        truncated = TruncatedLine(len(chunks), len(raw) - len(tail), _preview(tail))
    documents: list[dict[str, Any]] = []
    lines: list[int] = []
    open_run: str | None = None
    offset = 0
    for number, chunk in enumerate(complete, 1):
        where = f"{file}, line {number}"
        try:
            document = parse_json(chunk.decode("utf-8"), where)
        except ValueError as error:  # not JSON, or not UTF-8
            if number == len(complete) and truncated is None:
                truncated = TruncatedLine(number, offset, _preview(chunk))
                break
            raise DatasetError(
                f"{where}: not a JSON document ({error}); the journal is corrupt"
            ) from None
        documents.append(_check_document(document, where, open_run))
        lines.append(number)
        kind = document["type"]
        open_run = document["uid"] if kind == "start" else None if kind == "stop" else open_run
        offset += len(chunk) + 1
    return JournalContents(file, documents, lines, truncated)


def _preview(chunk: bytes) -> str:
    return chunk[:80].decode("utf-8", errors="replace")


@dataclass(frozen=True)
class RunSummary:
    """One run of a journal: its start, its stop (None if it never stopped) and event count."""

    start: dict[str, Any]
    stop: dict[str, Any] | None
    events: int

    @property
    def uid(self) -> str:
        """The run's start uid."""
        return str(self.start["uid"])

    @property
    def status(self) -> RunStatus:
        """The stop document's exit status, or "interrupted" for a run that never stopped."""
        return "interrupted" if self.stop is None else self.stop["exit_status"]


def runs(documents: Iterable[Mapping[str, Any]]) -> list[RunSummary]:
    """The runs of a journal's documents, in order."""
    summaries: list[RunSummary] = []
    for document in documents:
        kind = document["type"]
        if kind == "start":
            summaries.append(RunSummary(dict(document), None, 0))
        elif summaries and document["run_start"] == summaries[-1].uid:
            last = summaries[-1]
            if kind == "event":
                summaries[-1] = RunSummary(last.start, last.stop, last.events + 1)
            else:
                summaries[-1] = RunSummary(last.start, dict(document), last.events)
    return summaries


def last_run_status(documents: Iterable[Mapping[str, Any]]) -> RunStatus | None:
    """Status of the last run ("interrupted" if it never stopped), or None if there is no run."""
    summaries = runs(documents)
    return summaries[-1].status if summaries else None


def completed_images(documents: Iterable[Mapping[str, Any]]) -> set[ImageKey]:
    """The images the journal records as completed, over all runs: what resume need not re-take.

    Resume still re-verifies each completed image's file (SHA-256) and re-takes bad ones.
    """
    return {
        ImageKey.from_record(document["record"])
        for document in documents
        if document["type"] == "event"
    }


class SupportsToDict(Protocol):
    """Anything with ``to_dict()``, such as ``capture.manifest.ImageRecord``."""

    def to_dict(self) -> dict[str, Any]: ...


class Journal:
    """Appends run documents to a journal, each line flushed and fsynced before returning.

    Opening an existing journal validates it and cuts off an unfinished last line (left by a
    crash), so the next document does not land glued to it; ``repaired`` says what was cut.
    One process writes a journal at a time.

    Parameters
    ----------
    path : path of ``journal.jsonl`` (created if missing)
    dataset_id : str, optional
        The dataset's id (its manifest's), written into every start document so the journal
        shows whose it is; None (a dataset made before ids) leaves it out.
    """

    def __init__(self, path: str | os.PathLike[str], *, dataset_id: str | None = None) -> None:
        if dataset_id is not None and not is_dataset_id(dataset_id):
            raise InputError(f"dataset_id {dataset_id!r} is not a dataset id (a UUID)")
        self.dataset_id = dataset_id
        self.path = Path(path)
        self.repaired: TruncatedLine | None = None
        existed = self.path.exists()
        if existed:
            contents = read_journal(self.path)
            self.repaired = contents.truncated
            if contents.truncated is not None:
                os.truncate(self.path, contents.truncated.offset)
                log.warning(
                    "%s, line %d: unfinished last line removed (a crash cut it short): %r",
                    self.path,
                    contents.truncated.line,
                    contents.truncated.text,
                )
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        os.fsync(self._fd)
        if not existed:
            _fsync_directory(self.path.parent)
        self._run: str | None = None
        self._events = 0

    def _check_writable(self, run_open: bool) -> None:
        if self._fd < 0:
            raise InputError(f"{self.path}: the journal is closed")
        if run_open and self._run is None:
            raise InputError(f"{self.path}: no run is open; call start() first")
        if not run_open and self._run is not None:
            raise InputError(f"{self.path}: run {self._run} is still open; stop it first")

    def _append(self, document: dict[str, Any]) -> dict[str, Any]:
        try:
            line = json.dumps(document, separators=(",", ":"), allow_nan=False) + "\n"
        except (TypeError, ValueError) as error:
            raise InputError(
                f"{self.path}: {document['type']} document is not JSON: {error}"
            ) from None
        data = line.encode("utf-8")
        while data:
            written = os.write(self._fd, data)
            data = data[written:]
        os.fsync(self._fd)
        return document

    def start(
        self,
        *,
        plan: Mapping[str, Any],
        rig_config_digest: str,
        resumed_from: str | None = None,
    ) -> dict[str, Any]:
        """Begin a run; returns the start document (its ``uid`` names the run)."""
        self._check_writable(run_open=False)
        document: dict[str, Any] = {
            "type": "start",
            "uid": str(uuid.uuid4()),
            "time": time.time(),
            "plan": dict(plan),
            "rig_config_digest": rig_config_digest,
            "resumed_from": resumed_from,
            "journal_version": JOURNAL_VERSION,
        }
        if self.dataset_id is not None:
            document["dataset_id"] = self.dataset_id
        document = self._append(document)
        self._run, self._events = document["uid"], 0
        return document

    def event(
        self,
        record: Mapping[str, Any] | SupportsToDict,
        *,
        time_start: float,
        time_end: float,
    ) -> dict[str, Any]:
        """Record one completed image (after its file is written); returns the event document.

        Parameters
        ----------
        record : the image record (``ImageRecord`` or its ``to_dict()``)
        time_start, time_end : float, epoch seconds of the exposure
        """
        self._check_writable(run_open=True)
        fields = dict(record) if isinstance(record, Mapping) else record.to_dict()
        ImageKey.from_record(fields)
        document = self._append(
            {
                "type": "event",
                "uid": str(uuid.uuid4()),
                "run_start": self._run,
                "seq_num": self._events + 1,
                "time": time.time(),
                "time_start": float(time_start),
                "time_end": float(time_end),
                "record": fields,
            }
        )
        self._events += 1
        return document

    def stop(
        self,
        exit_status: ExitStatus,
        *,
        reason: str = "",
        counts: Mapping[str, int] | None = None,
    ) -> dict[str, Any]:
        """End the open run with an exit status and reason; returns the stop document."""
        self._check_writable(run_open=True)
        if exit_status not in EXIT_STATUSES:
            raise InputError(
                f"exit status must be one of {', '.join(EXIT_STATUSES)}, got {exit_status!r}"
            )
        document = self._append(
            {
                "type": "stop",
                "uid": str(uuid.uuid4()),
                "run_start": self._run,
                "time": time.time(),
                "exit_status": exit_status,
                "reason": reason,
                "num_events": self._events,
                "counts": dict(counts or {}),
            }
        )
        self._run = None
        return document

    def close(self) -> None:
        """Close the file (an open run stays open on disk: it reads as interrupted)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def __enter__(self) -> Journal:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def _fsync_directory(directory: Path) -> None:
    # A new file's directory entry is durable only once the directory is synced.
    handle = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)
