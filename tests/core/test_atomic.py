"""core.atomic: a target appears only complete, an error leaves the old file and no temporary."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.atomic import atomic_path, write_json_atomic


def test_the_target_appears_only_when_the_block_succeeds(tmp_path: Path) -> None:
    target = tmp_path / "picture.png"
    with atomic_path(target) as temporary:
        # A hidden name beside the target that keeps its suffix (writers choose by extension).
        assert temporary.parent == tmp_path
        assert temporary.name == f".picture.{os.getpid()}.partial.png"
        assert temporary.suffix == ".png"
        temporary.write_bytes(b"complete")
        assert not target.exists()  # nothing under the real name while it is being written
    assert target.read_bytes() == b"complete"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["picture.png"]


def test_replacing_keeps_the_old_file_visible_until_the_rename(tmp_path: Path) -> None:
    target = tmp_path / "manifest.json"
    target.write_text("old")
    with atomic_path(target) as temporary:
        temporary.write_text("new")
        assert target.read_text() == "old"
    assert target.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["manifest.json"]


def test_an_error_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "field.exr"
    target.write_bytes(b"the previous version")
    with pytest.raises(RuntimeError, match="writer failed"), atomic_path(target) as temporary:
        temporary.write_bytes(b"half writ")
        raise RuntimeError("writer failed")
    assert target.read_bytes() == b"the previous version"
    assert [p.name for p in tmp_path.iterdir()] == ["field.exr"]


def test_an_error_on_a_new_target_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "new.tif"
    with pytest.raises(KeyboardInterrupt), atomic_path(target) as temporary:
        temporary.write_bytes(b"partial")
        raise KeyboardInterrupt  # not only Exception: any way out of the block
    assert list(tmp_path.iterdir()) == []


def test_missing_parent_folders_are_created(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "out.txt"
    with atomic_path(str(target)) as temporary:  # a str path works too
        assert temporary.parent.is_dir()
        temporary.write_text("x")
    assert target.read_text() == "x"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


def test_a_block_that_writes_nothing_creates_no_target(tmp_path: Path) -> None:
    target = tmp_path / "never.json"
    with pytest.raises(OSError), atomic_path(target):
        pass
    assert list(tmp_path.iterdir()) == []


def test_write_json_atomic_writes_indented_json_with_a_final_newline(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "doc.json"
    document = {"name": "rig", "axes": [1, 2.5, None, True], "nested": {"é": "ü"}}
    write_json_atomic(target, document)
    text = target.read_text(encoding="utf-8")
    assert text == json.dumps(document, indent=2) + "\n"
    assert text.startswith('{\n  "name": "rig",')
    assert json.loads(text) == document
    assert [p.name for p in target.parent.iterdir()] == ["doc.json"]


def test_write_json_atomic_replaces_a_previous_document(tmp_path: Path) -> None:
    target = tmp_path / "doc.json"
    write_json_atomic(target, {"version": 1})
    write_json_atomic(target, [1, 2, 3])
    assert json.loads(target.read_text()) == [1, 2, 3]


def test_an_unserialisable_document_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "doc.json"
    write_json_atomic(target, {"version": 1})
    with pytest.raises(TypeError, match="not JSON serializable"):
        write_json_atomic(target, {"version": object()})
    assert json.loads(target.read_text()) == {"version": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["doc.json"]


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**63)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=20),
    lambda children: (
        st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=10), children, max_size=5)
    ),
    max_leaves=20,
)


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(document=json_values)
def test_write_json_atomic_round_trips(tmp_path: Path, document: Any) -> None:
    target = tmp_path / "round-trip.json"
    write_json_atomic(target, document)  # the same name each time: each write replaces
    assert json.loads(target.read_text(encoding="utf-8")) == document
    assert [p.name for p in tmp_path.iterdir()] == ["round-trip.json"]
