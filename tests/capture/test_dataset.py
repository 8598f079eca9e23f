from __future__ import annotations

import hashlib
import json
import os
import posixpath
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from capture.dataset import Dataset, ImageKey
from capture.manifest import SCHEMA_VERSION, ImageRecord
from core.errors import DatasetError, InputError

POSE = {
    "camera_azimuth_deg": 30.0,
    "camera_inclination_deg": 45.0,
    "light_azimuth_deg": 120.0,
    "light_inclination_deg": 60.0,
    "turntable_deg": 0.0,
}
KEYS = [ImageKey("light", 0, light, 0) for light in range(3)] + [ImageKey("dark", 0, None, 0)]


def _payload(key: ImageKey) -> bytes:
    return hashlib.sha256(key.stem().encode()).digest() * 8


def _take(dataset: Dataset, key: ImageKey) -> ImageRecord:
    measured = POSE | {"camera_azimuth_deg": 30.02}
    return dataset.write_image(
        f"{key.stem()}.png",
        _payload(key),
        key=key,
        exposure_ms=20.0,
        commanded_pose=POSE,
        measured_pose=measured,
    )


def _dataset(path: Path, keys: list[ImageKey] = KEYS, taken: int | None = None) -> Dataset:
    dataset = Dataset.create(path, rig_config={"name": "sim"}, plan={"grid": [1, 3]}, planned=keys)
    for key in keys[:taken]:
        _take(dataset, key)
    dataset.save()
    return dataset


def _rewrite_manifest(dataset: Dataset, change: Callable[[dict[str, Any]], None]) -> None:
    document = json.loads(dataset.manifest_path.read_text())
    change(document)
    dataset.manifest_path.write_text(json.dumps(document))


# -- verify: a table of named cases ------------------------------------------------------------


def _flip_byte(dataset: Dataset) -> None:
    path = dataset.image_path(dataset.records[1])
    data = bytearray(path.read_bytes())
    data[5] ^= 0xFF
    path.write_bytes(bytes(data))


def _truncate(dataset: Dataset) -> None:
    path = dataset.image_path(dataset.records[2])
    path.write_bytes(path.read_bytes()[:-1])


def _delete(dataset: Dataset) -> None:
    dataset.image_path(dataset.records[0]).unlink()


def _stray(dataset: Dataset) -> None:
    (dataset.images_path / "stray.png").write_bytes(b"?")
    (dataset.images_path / "sub").mkdir()
    (dataset.images_path / "sub" / "notes.txt").write_text("hi")


def _partial(dataset: Dataset) -> None:
    (dataset.images_path / ".light_c000_l009_e0.4242.partial.png").write_bytes(b"half")


def _replace_by_directory(dataset: Dataset) -> None:
    path = dataset.image_path(dataset.records[0])
    path.unlink()
    path.mkdir()


@dataclass(frozen=True)
class VerifyCase:
    name: str
    damage: Callable[[Dataset], None] | None = None
    taken: int | None = None
    missing: tuple[str, ...] = ()
    corrupt: tuple[tuple[str, str], ...] = ()  # (file, words in the reason)
    unexpected: tuple[str, ...] = ()
    partials: tuple[str, ...] = ()
    not_taken: tuple[ImageKey, ...] = ()


VERIFY_CASES = [
    VerifyCase("clean"),
    VerifyCase(
        "corrupt image, one byte flipped",
        _flip_byte,
        corrupt=(("images/light_c000_l001_e0.png", "SHA-256"),),
    ),
    VerifyCase(
        "truncated image",
        _truncate,
        corrupt=(("images/light_c000_l002_e0.png", "size 255 bytes, the record says 256"),),
    ),
    VerifyCase("missing image", _delete, missing=("images/light_c000_l000_e0.png",)),
    VerifyCase(
        "image replaced by a directory",
        _replace_by_directory,
        corrupt=(("images/light_c000_l000_e0.png", "not a regular file"),),
    ),
    VerifyCase(
        "unexpected files",
        _stray,
        unexpected=("images/stray.png", "images/sub/notes.txt"),
    ),
    VerifyCase(
        "temporary file left by a crash",
        _partial,
        partials=("images/.light_c000_l009_e0.4242.partial.png",),
    ),
    VerifyCase("planned images never taken", taken=2, not_taken=tuple(KEYS[2:])),
]


