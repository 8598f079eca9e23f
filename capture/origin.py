"""Whether a dataset's manifest, journal and images are of one capture.

A dataset's three parts can be mixed up by hand: another dataset's ``journal.jsonl`` copied in
(a resume then took every image again over the files and merged the other capture's records),
another dataset's ``manifest.json``, or a plan edited in the manifest after the images were taken
(a resume took nothing new and said success). :func:`origin_problems` says so, in words that name
the file, the dataset ids and what to do:

- the dataset id: the manifest's ``dataset_id`` is written into every run's start document and
  every image (``capture.image_identity``); when the manifest and the journal disagree, the
  images' own ids say which of the two is the stranger;
- the records: a dataset made before ids (or whose ids agree) whose manifest and journal share
  images but agree on none of their checksums describes two captures;
- the plan: every run's start document holds the plan it ran; the manifest's must be the same.

:meth:`capture.dataset.Dataset.open` refuses such a dataset (``rig process``, ``rig capture
--resume``, ``rig export-lp``), or keeps the problems for ``rig verify`` to report. See
``docs/dataset.md``.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from capture.image_identity import read_identity
from capture.journal import JOURNAL_NAME, ImageKey, JournalContents
from capture.manifest import IMAGES_DIR, MANIFEST_NAME, ImageRecord
from core.errors import DatasetError

__all__ = ["Origin", "origin_problems"]

#: Images whose identity is read to tell whose they are (spread over their names).
_SAMPLE = 32

#: What a person can do about a journal or manifest of another dataset.
_RESTORE = (
    "put back this dataset's own {name} (from a backup, or from the folder it was copied "
    "over from); a resume or a field built now would mix two captures"
)


@dataclass(frozen=True)
class Origin:
    """What :func:`origin_problems` found.

    Attributes
    ----------
    problems : tuple of str, one sentence each, naming the file and what to do
    foreign_journal : bool, the journal is another dataset's (its events are not this one's)
    """

    problems: tuple[str, ...] = ()
    foreign_journal: bool = False


def origin_problems(
    root: Path,
    dataset_id: str | None,
    plan: Mapping[str, Any],
    records: Sequence[ImageRecord],
    journal: JournalContents | None,
) -> Origin:
    """Check that a dataset's manifest, journal and images are of one capture.

    Parameters
    ----------
    root : Path
        The dataset directory.
    dataset_id : str or None
        The manifest's dataset id (None: a dataset made before ids).
    plan : mapping
        The manifest's plan.
    records : sequence of ImageRecord
        The manifest's own records (before the journal's events are replayed over them).
    journal : JournalContents or None
        The journal as read (None: the dataset has none).

    Returns
    -------
    Origin
    """
    images = _image_dataset_ids(root)
    starts = []
    if journal is not None:
        starts = [
            (line, document)
            for line, document in zip(journal.lines, journal.documents, strict=True)
            if document["type"] == "start"
        ]
    if starts:
        problem = _id_problem(root, dataset_id, {d.get("dataset_id") for _, d in starts}, images)
        if problem:
            return Origin((problem,), foreign_journal=True)
    problem = _images_problem(root, dataset_id, images, bool(starts))
    if problem:
        return Origin((problem,), foreign_journal=bool(starts))
    if journal is None or not starts:
        return Origin()
    problem = _records_problem(root, records, journal.documents)
    if problem:
        return Origin((problem,), foreign_journal=True)
    for line, document in starts:
        if document["plan"] != plan:
            return Origin((_plan_problem(root, line, document["plan"], plan),))
    return Origin()


def _id_problem(
    root: Path,
    manifest_id: str | None,
    journal_ids: set[str | None],
    images: Counter[str | None],
) -> str:
    """How the journal's dataset ids disagree with the manifest's ("" when they agree).

    The images' own ids say which of the two files is the stranger.
    """
    if journal_ids == {manifest_id}:
        return ""
    journal, manifest = root / JOURNAL_NAME, root / MANIFEST_NAME
    if len(journal_ids) > 1:
        listed = ", ".join(sorted(str(i) for i in journal_ids))
        return (
            f"{journal} mixes the runs of several datasets (dataset ids {listed}); "
            f"{manifest} is of dataset id {manifest_id}: {_RESTORE.format(name=JOURNAL_NAME)}"
        )
    (journal_id,) = journal_ids
    if journal_id is not None and images and images.most_common(1)[0][0] == journal_id:
        return (
            f"{manifest} belongs to another dataset (dataset id {manifest_id}): {journal} and "
            f"the images are of dataset id {journal_id}: {_RESTORE.format(name=MANIFEST_NAME)}"
        )
    return (
        f"{journal} belongs to another dataset (dataset id {journal_id}): {manifest} is of "
        f"dataset id {manifest_id}: {_RESTORE.format(name=JOURNAL_NAME)}"
    )


def _images_problem(
    root: Path, dataset_id: str | None, images: Counter[str | None], journal: bool
) -> str:
    """Most images carrying another dataset id than the manifest (and the journal agreeing).

    Another dataset's manifest and journal copied over a dataset's own agree with each other,
    but not with the images, each of which carries its dataset's id. A few strays among the
    images are :meth:`Dataset.verify`'s to name one by one.
    """
    if not images:
        return ""
    image_id, count = images.most_common(1)[0]
    looked = sum(images.values())
    if image_id == dataset_id or 2 * count <= looked:
        return ""
    manifest = root / MANIFEST_NAME
    names = f"{manifest} and {root / JOURNAL_NAME}" if journal else str(manifest)
    files = f"{MANIFEST_NAME} and {JOURNAL_NAME}" if journal else MANIFEST_NAME
    verb = "belong" if journal else "belongs"
    return (
        f"{names} {verb} to another dataset (dataset id {dataset_id}): the images are of "
        f"dataset id {image_id} ({count} of the {looked} looked at): "
        f"{_RESTORE.format(name=files)}"
    )


def _records_problem(
    root: Path, records: Sequence[ImageRecord], documents: Sequence[Mapping[str, Any]]
) -> str:
    """Manifest and journal sharing images but agreeing on none of their checksums.

    Every record the executor saves in the manifest was journaled first, so one capture's
    manifest and journal agree on each image they both hold (a re-take adds an event, and the
    earlier one stays). Datasets made before ids are told apart only this way.
    """
    journaled: dict[ImageKey, set[str]] = {}
    for document in documents:
        if document["type"] == "event":
            record = document["record"]
            key = ImageKey.from_record(record)
            journaled.setdefault(key, set()).add(str(record.get("sha256")))
    shared = [record for record in records if record.key in journaled]
    if not shared or any(record.sha256 in journaled[record.key] for record in shared):
        return ""
    return (
        f"{root / MANIFEST_NAME} and {root / JOURNAL_NAME} are of two captures: the {len(shared)} "
        "images both record have other checksums in each, so one of the two files belongs to "
        "another dataset; put back this dataset's own (from a backup, or from the folder it "
        "was copied over from)"
    )


def _plan_problem(root: Path, line: int, ran: object, stated: Mapping[str, Any]) -> str:
    """The manifest's plan differs from the one a run was started with."""
    return (
        f"the plan in {root / MANIFEST_NAME} differs from the plan the dataset was captured "
        f"with ({root / JOURNAL_NAME}, line {line}: {_difference(ran, stated)}): its images "
        "were not taken at the poses it states. Put the plan back as it was captured; to "
        "capture the edited plan, start a new dataset (rig capture --config RIG --plan PLAN "
        "-o NEW)"
    )


