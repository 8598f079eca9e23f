"""core.file_kinds: a FIFO, a device or a socket is refused by name, and never waited on."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from core.errors import InputError
from core.file_kinds import read_regular_bytes, special_file_problem
from tests.full_disk import ROOT


def test_files_folders_and_missing_paths_pass(tmp_path: Path) -> None:
    (tmp_path / "plain.toml").write_text("a = 1\n")
    (tmp_path / "link.toml").symlink_to("plain.toml")
    for path in ("plain.toml", "link.toml", ".", "missing.toml", "plain.toml/under"):
        assert special_file_problem(tmp_path / path) is None
    assert read_regular_bytes(tmp_path / "link.toml") == b"a = 1\n"


def test_a_fifo_is_refused_by_name(tmp_path: Path) -> None:
    fifo = tmp_path / "config.toml"
    os.mkfifo(fifo)
    words = f"{fifo}: is a FIFO (named pipe), not a regular file; name a regular file"
    assert special_file_problem(fifo) == words
    (tmp_path / "link.toml").symlink_to("config.toml")
    assert special_file_problem(tmp_path / "link.toml") == words.replace("config", "link")
    with pytest.raises(InputError, match="is a FIFO"):
        read_regular_bytes(fifo)


def test_a_device_and_a_socket_are_refused_by_name(tmp_path: Path) -> None:
    assert special_file_problem("/dev/zero") == (
        "/dev/zero: is a character device, not a regular file; name a regular file"
    )
    with pytest.raises(InputError, match="/dev/null: is a character device"):
        read_regular_bytes("/dev/null")
    with socket.socket(socket.AF_UNIX) as server:
        server.bind(str(tmp_path / "s.sock"))
        problem = special_file_problem(tmp_path / "s.sock")
        assert problem is not None and problem.endswith(
            "s.sock: is a socket, not a regular file; name a regular file"
        )


def test_paths_no_lookup_can_follow_are_named(tmp_path: Path) -> None:
    (tmp_path / "loop").symlink_to("loop")
    assert (
        special_file_problem(tmp_path / "loop")
        == f"{tmp_path / 'loop'}: the path runs through a loop of symbolic links"
    )
    assert special_file_problem(tmp_path / ("n" * 300)) == (
        f"{tmp_path / ('n' * 300)}: the name {'n' * 24}... is 300 bytes long, the file system "
        "allows 255; choose a shorter name"
    )
    assert special_file_problem("a\0b") == "'a\\x00b': a path cannot hold a NUL byte"


def test_reading_a_fifo_with_no_writer_never_waits(tmp_path: Path) -> None:
    # Run in a child with a generous limit: a plain open() of a FIFO waits for a writer forever.
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    code = (
        "from core.errors import InputError\n"
        "from core.file_kinds import read_regular_bytes\n"
        "from core.image_io import read_pixels\n"
        f"for read in (read_regular_bytes, read_pixels):\n"
        f"    try:\n        read({str(fifo)!r})\n"
        "    except InputError as error:\n        print(error)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
        check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (
        done.stdout.splitlines()
        == [f"{fifo}: is a FIFO (named pipe), not a regular file; name a regular file"] * 2
    )
