from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from capture.dataset_lock import LOCK_NAME, DatasetLock
from core.errors import DatasetError


def test_one_holder_at_a_time_and_it_is_named(tmp_path: Path) -> None:
    first, second = DatasetLock(tmp_path), DatasetLock(tmp_path)
    with first:
        holder = json.loads((tmp_path / LOCK_NAME).read_text())
        assert holder["pid"] == os.getpid() and holder["host"]
        with pytest.raises(DatasetError, match=rf"in use by process {os.getpid()} on "):
            second.acquire()
        assert not second.held
    # Released: the next one takes it, and the file no longer names anyone.
    with second:
        assert second.held
    assert (tmp_path / LOCK_NAME).read_text() == ""


def test_the_lock_is_reentrant_within_one_object(tmp_path: Path) -> None:
    lock = DatasetLock(tmp_path)
    with lock, lock:
        assert lock.held
    assert not lock.held
    with DatasetLock(tmp_path):
        pass


def test_a_leftover_lock_file_of_a_dead_holder_does_not_block(tmp_path: Path) -> None:
    # What a killed process leaves: the file with its name, but no lock held on it.
    (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": 1, "host": "x", "since": "then"}))
    with DatasetLock(tmp_path) as lock:
        assert lock.held


def test_a_dataset_that_cannot_be_locked_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="cannot lock the dataset"):
        DatasetLock(tmp_path / "missing").acquire()