def _difference(ran: object, stated: object, where: str = "") -> str:
    """The first place two plain-JSON values differ, with both values."""
    if isinstance(ran, Mapping) and isinstance(stated, Mapping):
        for name in sorted(set(ran) | set(stated), key=str):
            if ran.get(name) != stated.get(name):
                return _difference(ran.get(name), stated.get(name), f"{where}.{name}".lstrip("."))
    if isinstance(ran, list) and isinstance(stated, list) and len(ran) == len(stated):
        for index, (a, b) in enumerate(zip(ran, stated, strict=True)):
            # Into a calibration capture or a list of poses; a pose itself is shown whole.
            nested = isinstance(a, Mapping) or (
                isinstance(a, list) and any(isinstance(v, Mapping | list) for v in a)
            )
            if a != b:
                if nested:
                    return _difference(a, b, f"{where}[{index}]")
                return f"{where}[{index}] was {_shown(a)}, the manifest says {_shown(b)}"
    return f"{where or 'the plan'} was {_shown(ran)}, the manifest says {_shown(stated)}"


def _shown(value: object) -> str:
    """A plan value for people: numbers to 6 significant digits."""
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_shown(v) for v in value) + "]"
    return repr(value) if isinstance(value, str) else str(value)


def _image_dataset_ids(root: Path) -> Counter[str | None]:
    """The dataset ids a sample of the images under ``images/`` carry (those carrying one).

    At most :data:`_SAMPLE` files, spread over the sorted names, and only their first chunks,
    so opening a large dataset stays quick.
    """
    paths = sorted(
        Path(directory, name)
        for directory, _, files in os.walk(root / IMAGES_DIR)
        for name in files
        if not name.startswith(".")  # a crash's temporary files
    )
    found: Counter[str | None] = Counter()
    for path in paths[:: max(1, len(paths) // _SAMPLE)]:
        try:
            identity = read_identity(path)
        except (DatasetError, OSError):
            continue
        if identity is not None:
            found[identity["dataset_id"]] += 1
    return found
