"""A dataset's parts are of one capture: each image carries its identity, the journal its id.

Issue 28: ``rig verify`` called "complete and intact" a dataset whose two images were swapped
and every checksum re-written, and two records naming each other's files; a resume with another
dataset's journal took every image again over the files and merged the other capture's records;
a resume of a dataset whose plan was edited took nothing and said success. Every case here
damages a real simulated capture (the executor on the simulated rig) the way a person or a
careless script would, and checks that the dataset says what it is.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from capture.dataset import Dataset
from capture.grid_plan import grid_plan
from capture.image_identity import read_identity, strip_identity, with_identity
from capture.journal import ImageKey
from capture.plan import SweepPlan
from capture.session import CaptureSession
from core.errors import DatasetError
from core.image_io import encode_lossless, read_linear
from processing.process_dataset import verify_for_processing
from rig.config import RigConfig
from sim.simulated_rig import SimulatedRig, simulated_capture_config

LIGHTS = (ImageKey("light", 1, 0, 0), ImageKey("light", 1, 1, 0))


def _config() -> RigConfig:
    return simulated_capture_config("glossy-sphere", size=24, points=600, speed=40.0)


def _plan() -> SweepPlan:
    return grid_plan(2, 3, exposures_ms=(20.0,), layout="fibonacci")


def _capture(path: Path, plan: SweepPlan | None = None) -> Path:
    plan = plan or _plan()
    config = _config()
    dataset = Dataset.create(
        path, rig_config=config.to_dict(), plan=plan.to_dict(), planned=plan.planned_keys(config)
    )
    with SimulatedRig(config) as simulated, simulated.rig() as rig:
        result = CaptureSession(rig, dataset, plan).run()
    assert result.exit_status == "success", result.reason
    return path


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two captures on one rig: the same file names, other exposures, other dataset ids."""
    root = tmp_path_factory.mktemp("origin")
    other = grid_plan(2, 3, exposures_ms=(30.0,), layout="fibonacci")
    return _capture(root / "ours"), _capture(root / "theirs", other)


@pytest.fixture
def ours(captures: tuple[Path, Path], tmp_path: Path) -> Path:
    """A copy of the first capture, to damage."""
    return Path(shutil.copytree(captures[0], tmp_path / "ours"))


# -- what a careless script does --------------------------------------------------------------


