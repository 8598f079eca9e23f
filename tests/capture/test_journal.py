from __future__ import annotations

import json
import logging
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from capture.dataset import Dataset, ImageKey
from capture.journal import (
    MAX_JSON_DEPTH,
    Journal,
    completed_images,
    config_digest,
    last_run_status,
    parse_json,
    read_journal,
    runs,
)
from core.errors import DatasetError, InputError

ROOT = Path(__file__).resolve().parents[2]


def _record(light: int, kind: str = "light") -> dict[str, Any]:
    return {
        "kind": kind,
        "camera_index": 0,
        "light_index": light if kind == "light" else None,
        "exposure_index": 0,
        "exposure_ms": 10.0,
        "commanded_pose": {"light_azimuth_deg": 10.0 * light},
        "measured_pose": {"light_azimuth_deg": 10.0 * light + 0.01},
        "file": f"images/{kind}_{light}.png",
        "sha256": "0" * 64,
        "size_bytes": 0,
    }


def _journal(path: Path, events: int = 3, status: str | None = "success") -> Path:
    with Journal(path) as journal:
        journal.start(plan={"images": events}, rig_config_digest=config_digest({"a": 1}))
        for light in range(events):
            journal.event(_record(light), time_start=100.0 + light, time_end=100.5 + light)
        if status is not None:
            journal.stop(status, reason="done", counts={"taken": events})  # type: ignore[arg-type]
    return path


def test_documents_round_trip(tmp_path: Path) -> None:
    contents = read_journal(_journal(tmp_path / "journal.jsonl"))
    kinds = [document["type"] for document in contents.documents]
    assert kinds == ["start", "event", "event", "event", "stop"]
    start, first, *_, stop = contents.documents
    assert start["resumed_from"] is None
    assert start["rig_config_digest"] == config_digest({"a": 1})
    assert first["run_start"] == start["uid"] and first["seq_num"] == 1
    assert first["record"]["measured_pose"] == {"light_azimuth_deg": 0.01}
    assert (first["time_start"], first["time_end"]) == (100.0, 100.5)
    assert stop["exit_status"] == "success" and stop["num_events"] == 3
    assert stop["counts"] == {"taken": 3}
    assert contents.truncated is None and contents.lines == [1, 2, 3, 4, 5]
    assert completed_images(contents.documents) == {ImageKey("light", 0, i, 0) for i in range(3)}
    assert last_run_status(contents.documents) == "success"


def test_runs_accumulate_across_resumes(tmp_path: Path) -> None:
    path = _journal(tmp_path / "journal.jsonl", events=2, status="paused")
    first = read_journal(path).documents[0]["uid"]
    with Journal(path) as journal:
        journal.start(plan={}, rig_config_digest="sha256:x", resumed_from=first)
        journal.event(_record(5), time_start=0.0, time_end=1.0)
        journal.event(_record(0, kind="dark"), time_start=0.0, time_end=1.0)
    documents = read_journal(path).documents
    summaries = runs(documents)
    assert [s.status for s in summaries] == ["paused", "interrupted"]
    assert [s.events for s in summaries] == [2, 2]
    assert summaries[1].start["resumed_from"] == first
    assert last_run_status(documents) == "interrupted"
    assert completed_images(documents) == {
        ImageKey("light", 0, 0, 0),
        ImageKey("light", 0, 1, 0),
        ImageKey("light", 0, 5, 0),
        ImageKey("dark", 0, None, 0),
    }
    assert last_run_status([]) is None


def test_config_digest_ignores_key_order() -> None:
    assert config_digest({"a": 1, "b": [1, 2]}) == config_digest({"b": [1, 2], "a": 1})
    assert config_digest({"a": 1}) != config_digest({"a": 2})
    with pytest.raises(InputError, match="not plain JSON"):
        config_digest({"a": float("nan")})


# -- damaged journals: a table of named cases --------------------------------------------------


@dataclass(frozen=True)
class TailCase:
    name: str
    tail: bytes  # replaces the file's last line (the stop document)
    truncated_line: int


TAIL_CASES = [
    TailCase("half a line, no newline", b'{"type":"stop","uid":"x","run_st', 5),
    TailCase("a complete document without its newline", b"{}", 5),
    TailCase("garbage with a newline", b'{"type":"st\x00\x00\n', 5),
    TailCase("zeros left by a power loss", b"\x00" * 40, 5),
]


