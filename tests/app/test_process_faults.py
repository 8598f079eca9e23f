"""Faults while ``rig process`` writes a store leave no debris (issue 28).

SIGTERM or SIGKILL of ``rig process`` left its ``.NAME.PID.partial`` store, even after a
successful re-run; of two ``rig process`` to one new output, the loser refused clearly but left
its complete partial store. Each run here is ``rig`` as a user runs it, in a process of its own,
on a small simulated capture; the waits are generous bounds on a hang (a loaded machine), and
nothing is timed.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from core.errors import InputError
from core.field_store import FieldStoreWriter
from core.store.integrity import check_store
from sim.field import field_cameras
from tests.processing.test_field_builder import make_capture

ROOT = Path(__file__).parents[2]
#: Seconds allowed for a run on a loaded 2-core machine (a bound on a hang, not a timing).
PATIENCE_S = 300.0
#: Points the simulated scene is built with: enough that building takes a few seconds, so the
#: signal comes while the partial store is there.
SLOW_POINTS = "200000"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_capture(tmp_path_factory.mktemp("capture"), cameras=2, lights=3, points=500).path


def _rig(*args: str, logs: Path) -> subprocess.Popen[bytes]:
    with open(logs / "stdout.txt", "ab") as stdout, open(logs / "stderr.txt", "ab") as stderr:
        return subprocess.Popen(
            [sys.executable, "-m", "app.cli", *args], cwd=ROOT, stdin=subprocess.DEVNULL,
            stdout=stdout, stderr=stderr,
        )  # fmt: skip


def _partials(folder: Path) -> list[str]:
    return sorted(path.name for path in folder.iterdir() if path.name.endswith(".partial"))


def _signalled_while_building(
    dataset: Path, output: Path, number: int, logs: Path, *, opened: bool = False
) -> subprocess.Popen[bytes]:
    """``rig process`` sent ``number`` as soon as its partial store appears; ended.

    ``opened``: once the partial store holds its group (zarr opens it by emptying the folder
    it made, so a signal at first sight may find no folder at that instant).
    """
    process = _rig("process", str(dataset), "-o", str(output), "--scene-points", SLOW_POINTS,
                   logs=logs)  # fmt: skip
    partial = output.with_name(f".{output.name}.{process.pid}.partial")
    deadline = time.monotonic() + PATIENCE_S
    try:
        while not (partial / "zarr.json").exists() if opened else not partial.exists():
            if process.poll() is not None:
                raise AssertionError(f"rig process ended ({process.returncode}) before building")
            if time.monotonic() > deadline:
                raise AssertionError(f"no partial store within {PATIENCE_S:.0f} s")
            time.sleep(0.005)  # at once: the write under way is what SIGTERM used to leave
        process.send_signal(number)
        process.wait(timeout=PATIENCE_S)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return process


def test_sigterm_removes_the_partial_store(dataset: Path, tmp_path: Path) -> None:
    output = tmp_path / "f.zarr"
    process = _signalled_while_building(dataset, output, signal.SIGTERM, tmp_path)
    stderr = (tmp_path / "stderr.txt").read_text(errors="replace")
    assert process.returncode == 128 + signal.SIGTERM, stderr[-2000:]
    assert "rig process: terminated" in stderr and "Traceback" not in stderr
    assert _partials(tmp_path) == [] and not output.exists()


def test_a_run_after_sigkill_removes_the_partial_left_and_says_so(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    output = tmp_path / "f.zarr"
    killed = _signalled_while_building(dataset, output, signal.SIGKILL, tmp_path, opened=True)
    assert killed.returncode == -signal.SIGKILL
    left = _partials(tmp_path)
    assert left == [f".f.zarr.{killed.pid}.partial"]  # a killed process cleans nothing
    # The next run (here in this process: another PID than the killed one's) cleans up.
    assert main(["process", str(dataset), "-o", str(output)]) == 0
    note = [line for line in capsys.readouterr().out.splitlines() if "partial stores" in line]
    assert note == [f"note: removed 1 partial stores of f.zarr left by runs that were killed "
                    f"({left[0]})"]  # fmt: skip
    assert _partials(tmp_path) == [] and check_store(output).ok


def test_of_two_runs_to_one_new_store_the_loser_refuses_and_leaves_nothing(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    output = tmp_path / "f.zarr"
    # One run in a process of its own, one in this one (a thread: no second start-up to wait
    # for) with more points to build, so the two tend to finish together; whichever wins, the
    # other must refuse and leave nothing.
    other = _rig("process", str(dataset), "-o", str(output), logs=tmp_path)
    codes: list[int] = []
    here = threading.Thread(target=lambda: codes.append(main(
        ["process", str(dataset), "-o", str(output), "--scene-points", SLOW_POINTS]
    )))  # fmt: skip
    here.start()
    try:
        codes.append(other.wait(timeout=PATIENCE_S))
        here.join(timeout=PATIENCE_S)
    finally:
        if other.poll() is None:
            other.kill()
            other.wait()
    assert sorted(codes) == [0, 2]
    said = capsys.readouterr().err + (tmp_path / "stderr.txt").read_text(errors="replace")
    assert f"rig process: error: {output}: " in said and "Traceback" not in said
    assert "already there" in said or "another process put a field store there" in said
    assert _partials(tmp_path) == [] and check_store(output).ok


def test_a_writer_whose_store_another_process_finished_first_removes_its_partial(
    tmp_path: Path,
) -> None:
    # The race's loser, deterministically: the other process's store arrives while this
    # writer builds (it checked the path when it began).
    def writer(path: Path) -> FieldStoreWriter:
        points = np.random.default_rng(1).normal(size=(8, 3))
        store = FieldStoreWriter(path, points=points, normals=points, cameras=field_cameras(1),
                                 light_directions=np.eye(3)[2:])  # fmt: skip
        store.write_slab(0, 0, np.ones((8, 3)))
        store.write_visibility(0, np.ones(8, dtype=bool))
        return store

    target = tmp_path / "f.zarr"
    loser = writer(target)
    winner = writer(tmp_path / "w.zarr").finish()
    shutil.copytree(winner, target)
    before = sorted(p.relative_to(target) for p in target.rglob("*"))
    with pytest.raises(InputError, match="a field store is already there"):
        loser.finish()
    assert not loser.partial.exists() and _partials(tmp_path) == []
    assert sorted(p.relative_to(target) for p in target.rglob("*")) == before
    assert sorted(os.listdir(tmp_path)) == ["f.zarr", "w.zarr"]


def test_an_aborted_store_waits_for_the_write_under_way(tmp_path: Path) -> None:
    # SIGTERM (raised as Ctrl-C) interrupts the wait for a write, not the write: it goes on in
    # zarr's event loop and made the removed partial store again (1 run in 4 of the SIGTERM
    # test above). Here a write still under way when the store is aborted.
    import asyncio

    from zarr.core.sync import _get_loop

    points = np.random.default_rng(1).normal(size=(8, 3))
    store = FieldStoreWriter(tmp_path / "f.zarr", points=points, normals=points,
                             cameras=field_cameras(1), light_directions=np.eye(3)[2:])  # fmt: skip

    async def late_write() -> None:
        await asyncio.sleep(0.5)
        chunk = store.partial / "radiance" / "c" / "0" / "0" / "0" / "0"
        chunk.parent.mkdir(parents=True, exist_ok=True)  # as zarr's LocalStore writes
        chunk.write_bytes(b"late")

    under_way = asyncio.run_coroutine_threadsafe(late_write(), _get_loop())
    store.abort()
    under_way.result(timeout=PATIENCE_S)
    assert _partials(tmp_path) == []