def _documents(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    manifest = json.loads((path / "manifest.json").read_text())
    lines = (path / "journal.jsonl").read_text().splitlines()
    return manifest, [json.loads(line) for line in lines]


def _rewrite(path: Path, change: Callable[[dict[str, Any]], None]) -> None:
    """Apply ``change`` to every record, in the manifest and in the journal's events."""
    manifest, journal = _documents(path)
    for record in manifest["images"]:
        change(record)
    for document in journal:
        if document["type"] == "event":
            change(document["record"])
    (path / "manifest.json").write_text(json.dumps(manifest))
    (path / "journal.jsonl").write_text("".join(json.dumps(d) + "\n" for d in journal))


def _revouch(path: Path) -> None:
    """Write every file's checksum and size into its records, as a 'repair' script would."""

    def vouch(record: dict[str, Any]) -> None:
        data = (path / record["file"]).read_bytes()
        record.update(sha256=hashlib.sha256(data).hexdigest(), size_bytes=len(data))

    _rewrite(path, vouch)


def _file(key: ImageKey) -> str:
    return f"images/{key.stem()}.png"


def _swap_images(path: Path) -> None:
    a, b = (path / _file(key) for key in LIGHTS)
    data_a, data_b = a.read_bytes(), b.read_bytes()
    a.write_bytes(data_b)
    b.write_bytes(data_a)


def _swap_names(path: Path) -> None:
    names = {_file(LIGHTS[0]): _file(LIGHTS[1]), _file(LIGHTS[1]): _file(LIGHTS[0])}
    _rewrite(path, lambda record: record.update(file=names.get(record["file"], record["file"])))


def _as_made_before_ids(path: Path) -> None:
    """The dataset as this program wrote it before datasets had ids (issue 28)."""
    manifest, journal = _documents(path)
    del manifest["dataset_id"]
    for document in journal:
        document.pop("dataset_id", None)
    (path / "manifest.json").write_text(json.dumps(manifest))
    (path / "journal.jsonl").write_text("".join(json.dumps(d) + "\n" for d in journal))
    for image in (path / "images").iterdir():
        image.write_bytes(strip_identity(image.read_bytes()))
    _revouch(path)


# -- an image's identity ----------------------------------------------------------------------


def test_the_identity_travels_with_the_pixels(tmp_path: Path) -> None:
    pixels = np.arange(4 * 5 * 3, dtype=np.uint16).reshape(4, 5, 3) * 997
    _, plain = encode_lossless(pixels)
    identity = {"dataset_id": None, "kind": "dark", "camera_index": 3, "light_index": None,
                "exposure_index": 0, "exposure_ms": 5.0, "commanded_pose": {},
                "measured_pose": {"camera_azimuth_deg": 1.5}}  # fmt: skip
    marked = with_identity(plain, identity)
    assert marked != plain and strip_identity(marked) == plain
    assert with_identity(marked, identity) == marked  # written once, in one place
    (tmp_path / "a.png").write_bytes(marked)
    assert read_identity(tmp_path / "a.png") == identity
    (tmp_path / "b.png").write_bytes(plain)
    assert read_identity(tmp_path / "b.png") is None
    assert np.array_equal(read_linear(tmp_path / "a.png"), read_linear(tmp_path / "b.png"))


def test_a_capture_binds_every_image_to_its_dataset_and_pose(ours: Path) -> None:
    dataset = Dataset.open(ours)
    assert dataset.dataset_id is not None
    _, journal = _documents(ours)
    assert {d["dataset_id"] for d in journal if d["type"] == "start"} == {dataset.dataset_id}
    for record in dataset.records:
        identity = read_identity(dataset.image_path(record))
        assert identity is not None and identity["dataset_id"] == dataset.dataset_id
        assert ImageKey.from_record(identity) == record.key
        assert identity["measured_pose"] == record.measured_pose
    report = dataset.verify()
    assert report.ok and report.complete and report.unbound == 0


# -- damage verify names, and processing refuses ----------------------------------------------


def _swapped_and_revouched(path: Path) -> None:
    _swap_images(path)
    _revouch(path)


def _names_swapped(path: Path) -> None:
    _swap_names(path)
    _revouch(path)


def _pose_edited(path: Path) -> None:
    def edit(record: dict[str, Any]) -> None:
        if record["file"] == _file(LIGHTS[0]):
            record["measured_pose"]["light_azimuth_deg"] += 40.0

    _rewrite(path, edit)


def _stray_of_theirs(path: Path, theirs: Path) -> None:
    shutil.copyfile(theirs / _file(LIGHTS[0]), path / _file(LIGHTS[0]))
    _revouch(path)


DAMAGE: dict[str, tuple[Callable[[Path], None], tuple[str, ...]]] = {
    "two images swapped, checksums re-written": (
        _swapped_and_revouched,
        (f"holds the image of {LIGHTS[1]}", f"not of {LIGHTS[0]}", "swapped or renamed"),
    ),
    "two records naming each other's files": (
        _names_swapped,
        (f"holds the image of {LIGHTS[0]}", f"not of {LIGHTS[1]}", "swapped or renamed"),
    ),
    "a record's pose edited in the manifest and the journal": (
        _pose_edited,
        ("was taken with measured_pose", "the record was edited"),
    ),
}


@pytest.mark.parametrize("damage", list(DAMAGE), ids=list(DAMAGE))
def test_a_record_bound_to_another_image_is_named(ours: Path, damage: str) -> None:
    change, words = DAMAGE[damage]
    assert Dataset.open(ours).verify().ok  # before
    change(ours)
    dataset = Dataset.open(ours)
    report = dataset.verify()
    assert not report.ok and not report.complete
    reasons = {bad.record.file: bad.reason for bad in report.corrupt}
    assert _file(LIGHTS[0]) in reasons
    for text in words:
        assert text in reasons[_file(LIGHTS[0])], reasons
    with pytest.raises(DatasetError, match="corrupt"):
        verify_for_processing(dataset, allow_missing=True)


def test_an_image_of_another_dataset_is_named_by_its_id(
    ours: Path, captures: tuple[Path, Path]
) -> None:
    _stray_of_theirs(ours, captures[1])
    theirs = Dataset.open(captures[1]).dataset_id
    report = Dataset.open(ours).verify()
    (bad,) = report.corrupt
    assert bad.record.file == _file(LIGHTS[0])
    assert f"an image of another dataset (dataset id {theirs})" in bad.reason


# -- another dataset's journal or manifest, an edited plan ------------------------------------


def _foreign(ours: Path, theirs: Path, *names: str) -> tuple[str, str]:
    """Copy another dataset's files over ours; the two dataset ids."""
    mine, other = Dataset.open(ours).dataset_id, Dataset.open(theirs).dataset_id
    assert mine and other and mine != other
    for name in names:
        shutil.copyfile(theirs / name, ours / name)
    return mine, other


@pytest.mark.parametrize(
    ("names", "words"),
    [
        (("journal.jsonl",), "journal.jsonl belongs to another dataset (dataset id {other})"),
        (("manifest.json",), "manifest.json belongs to another dataset (dataset id {other})"),
        (
            ("manifest.json", "journal.jsonl"),
            "journal.jsonl belong to another dataset (dataset id {other}): the images are of "
            "dataset id {mine}",
        ),
    ],
    ids=["journal", "manifest", "both"],
)
def test_a_journal_or_manifest_of_another_dataset_is_named(
    ours: Path, captures: tuple[Path, Path], names: tuple[str, ...], words: str
) -> None:
    before = {p.name: p.read_bytes() for p in (ours / "images").iterdir()}
    mine, other = _foreign(ours, captures[1], *names)
    expected = words.format(mine=mine, other=other)
    with pytest.raises(DatasetError, match="put back this dataset's own") as refused:
        Dataset.open(ours)  # what rig process, rig capture --resume and rig export-lp do
    assert expected in str(refused.value)
    report = Dataset.open(ours, strict=False).verify()  # what rig verify does
    assert not report.ok and expected in report.summary()
    assert "not journaled" not in report.summary()  # not a deleted journal
    assert not any("size" in bad.reason for bad in report.corrupt)  # nor size mismatches
    assert {p.name: p.read_bytes() for p in (ours / "images").iterdir()} == before


def test_a_resume_with_another_datasets_journal_takes_nothing(
    ours: Path, captures: tuple[Path, Path]
) -> None:
    _foreign(ours, captures[1], "journal.jsonl")
    dataset = Dataset.open(ours, strict=False)
    with SimulatedRig(_config()) as simulated, simulated.rig() as rig:
        session = CaptureSession(rig, dataset, _plan())
        with pytest.raises(DatasetError, match="belongs to another dataset"):
            session.run()
        assert not any("G1" in line for line in simulated.gantry.lines)


def test_an_edited_plan_is_refused_naming_what_moved(ours: Path) -> None:
    manifest = json.loads((ours / "manifest.json").read_text())
    manifest["plan"]["lights"][1][0] += 25.0  # a light moved
    (ours / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError) as refused:
        Dataset.open(ours)
    message = str(refused.value)
    assert "differs from the plan the dataset was captured with" in message
    assert "journal.jsonl, line 1: lights[1] was [" in message
    assert "start a new dataset" in message
    assert not Dataset.open(ours, strict=False).verify().ok


# -- datasets made before ids -----------------------------------------------------------------


def test_a_dataset_made_before_ids_verifies_with_a_note_and_resumes_as_it_was(
    ours: Path, caplog: pytest.LogCaptureFixture
) -> None:
    _as_made_before_ids(ours)
    report = Dataset.open(ours, strict=False).verify()
    assert report.ok and report.complete, report.summary()
    assert report.unbound == len(list((ours / "images").iterdir()))
    assert "carry no identity of their own" in report.summary()
    dataset = Dataset.open(ours)
    assert "made before datasets had ids" in caplog.text
    verify_for_processing(dataset, allow_missing=False)
    # A resume re-takes a deleted image; the dataset stays one without ids.
    (ours / _file(LIGHTS[1])).unlink()
    with SimulatedRig(_config()) as simulated, simulated.rig() as rig:
        result = CaptureSession(rig, Dataset.open(ours), _plan()).run()
    assert (result.exit_status, result.taken) == ("success", 1), result.reason
    again = Dataset.open(ours)
    assert again.dataset_id is None and again.verify().ok
    identity = read_identity(ours / _file(LIGHTS[1]))
    assert identity is not None and identity["dataset_id"] is None


def test_a_dataset_made_before_ids_still_shows_records_naming_each_others_files(
    ours: Path,
) -> None:
    _as_made_before_ids(ours)
    _names_swapped(ours)
    reasons = {bad.record.file: bad.reason for bad in Dataset.open(ours).verify().corrupt}
    assert (
        f"its name is that of {LIGHTS[0]}, the record is of {LIGHTS[1]}"
        in reasons[_file(LIGHTS[0])]
    )


def test_a_dataset_made_before_ids_with_another_journal_is_named(
    ours: Path, captures: tuple[Path, Path], tmp_path: Path
) -> None:
    theirs = Path(shutil.copytree(captures[1], tmp_path / "theirs"))
    _as_made_before_ids(ours)
    _as_made_before_ids(theirs)
    shutil.copyfile(theirs / "journal.jsonl", ours / "journal.jsonl")
    with pytest.raises(DatasetError, match="are of two captures"):
        Dataset.open(ours)


def test_a_session_with_another_plan_than_the_datasets_is_refused(ours: Path) -> None:
    other = grid_plan(2, 3, exposures_ms=(30.0,), layout="fibonacci")
    with SimulatedRig(_config()) as simulated, simulated.rig() as rig:
        session = CaptureSession(rig, Dataset.open(ours), other)
        with pytest.raises(DatasetError, match="made with another plan than the one given"):
            session.run()
        assert not any("G1" in line for line in simulated.gantry.lines)
