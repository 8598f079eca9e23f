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

from capture.journal import ImageKey
from capture.manifest import IMAGES_DIR, ImageRecord, file_digest
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

    @property
    def complete(self) -> bool:
        """Every planned image has a record whose file is present, intact and journaled."""
        bad = self.not_taken or self.missing or self.corrupt or self.unvouched
        return self.planned_known and not bad

    @property
    def ok(self) -> bool:
        """Nothing missing, corrupt, unexpected, not journaled or not taken."""
        bad = self.not_taken or self.missing or self.corrupt or self.unexpected or self.unvouched
        return not bad

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

    Returns
    -------
    VerifyReport
        Names each image not taken, each missing, corrupt or unexpected file.
    """
    missing: list[ImageRecord] = []
    corrupt: list[CorruptImage] = []
    for record in records:
        try:
            path = image_path(record)
        except DatasetError as error:
            corrupt.append(CorruptImage(record, str(error)))
            continue
        reason = _file_problem(path, record)
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


def _file_problem(path: Path, record: ImageRecord) -> str:
    """What is wrong with a record's file: nothing (""), "missing", or how it differs."""
    if not path.exists():
        return "missing"
    if not path.is_file():
        return "not a regular file"
    size = path.stat().st_size
    if size != record.size_bytes:
        return f"size {size} bytes, the record says {record.size_bytes}"
    digest, _ = file_digest(path)
    if digest != record.sha256:
        return f"SHA-256 {digest}, the record says {record.sha256}"
    return ""