@pytest.mark.parametrize("case", VERIFY_CASES, ids=lambda case: case.name)
def test_verify(case: VerifyCase, tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds", taken=case.taken)
    if case.damage is not None:
        case.damage(dataset)
    report = Dataset.open(dataset.path).verify()
    assert [record.file for record in report.missing] == list(case.missing)
    assert [(bad.record.file) for bad in report.corrupt] == [file for file, _ in case.corrupt]
    for bad, (_, words) in zip(report.corrupt, case.corrupt, strict=True):
        assert words in bad.reason
    assert report.unexpected == case.unexpected
    assert report.partials == case.partials
    assert report.not_taken == case.not_taken
    clean = not (case.missing or case.corrupt or case.unexpected or case.not_taken)
    assert report.ok is clean
    assert report.complete is not bool(case.missing or case.corrupt or case.not_taken)
    # Every problem is named in the summary people read.
    summary = report.summary()
    for name in (*case.missing, *(file for file, _ in case.corrupt), *case.unexpected):
        assert name in summary
    bad_keys = {r.key for r in report.missing} | {b.record.key for b in report.corrupt}
    assert report.retake == set(case.not_taken) | bad_keys


def test_verify_without_a_planned_list_cannot_judge_completeness(tmp_path: Path) -> None:
    dataset = Dataset.create(tmp_path / "ds", rig_config={}, plan={})
    _take(dataset, KEYS[0])
    report = dataset.verify()
    assert report.ok and not report.complete
    assert "completeness unknown" in report.summary()


def test_remove_partials(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds")
    _partial(dataset)
    (dataset.path / ".manifest.77.partial.json").write_text("{")
    assert sorted(dataset.remove_partials()) == [
        ".manifest.77.partial.json",
        "images/.light_c000_l009_e0.4242.partial.png",
    ]
    report = dataset.verify()
    assert report.ok and report.partials == ()


# -- records, round trips, the journal replay ----------------------------------------------------


def test_write_image_records_digest_and_round_trips(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds")
    record = dataset.get(KEYS[0])
    assert record is not None
    assert record.sha256 == hashlib.sha256(_payload(KEYS[0])).hexdigest()
    assert record.size_bytes == len(_payload(KEYS[0]))
    assert record.file == "images/light_c000_l000_e0.png"
    assert record.measured_pose["camera_azimuth_deg"] == 30.02
    reopened = Dataset.open(dataset.path)
    assert reopened.records == dataset.records
    assert reopened.planned == tuple(KEYS)
    assert reopened.rig_config == {"name": "sim"}
    manifest = json.loads(dataset.manifest_path.read_text())
    assert manifest["schema_version"] == SCHEMA_VERSION
    # Spelled out, not capture.manifest's _RECORD_KEYS: the test pins the file format, which a
    # change to that constant must not move unseen.
    assert set(manifest["images"][0]) == {
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
    }


def test_writer_callable_is_hashed_from_the_file_it_wrote(tmp_path: Path) -> None:
    dataset = Dataset.create(tmp_path / "ds", rig_config={}, plan={})
    seen: list[Path] = []

    def writer(path: Path) -> None:
        seen.append(path)
        assert path.suffix == ".tif"  # writers that pick a format by suffix keep working
        path.write_bytes(b"II*\x00" + bytes(range(256)))

    key = ImageKey("calibration", 2, None, 0)
    record = dataset.write_image(
        "calib/board.tif", writer, key=key, exposure_ms=5, commanded_pose={}, measured_pose={}
    )
    assert record.sha256 == hashlib.sha256(b"II*\x00" + bytes(range(256))).hexdigest()
    assert dataset.image_path(record) == dataset.path / "images" / "calib" / "board.tif"
    assert seen[0] != dataset.image_path(record) and not seen[0].exists()


def test_retake_replaces_the_record_in_place(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds")
    first = dataset.records
    new = dataset.write_image(
        "light_c000_l000_e0.png",
        b"retaken",
        key=KEYS[0],
        exposure_ms=20.0,
        commanded_pose=POSE,
        measured_pose=POSE,
    )
    assert dataset.records[0] == new and dataset.records[1:] == first[1:]
    assert dataset.verify().ok


def test_journal_events_are_replayed_over_the_manifest(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds", taken=1)  # the manifest was saved with one record
    with dataset.open_journal() as journal:
        journal.start(plan=dataset.plan, rig_config_digest="sha256:0")
        for key in KEYS[1:]:
            journal.event(_take(dataset, key), time_start=1.0, time_end=2.0)
    # Killed before save(): the manifest lists one image, the journal three more.
    reopened = Dataset.open(dataset.path)
    assert reopened.records == dataset.records
    assert reopened.verify().complete


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"key": ImageKey("light", 0, 0, 0), "exposure_ms": 0.0}, "exposure_ms"),
        ({"key": ImageKey("light", 0, 0, 0), "measured_pose": {"x": 1.0}}, "_deg"),
        ({"key": ImageKey("light", 0, 0, 0), "measured_pose": {"x_deg": float("nan")}}, "finite"),
        ({"key": ImageKey("light", 0, 0, 0), "name": "a b.png"}, "letters, digits"),
        ({"key": ImageKey("light", 0, 0, 0), "name": ".hidden.png"}, "may not start"),
        ({"key": ImageKey("light", 0, 0, 0), "name": "raw.txt"}, "suffix"),
        ({"key": ImageKey("light", 0, 0, 0), "name": "../../escape.png"}, "leaves"),
        ({"key": ImageKey("light", 0, 2, 0), "name": "light_c000_l000_e0.png"}, "already"),
    ],
    ids=["exposure", "pose key", "pose nan", "space", "hidden", "suffix", "escape", "name clash"],
)
def test_write_image_refuses_bad_arguments(
    kwargs: dict[str, Any], words: str, tmp_path: Path
) -> None:
    dataset = _dataset(tmp_path / "ds", keys=KEYS[:1])
    arguments: dict[str, Any] = {
        "name": "new.png",
        "exposure_ms": 1.0,
        "commanded_pose": POSE,
        "measured_pose": POSE,
    } | kwargs
    before = sorted(os.listdir(dataset.images_path))
    with pytest.raises(InputError, match=re.escape(words)):
        dataset.write_image(arguments.pop("name"), b"data", **arguments)
    assert sorted(os.listdir(dataset.images_path)) == before


@pytest.mark.parametrize(
    ("kind", "light", "words"),
    [("light", None, "needs a light_index"), ("dark", 3, "no light_index"), ("flat", 0, "kind")],
)
def test_image_key_validation(kind: str, light: int | None, words: str) -> None:
    with pytest.raises(InputError, match=words):
        ImageKey(kind, 0, light, 0)


# -- atomic writes ------------------------------------------------------------------------------


def test_crash_inside_the_writer_leaves_no_file(tmp_path: Path) -> None:
    dataset = Dataset.create(tmp_path / "ds", rig_config={}, plan={})

    def crashing(path: Path) -> None:
        path.write_bytes(b"half an ima")
        raise RuntimeError("camera unplugged")

    with pytest.raises(RuntimeError, match="unplugged"):
        dataset.write_image(
            "x.dng", crashing, key=KEYS[0], exposure_ms=1, commanded_pose={}, measured_pose={}
        )
    assert os.listdir(dataset.images_path) == []
    assert dataset.records == ()


def test_crash_during_a_retake_keeps_the_earlier_take(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds")
    record = dataset.records[0]

    def crashing(path: Path) -> None:
        path.write_bytes(b"partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        dataset.write_image(
            "light_c000_l000_e0.png",
            crashing,
            key=record.key,
            exposure_ms=1,
            commanded_pose={},
            measured_pose={},
        )
    assert dataset.records[0] == record
    assert dataset.verify().ok


def test_writer_that_writes_nothing_is_an_error(tmp_path: Path) -> None:
    dataset = Dataset.create(tmp_path / "ds", rig_config={}, plan={})
    with pytest.raises(DatasetError, match="did not create"):
        dataset.write_image(
            "x.png",
            lambda path: None,
            key=KEYS[0],
            exposure_ms=1,
            commanded_pose={},
            measured_pose={},
        )
    assert os.listdir(dataset.images_path) == []


# -- create and open: clear errors --------------------------------------------------------------


def test_create_refuses_a_non_empty_directory(tmp_path: Path) -> None:
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "old.txt").write_text("x")
    with pytest.raises(InputError, match="not an empty directory"):
        Dataset.create(tmp_path / "ds", rig_config={}, plan={})
    (tmp_path / "empty").mkdir()
    Dataset.create(tmp_path / "empty", rig_config={}, plan={})


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"rig_config": {"when": object()}}, "rig_config is not plain JSON"),
        ({"plan": {"x": float("nan")}}, "plan is not plain JSON"),
        ({"planned": [KEYS[0], KEYS[0]]}, "duplicates"),
    ],
)
def test_create_refuses_bad_metadata(kwargs: dict[str, Any], words: str, tmp_path: Path) -> None:
    arguments: dict[str, Any] = {"rig_config": {}, "plan": {}} | kwargs
    with pytest.raises(InputError, match=words):
        Dataset.create(tmp_path / "ds", **arguments)