@pytest.mark.parametrize("case", TAIL_CASES, ids=lambda case: case.name)
def test_unfinished_last_line_is_reported_and_ignored(
    case: TailCase, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = _journal(tmp_path / "journal.jsonl")
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:-1]) + case.tail)
    with caplog.at_level(logging.WARNING, logger="capture.journal"):
        contents = read_journal(path)
    assert contents.truncated is not None and contents.truncated.line == case.truncated_line
    assert [d["type"] for d in contents.documents] == ["start", "event", "event", "event"]
    assert last_run_status(contents.documents) == "interrupted"
    assert caplog.text == ""  # reading reports it in its result; only the repair logs
    assert "a crash" in contents.report()
    # Appending cuts the unfinished line off, so the next document starts on a line of its own.
    with caplog.at_level(logging.WARNING, logger="capture.journal"), Journal(path) as journal:
        assert journal.repaired == contents.truncated
        journal.start(plan={}, rig_config_digest="sha256:x")
    assert f"line {case.truncated_line}: unfinished last line removed" in caplog.text
    repaired = read_journal(path)
    assert repaired.truncated is None
    assert [d["type"] for d in repaired.documents] == ["start", "event", "event", "event", "start"]


@dataclass(frozen=True)
class CorruptCase:
    name: str
    line: int
    replacement: bytes
    words: str


CORRUPT_CASES = [
    CorruptCase("not JSON in the middle", 3, b'{"type": "event", \n', "not a JSON document"),
    CorruptCase("empty line in the middle", 2, b"\n", "not a JSON document"),
    CorruptCase("not an object", 2, b"[1, 2]\n", "expected a JSON object"),
    CorruptCase("unknown document type", 4, b'{"type": "descriptor"}\n', "unknown document type"),
    CorruptCase("missing field", 1, b'{"type": "start", "uid": "u"}\n', "missing ["),
    CorruptCase(
        "event of another run",
        2,
        json.dumps(
            {
                **json.loads('{"type":"event"}'),
                "uid": "e",
                "run_start": "other",
                "seq_num": 1,
                "time": 0,
                "time_start": 0,
                "time_end": 0,
                "record": _record(0),
            }
        ).encode()
        + b"\n",
        "belongs to run 'other'",
    ),
]


@pytest.mark.parametrize("case", CORRUPT_CASES, ids=lambda case: case.name)
def test_corrupt_line_before_the_last_is_an_error(case: CorruptCase, tmp_path: Path) -> None:
    path = _journal(tmp_path / "journal.jsonl")
    lines = path.read_bytes().splitlines(keepends=True)
    lines[case.line - 1] = case.replacement
    path.write_bytes(b"".join(lines))
    with pytest.raises(DatasetError) as raised:
        read_journal(path)
    assert f"{path}, line {case.line}" in str(raised.value)
    assert case.words in str(raised.value)
    with pytest.raises(DatasetError):
        Journal(path)  # never append to a corrupt journal


def _nested(kinds: list[bool], leaf: str = "1") -> str:
    """JSON text of containers nested ``len(kinds)`` deep: a list (True) or an object."""
    opening = "".join("[" if is_list else '{"k": ' for is_list in kinds)
    closing = "".join("]" if is_list else "}" for is_list in reversed(kinds))
    return opening + leaf + closing


@given(
    kinds=st.lists(st.booleans(), max_size=MAX_JSON_DEPTH + 4)
    | st.builds(lambda n, k: [k] * n, st.sampled_from([999, 5_000, 200_000]), st.booleans())
)
def test_json_deeper_than_the_limit_is_refused_by_name_never_a_recursion_error(
    kinds: list[bool],
) -> None:
    text = _nested(kinds)
    if len(kinds) <= MAX_JSON_DEPTH:
        assert parse_json(text, "f.json") == json.loads(text)
    else:
        with pytest.raises(DatasetError, match=r"^f\.json, line 7: JSON nested "):
            parse_json(text, "f.json, line 7")


@pytest.mark.parametrize("line", [2, 5])  # an event in the middle, the last line (the stop)
def test_a_journal_line_nested_200000_deep_is_named(tmp_path: Path, line: int) -> None:
    path = _journal(tmp_path / "journal.jsonl")
    lines = path.read_bytes().splitlines(keepends=True)
    assert len(lines) == 5
    lines[line - 1] = b'{"type": ' + _nested([True] * 200_000).encode() + b"}\n"
    path.write_bytes(b"".join(lines))
    with pytest.raises(DatasetError, match=rf"{path}, line {line}: JSON nested too deeply"):
        read_journal(path)


