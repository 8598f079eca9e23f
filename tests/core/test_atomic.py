"""core.atomic: a target appears only complete, an error leaves the old file and no temporary."""

from __future__ import annotations

import errno
import json
import os
import threading
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.atomic import atomic_path, output_problem, write_json_atomic
from core.errors import InputError
from tests.full_disk import writes_under_limit


def test_the_target_appears_only_when_the_block_succeeds(tmp_path: Path) -> None:
    target = tmp_path / "picture.png"
    with atomic_path(target) as temporary:
        # A hidden name beside the target that keeps its suffix (writers choose by extension).
        assert temporary.parent == tmp_path
        assert temporary.name == f".picture.{os.getpid()}.{threading.get_native_id()}.partial.png"
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
    with (
        pytest.raises(InputError, match=f"{target}: the writer wrote no file"),
        atomic_path(target),
    ):
        pass
    assert list(tmp_path.iterdir()) == []


def test_an_os_error_in_the_block_names_the_target_and_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "r.png"
    target.write_bytes(b"the previous picture")
    with pytest.raises(InputError) as raised, atomic_path(target) as temporary:
        temporary.write_bytes(b"half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(raised.value) == (
        f"{target}: cannot write: no space left on the device; free some space or choose "
        "another place (the earlier file is kept as it was)"
    )
    assert target.read_bytes() == b"the previous picture"
    assert [p.name for p in tmp_path.iterdir()] == ["r.png"]


# --- a full disk, for real: a child process under a file size limit (tests/full_disk.py) -----


def test_a_write_past_the_file_size_limit_keeps_the_old_file(tmp_path: Path) -> None:
    document = tmp_path / "doc.json"
    blob = tmp_path / "blob.bin"
    write_json_atomic(document, {"version": 1})
    blob.write_bytes(b"old")
    found = writes_under_limit(
        f"""
from core.atomic import write_bytes_atomic, write_json_atomic
attempt("json", lambda: write_json_atomic({str(document)!r}, list(range(5000))))
attempt("bytes", lambda: write_bytes_atomic({str(blob)!r}, bytes(100_000)))
attempt("new", lambda: write_bytes_atomic({str(tmp_path / "new.bin")!r}, bytes(100_000)))
""",
        limit=4096,
    )
    for name, target in (("json", document), ("bytes", blob)):
        assert found[name]["project"], found[name]["traceback"]
        assert found[name]["message"] == (
            f"{target}: cannot write: the file is larger than this process may write (a file "
            "size limit) (the earlier file is kept as it was)"
        )
    assert found["new"]["message"].endswith("(nothing was written)")
    assert json.loads(document.read_text()) == {"version": 1}
    assert blob.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blob.bin", "doc.json"]


@settings(max_examples=12, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(size=st.integers(0, 3000), limit=st.integers(0, 3000))
def test_a_write_succeeds_whole_or_fails_leaving_the_old_file(
    tmp_path: Path, size: int, limit: int
) -> None:
    target = tmp_path / "data.bin"
    target.write_bytes(b"old")
    data = bytes(range(256)) * (size // 256) + bytes(size % 256)
    found = writes_under_limit(
        f"""
from core.atomic import write_bytes_atomic
attempt("write", lambda: write_bytes_atomic({str(target)!r}, {data!r}))
""",
        limit=limit,
    )["write"]
    if size <= limit:
        assert found["error"] is None, found["traceback"]
        assert target.read_bytes() == data
    else:
        assert found["project"] and "cannot write" in found["message"], found["traceback"]
        assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["data.bin"]


# --- outputs that cannot be named --------------------------------------------------------


def test_a_name_longer_than_the_file_system_allows_is_refused(tmp_path: Path) -> None:
    target = tmp_path / ("a" * 256 + ".png")
    assert output_problem(target) == (
        f"{target}: the name {'a' * 24}... is 260 bytes long, the file system allows 255; "
        "choose a shorter name"
    )
    with pytest.raises(InputError, match="choose a shorter name"), atomic_path(target):
        pass
    assert list(tmp_path.iterdir()) == []


def test_a_long_name_within_the_limit_is_written(tmp_path: Path) -> None:
    # Its temporary name (".NAME.PID.partial.png") would be too long: it is shortened.
    target = tmp_path / ("b" * 251 + ".png")
    with atomic_path(target) as temporary:
        assert len(temporary.name) <= 255 and temporary.suffix == ".png"
        temporary.write_bytes(b"x")
    assert target.read_bytes() == b"x"


@pytest.mark.parametrize("where", ["loop/r.png", "loop", "deep/loop/x/r.png"])
def test_a_loop_of_symbolic_links_is_refused(tmp_path: Path, where: str) -> None:
    (tmp_path / "loop").symlink_to("loop")
    (tmp_path / "deep").mkdir()
    (tmp_path / "deep" / "loop").symlink_to("loop")
    target = tmp_path / where
    problem = output_problem(target)
    assert problem is not None and problem.startswith(f"{target}: the path runs through a loop")
    with pytest.raises(InputError, match="loop of symbolic links"), atomic_path(target):
        pass


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


def test_threads_saving_one_file_each_write_it_whole(tmp_path: Path) -> None:
    # A viewer's session and its light view both save a field's fit: each thread's temporary
    # file is its own, so neither renames the other's away (that failed as "No such file").
    target = tmp_path / "fit.npz"
    started = threading.Barrier(4)
    failures: list[BaseException] = []

    def save(byte: int) -> None:
        started.wait()
        try:
            for _ in range(50):
                with atomic_path(target) as temporary:
                    temporary.write_bytes(bytes([byte]) * 100_000)
        except BaseException as error:
            failures.append(error)

    threads = [threading.Thread(target=save, args=(b,)) for b in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert failures == []
    data = target.read_bytes()
    assert len(data) == 100_000 and len(set(data)) == 1  # one writer's file, whole
    assert [p.name for p in tmp_path.iterdir()] == ["fit.npz"]