def _write(path: Path, text: str) -> None:
    path.write_text(text)


def _set_file(index: int, file: str) -> Callable[[dict[str, Any]], None]:
    def change(document: dict[str, Any]) -> None:
        document["images"][index]["file"] = file

    return change


@dataclass(frozen=True)
class OpenCase:
    name: str
    change: Callable[[Dataset], None]
    words: tuple[str, ...]  # what the message must name, besides the manifest


def _manifest_change(change: Callable[[dict[str, Any]], None]) -> Callable[[Dataset], None]:
    return lambda dataset: _rewrite_manifest(dataset, change)


def _symlink_out(dataset: Dataset) -> None:
    outside = dataset.path.parent / "secret.png"
    outside.write_bytes(b"not yours")
    (dataset.images_path / "link.png").symlink_to(outside)
    _rewrite_manifest(dataset, _set_file(1, "images/link.png"))


def _images_dir_symlinked_out(dataset: Dataset) -> None:
    elsewhere = dataset.path.parent / "elsewhere"
    dataset.images_path.rename(elsewhere)
    dataset.images_path.symlink_to(elsewhere)


OPEN_CASES = [
    OpenCase(
        "path climbing out with ..",
        _manifest_change(_set_file(0, "../x.png")),
        ("record 0", "'../x.png'", "leaves the dataset directory"),
    ),
    OpenCase(
        "path climbing out from inside images",
        _manifest_change(_set_file(2, "images/../../x.png")),
        ("record 2", "'images/../../x.png'", "leaves the dataset directory"),
    ),
    OpenCase(
        "absolute path",
        _manifest_change(_set_file(1, "/etc/passwd")),
        ("record 1", "'/etc/passwd'", "absolute"),
    ),
    OpenCase(
        "windows absolute path",
        _manifest_change(_set_file(1, "C:/x.png")),
        ("record 1", "'C:/x.png'", "absolute"),
    ),
    OpenCase(
        "symlink out of the dataset",
        _symlink_out,
        ("record 1", "'images/link.png'", "symlink out of the dataset"),
    ),
    OpenCase(
        "images directory symlinked out",
        _images_dir_symlinked_out,
        ("record 0", "'images/light_c000_l000_e0.png'", "symlink out"),
    ),
    OpenCase(
        "unknown schema version",
        _manifest_change(lambda document: document.update(schema_version=2)),
        ("schema version 2", f"reads schema version {SCHEMA_VERSION}"),
    ),
    OpenCase(
        "schema version as a string",
        _manifest_change(lambda document: document.update(schema_version="1")),
        ("schema version '1'",),
    ),
    OpenCase(
        "no schema version",
        _manifest_change(lambda document: document.pop("schema_version")),
        ("schema version None",),
    ),
    OpenCase(
        "unknown field",
        _manifest_change(lambda document: document.update(colour="red")),
        ("unknown fields ['colour']",),
    ),
    OpenCase(
        "record with a bad checksum field",
        _manifest_change(lambda document: document["images"][3].update(sha256="abc")),
        ("record 3", "sha256"),
    ),
    OpenCase(
        "two records of one file",
        _manifest_change(_set_file(1, "images/light_c000_l000_e0.png")),
        ("record 1", "already the image of light camera 0 light 0"),
    ),
    OpenCase(
        "not JSON",
        lambda dataset: _write(dataset.manifest_path, '{\n  "schema_version": 1,\n  oops\n}'),
        ("line 3 column 3", "not valid JSON"),
    ),
]