def test_missing_journal(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no such journal"):
        read_journal(tmp_path / "journal.jsonl")


def test_journal_refuses_misuse(tmp_path: Path) -> None:
    with Journal(tmp_path / "journal.jsonl") as journal:
        with pytest.raises(InputError, match="no run is open"):
            journal.event(_record(0), time_start=0, time_end=0)
        with pytest.raises(InputError, match="no run is open"):
            journal.stop("success")
        journal.start(plan={}, rig_config_digest="sha256:x")
        with pytest.raises(InputError, match="still open"):
            journal.start(plan={}, rig_config_digest="sha256:x")
        with pytest.raises(InputError, match="needs a light_index"):
            journal.event(_record(0) | {"light_index": None}, time_start=0, time_end=0)
        with pytest.raises(InputError, match="exit status"):
            journal.stop("crashed")  # type: ignore[arg-type]
        with pytest.raises(InputError, match="not JSON"):
            journal.event(_record(0) | {"exposure_ms": float("inf")}, time_start=0, time_end=0)
    with pytest.raises(InputError, match="closed"):
        journal.start(plan={}, rig_config_digest="sha256:x")
    documents = read_journal(tmp_path / "journal.jsonl").documents
    assert [d["type"] for d in documents] == ["start"]  # nothing half-written by the refusals


# -- a real SIGKILL while capturing --------------------------------------------------------------

# A capture loop as the executor will run it: resume from the journal, take every image the
# journal does not record (deterministic bytes per image), journal each one, forever.
CHILD = textwrap.dedent(
    """
    import hashlib, sys, time
    from capture.dataset import Dataset, ImageKey
    from capture.journal import completed_images, runs

    dataset = Dataset.open(sys.argv[1])
    dataset.remove_partials()
    journal = dataset.open_journal()
    previous = runs(dataset.journal.documents) if dataset.journal else []
    done = completed_images(dataset.journal.documents) if dataset.journal else set()
    journal.start(
        plan=dataset.plan,
        rig_config_digest="sha256:sim",
        resumed_from=previous[-1].uid if previous else None,
    )
    print("started", flush=True)
    pose = {"camera_azimuth_deg": 0.0, "light_azimuth_deg": 0.0}
    light = 0
    while True:
        key = ImageKey("light", 0, light, 0)
        if key not in done:
            data = hashlib.sha256(str(light).encode()).digest() * (64 + 97 * (light % 13))
            begin = time.time()
            record = dataset.write_image(
                key.stem() + ".png", data, key=key, exposure_ms=1.0,
                commanded_pose=pose, measured_pose=pose,
            )
            journal.event(record, time_start=begin, time_end=time.time())
        light += 1
    """
)


def _run_and_kill(dataset: Path, delay: float) -> None:
    environment = os.environ | {"PYTHONPATH": str(ROOT)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(dataset)],
        stdout=subprocess.PIPE,
        cwd=ROOT,
        env=environment,
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline() == b"started\n"
        time.sleep(delay)
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        child.stdout.close()  # type: ignore[union-attr]
    assert child.returncode == -signal.SIGKILL


def test_sigkill_while_appending_leaves_a_resumable_dataset(tmp_path: Path) -> None:
    path = tmp_path / "ds"
    Dataset.create(path, rig_config={"name": "sim"}, plan={})
    rng = random.Random(20240607)
    counts: list[int] = []
    for _ in range(4):
        _run_and_kill(path, rng.uniform(0.0, 0.15))
        contents = read_journal(path / "journal.jsonl")
        events = [d for d in contents.documents if d["type"] == "event"]
        # Every completed event names a file that exists and matches its checksum.
        dataset = Dataset.open(path)
        report = dataset.verify()
        assert report.missing == () and report.corrupt == ()
        for event in events:
            assert dataset.get(ImageKey.from_record(event["record"])) is not None
        # Nothing is duplicated: each image is journalled once across all runs.
        keys = [ImageKey.from_record(event["record"]) for event in events]
        assert len(keys) == len(set(keys))
        # Images written but not yet journalled are strays that resume overwrites.
        assert all(name.startswith("images/light_c000_l") for name in report.unexpected)
        assert last_run_status(contents.documents) == "interrupted"
        counts.append(len(keys))
    assert counts == sorted(counts) and counts[-1] > 0
    assert [run.start["resumed_from"] is None for run in runs(contents.documents)] == [
        True,
        False,
        False,
        False,
    ]
