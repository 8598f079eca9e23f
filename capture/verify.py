"""Verifying a dataset's files against its records: the verify report.

:func:`verify_files` checks every record's file (present, a regular file, its size and SHA-256),
lists the planned images no record has, and the files under ``images/`` that no record names,
telling apart the temporary files a crash left behind (``core.atomic``'s names, harmless). It
is what :meth:`capture.dataset.Dataset.verify` returns; see ``docs/dataset.md``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from capture.image_identity import identity_problem, is_png, read_identity
from capture.journal import ImageKey
from capture.manifest import IMAGES_DIR, ImageRecord, file_digest, named_key
from core.errors import DatasetError

__all__ = ["CorruptImage", "VerifyReport", "partial_files", "verify_files"]

# core.atomic's temporary names: ".<stem>.<pid>.partial<suffix>".
_PARTIAL = re.compile(r"\..*\.\d+\.partial(\.[^.]*)?")


@dataclass(frozen=True)
class CorruptImage:
    """A record whose file is present but does not match it; ``reason`` says how."""

    record: ImageRecord
    reason: str


@dataclass(frozen=True)
class VerifyReport:
    """What :meth:`capture.dataset.Dataset.verify` found.

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
    unvouched : records of a journaled dataset that its journal does not vouch for (the journal
        was deleted, emptied or cut short): their files cannot be trusted to be this capture's
    torn_journal_line : the journal's unfinished last line (a crash while writing it), ignored;
        harmless, and the next resume removes it
    origin : the dataset's files that are not of one capture: a journal or a manifest of another
        dataset, a plan edited since the images were taken (``Dataset.open(strict=False)``)
    unbound : records whose file carries no identity of its own (a dataset made before images
        carried one, or a file stored as the camera wrote it): bound by the records alone
    """

    path: Path
    checked: int
    planned_known: bool
    not_taken: tuple[ImageKey, ...] = ()
    missing: tuple[ImageRecord, ...] = ()
    corrupt: tuple[CorruptImage, ...] = ()
    unexpected: tuple[str, ...] = ()
    partials: tuple[str, ...] = ()
    unvouched: tuple[ImageRecord, ...] = ()
    torn_journal_line: int | None = None
    origin: tuple[str, ...] = ()
    unbound: int = 0

    @property
    def complete(self) -> bool:
        """Every planned image has a record whose file is present, intact and journaled."""
        bad = self.not_taken or self.missing or self.corrupt or self.unvouched or self.origin
        return self.planned_known and not bad

    @property
    def ok(self) -> bool:
        """Nothing missing, corrupt, unexpected, not journaled, not taken or of another capture."""
        bad = self.not_taken or self.missing or self.corrupt or self.unexpected or self.unvouched
        return not (bad or self.origin)

    @property
    def retake(self) -> set[ImageKey]:
        """The images a resumed capture must take (again)."""
        bad = [record.key for record in self.missing] + [bad.record.key for bad in self.corrupt]
        return set(self.not_taken) | set(bad)

    def problems(self) -> list[str]:
        """One line per problem, naming the file (or image) concerned."""
        lines = list(self.origin)
        lines += [f"not taken: {key}" for key in self.not_taken]
        lines += [f"missing: {record.file} ({record.key})" for record in self.missing]
        lines += [
            f"corrupt: {bad.record.file} ({bad.record.key}): {bad.reason}" for bad in self.corrupt
        ]
        lines += [f"unexpected: {name} (named by no record)" for name in self.unexpected]
        if self.unvouched:
            lines.append(
                f"not journaled: {len(self.unvouched)} images (first {self.unvouched[0].file}) "
                "have no event in journal.jsonl, which was deleted, emptied or cut short: "
                "restore it from a backup, or capture into a new dataset"
            )
        return lines

    def summary(self) -> str:
        """A paragraph for people: the verdict, then each problem."""
        verdict = "complete and intact" if self.complete and self.ok else "NOT OK"
        if self.ok and not self.planned_known:
            verdict = "intact (completeness unknown: no planned images listed)"
        head = f"{self.path}: {self.checked} images checked, {verdict}"
        notes = [f"leftover temporary file: {name}" for name in self.partials]
        if self.unbound:
            notes.append(
                f"note: {self.unbound} images carry no identity of their own (made before "
                "images carried one, or stored as the camera wrote them): only their records "
                "bind them to their poses, so two of them swapped with their checksums "
                "re-written would not show"
            )
        if self.torn_journal_line is not None:
            notes.append(
                f"journal.jsonl line {self.torn_journal_line}: unfinished last line (a crash), "
                "ignored; rig capture --resume removes it"
            )
        return "\n".join([head, *(f"  {line}" for line in self.problems() + notes)])


def verify_files(
    root: Path,
    records: Sequence[ImageRecord],
    planned: Sequence[ImageKey] | None,
    image_path: Callable[[ImageRecord], Path],
    journaled: set[ImageKey] | None = None,
    dataset_id: str | None = None,
) -> VerifyReport:
    """Check a dataset's records against its files: completeness, integrity, stray files.

    Parameters
    ----------
    root : Path
        The dataset directory.
    records : sequence of ImageRecord
        Its records, one per image.
    planned : sequence of ImageKey or None
        The planned images, or None when the manifest does not list them.
    image_path : callable
        The confined path of a record's file; a :class:`DatasetError` it raises makes the
        record corrupt (its path leads out of the dataset).
    journaled : set of ImageKey, optional
        The images the journal vouches for, when the dataset keeps one (None: not checked).
    dataset_id : str, optional
        The dataset's id: every PNG must carry its identity, of this dataset (None: a dataset
        made before ids, whose images need not carry one).

    Returns
    -------
    VerifyReport
        Names each image not taken, each missing, corrupt or unexpected file.
    """
    missing: list[ImageRecord] = []
    corrupt: list[CorruptImage] = []
    unbound = 0
    for record in records:
        try:
            path = image_path(record)
        except DatasetError as error:
            corrupt.append(CorruptImage(record, str(error)))
            continue
        reason, bound = _file_problem(path, record, dataset_id)
        unbound += not bound and reason != "missing"
        if reason == "missing":
            missing.append(record)
        elif reason:
            corrupt.append(CorruptImage(record, reason))
    named = {record.file for record in records}
    unexpected, partials = _strays(root, named)
    taken = {record.key for record in records}
    not_taken = [] if planned is None else [key for key in planned if key not in taken]
    return VerifyReport(
        path=root,
        checked=len(records),
        planned_known=planned is not None,
        not_taken=tuple(not_taken),
        missing=tuple(missing),
        corrupt=tuple(corrupt),
        unexpected=tuple(unexpected),
        partials=tuple(partials),
        unvouched=()
        if journaled is None
        else tuple(record for record in records if record.key not in journaled),
        unbound=unbound,
    )


def partial_files(root: Path) -> list[str]:
    """The temporary files a crash left in a dataset, in ``images/`` and beside the manifest.

    Parameters
    ----------
    root : Path
        The dataset directory.

    Returns
    -------
    list of str
        Their paths relative to ``root``: those under ``images/`` first (sorted within each
        directory), then those beside the manifest.
    """
    partials = _strays(root, set())[1]
    return partials + [p.name for p in root.iterdir() if _PARTIAL.fullmatch(p.name)]


def _strays(root: Path, named: set[str]) -> tuple[list[str], list[str]]:
    """Files under ``images/`` no record names, split into temporaries and the rest."""
    unexpected: list[str] = []
    partials: list[str] = []
    for directory, subdirectories, files in os.walk(root / IMAGES_DIR):
        base = Path(directory).relative_to(root)
        # A symlinked directory is not walked into (os.walk's default); report it instead.
        links = [name for name in subdirectories if Path(directory, name).is_symlink()]
        for name in sorted(files + links):
            relative = (base / name).as_posix()
            if relative in named:
                continue
            (partials if _PARTIAL.fullmatch(name) else unexpected).append(relative)
    return unexpected, partials


def _file_problem(path: Path, record: ImageRecord, dataset_id: str | None) -> tuple[str, bool]:
    """What is wrong with a record's file, and whether the file carries its own identity.

    The problem is nothing (""), "missing", or how the file differs from the record. The
    identity written into the image comes first: it says whose image a file is when its bytes
    differ too (another dataset's journal or manifest gives every file other checksums).
    """
    if not path.exists():
        return "missing", False
    if not path.is_file():
        return "not a regular file", False
    try:
        identity = read_identity(path)
    except DatasetError as error:
        return str(error), False
    if identity is not None:
        problem = identity_problem(identity, record.to_dict(), dataset_id)
        if problem:
            return problem, True
    elif dataset_id is not None and _starts_png(path):
        # Every PNG this dataset stores was written with its identity.
        return (
            "a PNG without the identity every image of this dataset is written with: not an "
            "image this capture stored"
        ), False
    size = path.stat().st_size
    if size != record.size_bytes:
        return f"size {size} bytes, the record says {record.size_bytes}", identity is not None
    digest, _ = file_digest(path)
    if digest != record.sha256:
        return f"SHA-256 {digest}, the record says {record.sha256}", identity is not None
    named = named_key(record.file)
    if named is not None and named != record.key:
        return (
            f"its name is that of {named}, the record is of {record.key}: records naming each "
            "other's files"
        ), identity is not None
    return "", identity is not None


def _starts_png(path: Path) -> bool:
    with open(path, "rb") as handle:
        return is_png(handle.read(8))