@pytest.mark.parametrize("case", OPEN_CASES, ids=lambda case: case.name)
def test_open_refuses_bad_manifests(case: OpenCase, tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds")
    case.change(dataset)
    with pytest.raises(DatasetError) as raised:
        Dataset.open(dataset.path)
    message = str(raised.value)
    assert str(dataset.manifest_path) in message
    for words in case.words:
        assert words in message


def test_open_refuses_a_journal_event_that_escapes(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds", taken=0)
    record = _take(dataset, KEYS[0]).to_dict() | {"file": "images/../../../etc/x.png"}
    with dataset.open_journal() as journal:
        journal.start(plan=dataset.plan, rig_config_digest="sha256:0")
        journal.event(record, time_start=0.0, time_end=1.0)
    with pytest.raises(DatasetError) as raised:
        Dataset.open(dataset.path)
    assert f"{dataset.journal_path}, line 2" in str(raised.value)
    assert "leaves the dataset directory" in str(raised.value)


def test_open_of_a_directory_without_manifest(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"manifest\.json: missing"):
        Dataset.open(tmp_path)
    with pytest.raises(DatasetError, match="no such dataset directory"):
        Dataset.open(tmp_path / "nothing")


# -- path confinement, on random names ---------------------------------------------------------

_SEGMENTS = st.sampled_from(["images", "a", "b.png", "..", ".", "", "c", "x.exr", "link"])


@pytest.fixture(scope="module")
def confined(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    root = tmp_path_factory.mktemp("confined")
    dataset = Dataset.create(root / "ds", rig_config={}, plan={})
    (dataset.images_path / "a").mkdir()
    (dataset.images_path / "link").symlink_to(root)  # leads out of the dataset
    return dataset


@settings(max_examples=150)
@given(parts=st.lists(_SEGMENTS, min_size=1, max_size=6), absolute=st.booleans())
def test_resolve_never_leaves_the_dataset(
    confined: Dataset, parts: list[str], absolute: bool
) -> None:
    name = ("/" if absolute else "") + "/".join(parts)
    escapes = absolute or posixpath.normpath(name).split("/")[0] == ".."
    try:
        path = confined.resolve(name)
    except DatasetError as error:
        assert repr(name) in str(error)
        return
    assert not escapes
    assert path.resolve().is_relative_to(confined.path.resolve())
    # The symlink leading out is never passed through.
    assert not path.relative_to(confined.path).as_posix().startswith("images/link")
